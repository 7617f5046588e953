"""
Designing a layout, with a certified bound
==========================================

``shipsense design`` places k copies of a scenario's first sensor among candidate points, maximising the
prior-averaged Bayesian D-optimality, certifies how far the design can be from the best k-sensor design, and
checks it for ambiguity.  This page designs three electrode envelopes for S1-P2 from 4 prior passages
(8 by default) and checks the result as ``shipsense check`` would.  The reports of the shipped scenarios are in
:doc:`../findings/design`.

Full-size command (S0, S1-P2 and S2 at k = 3, as a table)::

    python experiments/design_reports.py --out results/design
"""

# %%
import json
import tempfile
from pathlib import Path

from shipsense.cli import main
from shipsense.plotting import show_image

out = Path(tempfile.mkdtemp()) / "design"
assert main(["--quiet", "design", "S1-P2", "--k", "3", "--passages", "4", "--bb-seconds", "2",
             "--out", str(out)]) == 0
report = json.loads((out / "design.json").read_text())
for key in ("criterion", "solver", "design_objective", "upper_bound", "guaranteed_efficiency", "verdict"):
    print(f"{key:22} {report[key]}")

# %%
# The design is a scenario file; ``shipsense check`` gives its verdict (exit 0: observable).
code = main(["--quiet", "check", str(out / "layout.toml"), "--passages", "4"])
print("exit code", code)


# %%
# ``design.png``: the candidates, the relaxed weights and the chosen sensors.
show_image(out / "design.png")

# %%
# ``bounds.png``: a map of the design's position bound (the CRLB's standard deviation where a ship passes).
show_image(out / "bounds.png")
