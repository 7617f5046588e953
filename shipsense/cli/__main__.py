"""``python -m shipsense.cli``: the command line (:func:`shipsense.cli.main`)."""

import sys

from shipsense.cli.main import main

sys.exit(main())
