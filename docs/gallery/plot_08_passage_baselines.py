"""
Passage-v1: the baselines on held-out passages
==============================================

The scheduling environment is sound when the baselines order as they should: reading the sensors of largest
predicted information gain (greedy) beats reading them in turn (round-robin), which beats reading at random.
Every policy plays the same held-out passages (seeds from 1,000,000), so the differences are paired.  This
page plays 8 passages per policy instead of 200; the full comparison and the trained agents are in
:doc:`../findings/agents`.

Full-size command::

    PYTHONPATH=. python experiments/passage_baselines.py          # 200 passages per policy and variant
    shipsense evaluate shipsense/Passage-v1 --policy greedy --episodes 100 --seed 2000000
"""

# %%
import sys
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

import shipsense

sys.path.insert(0, str(Path(shipsense.__file__).resolve().parents[1] / "experiments"))
import passage_baselines  # noqa: E402

episodes, num_envs, seed = 8, 4, 1_000_000
results = {policy: passage_baselines.run("shipsense/Passage-v1", policy, episodes, num_envs, seed)[0]
           for policy in passage_baselines.POLICIES}
for policy, m in results.items():
    print(f"{policy:<12} return {m['return'].mean():7.2f} +- {passage_baselines.se(m['return']):.2f}   "
          f"mean error {m['mean_error_m'].mean():.3f} m   inside 95 % ellipse {m['coverage95'].mean():.3f}")

# %%
# Return (higher is better) and mean position error per policy, with standard errors, over the same passages.
fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 3.8), layout="constrained")
names = list(results)
for ax, key, label in ((ax1, "return", "episode return"), (ax2, "mean_error_m", "mean position error [m]")):
    values = [results[n][key] for n in names]
    ax.bar(names, [v.mean() for v in values], yerr=[passage_baselines.se(v) for v in values], capsize=4,
           color=["tab:gray", "tab:blue", "tab:green"])
    ax.set_ylabel(label)
    ax.grid(alpha=0.3, axis="y")
ax1.set_title(f"Passage-v1, {episodes} held-out passages per policy")
ax2.set_title("the task metric")
np.set_printoptions(precision=3)
