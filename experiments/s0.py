"""Reproduce the S0 experiments of scenarios.md (same as `shipsense reproduce S0`).

Run:  python experiments/s0.py [--runs N] [--out DIR] [--seed S]
"""

import sys

from shipsense.cli import main

if __name__ == "__main__":
    sys.exit(main(["reproduce", "S0", *sys.argv[1:]]))
