"""Reproduce the S2 experiments of scenarios.md (same as `shipsense reproduce S2`).

Run:  python experiments/s2.py [--runs N] [--out DIR] [--seed S]
"""

import sys

from shipsense.cli import main

if __name__ == "__main__":
    sys.exit(main(["reproduce", "S2", *sys.argv[1:]]))
