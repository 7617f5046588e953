"""
Study S0: one vector magnetometer and the SRCDKF bank
=====================================================

The first source study: a bank of 12 SRCDKF hypotheses seeded from the first sample of one vector
magnetometer, the convergence basin of a single filter, the seeding, the likelihood's selection and the
filter units.  This page runs ``shipsense reproduce S0`` with 10 runs instead of 200; the numbers it prints
are the small run's.  The full run's numbers and the verdicts against the study are in
:doc:`../findings/studies`.

Full-size command::

    shipsense reproduce S0 --out results/S0        # 200 runs, seed 0
"""

# %%
import json
import tempfile
from pathlib import Path

from shipsense.cli import main
from shipsense.plotting import show_image

out = Path(tempfile.mkdtemp()) / "S0"
assert main(["--quiet", "reproduce", "S0", "--runs", "10", "--out", str(out)]) == 0
summary = json.loads((out / "summary.json").read_text())
for key in ("basin_radius_m", "seed_nearest_m", "seed_inside_basin_rate", "loglik_top3", "selected_mrmse_m"):
    print(f"{key:24} {summary.get(key)}")


# %%
# Exp. 1, the convergence basin (``basin_rmse.png``): one SRCDKF started ``dr`` from the truth.
show_image(out / "basin_rmse.png")

# %%
# Exp. 2, the seeding (``seeding.png``): the 12 seeds (3 moment levels x 4 bearings) against the truth.
show_image(out / "seeding.png")

# %%
# Exp. 3, the selection (``selection_bars.png``): each hypothesis's final log-likelihood and error.
show_image(out / "selection_bars.png")

# %%
# Exp. 4, the filter units (``units_rmse.png``): the same bank with each unit.
show_image(out / "units_rmse.png")
