"""Layout study: random, line, greedy, convex and convex-with-cuts placements, judged by the same evaluation.

Run:  python experiments/layout_study.py [--passages 40] [--out results/layouts]

Two families: envelope electrodes (the S1-P2 template, 3 sensors from a 9 x 9
grid of 60 m x 60 m on the seabed) and vector magnetometers (the S2 template,
3 sensors from a 9 x 9 grid of 40 m x 40 m).  Every method designs from the
same 8 prior passages (seed 0); every layout is evaluated by
:func:`shipsense.design.evaluate.evaluate_layout` with the scenario's bank on
the same held-out passages (seed 10000): convergence rate, mean TRMSE, RMSE
over the second half against the PCRLB, and the ambiguity verdict.  Writes
``layouts.csv``, ``layouts.json`` and ``layouts.png``.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from shipsense import load_scenario
from shipsense.design import placement as pl
from shipsense.design.evaluate import evaluate_layout
from shipsense.plotting import plt
from shipsense.simulator import sample_passages
from shipsense.trackers.models import candidate_model

FAMILIES = {
    "envelope": ("S1-P2", 30.0, [30.0, 30.0, 2.0, 2.0, 1.0, 50.0]),
    "vector": ("S2", 20.0, [20.0, 20.0, 2.0, 2.0, 5e4, 5e4, 5e4]),
}
K = 3


def layouts_for(name, half, prior_std, seed=0):
    sc = load_scenario(name)
    z = sc.sensors[0].position[2]
    box = [(-half, -half), (half, -half), (half, half), (-half, half)]
    cands = pl.grid_candidates(box, 2 * half / 8, z)
    model = candidate_model(sc, cands)
    thetas = model.to_internal(model.state_from_truth(sample_passages(sc, 8, seed=seed)))
    problem = pl.build_problem(model, thetas, sc.steps, K, model.to_internal(np.array(prior_std)))
    rng = np.random.default_rng(seed)
    on_line = sorted(np.flatnonzero(cands[:, 0] == 0.0), key=lambda i: cands[i, 1])   # the line x = 0
    out = {
        "random": rng.choice(len(cands), K, replace=False),
        "line": np.array(on_line)[np.linspace(0, len(on_line) - 1, K).round().astype(int)],
        "greedy": pl.swap_refine(problem, pl.greedy(problem, "D"), "D")[0],
        "convex": pl.place(problem, "D").chosen,
        "convex + cuts": pl.place_with_cuts(problem, model, thetas, sc.steps).chosen,
    }
    values = {m: float(pl._value_of_sets(problem, np.sort(c)[None], "D")[0]) for m, c in out.items()}
    return sc, cands, out, values


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--passages", type=int, default=40)
    ap.add_argument("--out", default="results/layouts")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows, fig = [], plt.figure(figsize=(15, 6.5), layout="constrained")
    axes = fig.subplots(2, 5)
    print(f"{'family':<9} {'method':<14} {'D value':>8} {'verdict':>11} {'converged':>9} {'TRMSE [m]':>10} "
          f"{'RMSE/bound':>11}")
    for f, (family, (name, half, prior_std)) in enumerate(FAMILIES.items()):
        sc, cands, layouts, values = layouts_for(name, half, prior_std)
        template = sc.sensors[0]
        for j, (method, chosen) in enumerate(layouts.items()):
            sensors = [template.model_copy(update={"id": f"L{i + 1}", "position": tuple(map(float, cands[c]))})
                       for i, c in enumerate(chosen)]
            ev = evaluate_layout(sc.model_copy(update={"sensors": sensors}), passages=args.passages)
            row = {"family": family, "method": method, "d_value": values[method], **ev.to_json(),
                   "sensors": cands[chosen].tolist()}
            rows.append(row)
            print(f"{family:<9} {method:<14} {values[method]:>8.2f} {ev.verdict:>11} {ev.convergence_rate:>9.2f} "
                  f"{ev.trmse_m:>10.2f} {ev.ratio_to_bound:>11.3g}", flush=True)
            ax = axes[f, j]
            ax.scatter(cands[:, 0], cands[:, 1], s=6, color="0.7")
            ax.scatter(cands[chosen, 0], cands[chosen, 1], s=60, color="tab:red", edgecolor="k")
            ax.set_title(f"{family}: {method}\n{ev.verdict}, conv {ev.convergence_rate:.2f}, "
                         f"TRMSE {ev.trmse_m:.1f} m", fontsize=8)
            ax.set_aspect("equal")
            ax.tick_params(labelsize=7)
    fig.savefig(out / "layouts.png", dpi=100)
    keys = [k for k in rows[0] if k != "sensors"]
    with open(out / "layouts.csv", "w") as fh:
        fh.write(",".join(keys) + "\n")
        for r in rows:
            fh.write(",".join(f"{r[k]:.6g}" if isinstance(r[k], float) else str(r[k]) for k in keys) + "\n")
    (out / "layouts.json").write_text(json.dumps(rows, indent=2) + "\n")
    print(f"wrote {out / 'layouts.csv'}, {out / 'layouts.json'} and {out / 'layouts.png'}")


if __name__ == "__main__":
    main()
