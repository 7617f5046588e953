"""Wide-prior benchmark of the source studies' bank against the global initialiser (same as
`shipsense reproduce wide`).

Run:  python experiments/wide.py [--runs N] [--out DIR] [--seed S]
"""

import sys

from shipsense.cli import main

if __name__ == "__main__":
    sys.exit(main(["reproduce", "wide", *sys.argv[1:]]))
