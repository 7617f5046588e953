"""Reproduce the S1 experiments of scenarios.md (same as `shipsense reproduce S1`).

Run:  python experiments/s1.py [--runs N] [--out DIR] [--seed S]
"""

import sys

from shipsense.cli import main

if __name__ == "__main__":
    sys.exit(main(["reproduce", "S1", *sys.argv[1:]]))
