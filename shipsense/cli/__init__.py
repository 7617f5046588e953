"""The command line, a thin dispatcher over the package: ``shipsense demo | scenarios | simulate | track | check |
design | train | evaluate | reproduce | sweep``.

:mod:`~shipsense.cli.main` (the entry point), :mod:`~shipsense.cli.parser` (every command's flags), the commands
by what they work on -- :mod:`~shipsense.cli.passages` (scenarios, simulate, demo, track; the tracking pipeline
to files is :mod:`~shipsense.cli.track`), :mod:`~shipsense.cli.layouts` (check, design),
:mod:`~shipsense.cli.agents` (train, evaluate), :mod:`~shipsense.cli.studies` (reproduce, sweep) -- and what
they share, :mod:`~shipsense.cli.common`.

Exit codes: 0 success, 1 an internal error, 2 bad input (an invalid scenario, file or argument: one line naming
it), 3 and 4 the verdicts of ``check`` (ambiguous, degenerate), 130 interrupted.
"""

from shipsense.cli.main import main

__all__ = ["main"]
