"""
Benchmarks: the current table
=============================

``benchmarks/run.py`` prints the whole performance picture in one process: the filter units' steps against
FilterPy's UKF, the environments' steps against CartPole, and the studies' wall time and memory.  This page
runs its quickest options (few filter steps, short environment runs, no study), so the absolute numbers are
noisy and the machine is the documentation build's: compare ratios measured in the same run, not numbers
across machines.  The measurement history is in ``benchmarks/LOG.md`` in the repository.

Full-size command (about a minute, plus each study)::

    PYTHONPATH=. python benchmarks/run.py --studies S0 S1
"""

# %%
import sys
from pathlib import Path

import shipsense

sys.path.insert(0, str(Path(shipsense.__file__).resolve().parents[1] / "benchmarks"))
import run  # noqa: E402  (benchmarks/run.py)

run.main(["--steps", "5", "--env-steps", "200", "--studies"])
