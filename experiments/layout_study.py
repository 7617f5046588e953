"""Layout study as a sweep: random, line, greedy, convex and convex-with-cuts placements, judged alike.

Run:  python experiments/layout_study.py [--passages 40] [--method tracker|bank] [--workers 2]
                                         [--out results/layouts]

Two families: envelope electrodes (the S1-P2 template, 3 sensors from a 9 x 9
grid of 60 m x 60 m on the seabed) and vector magnetometers (the S2 template,
3 sensors from a 9 x 9 grid of 40 m x 40 m).  Every method designs from the
same 8 prior passages (seed 0); each design is written as a layout file and
the layouts of a family are one sweep (``shipsense sweep``, seed 10000 for
held-out passages): convergence, RMSE of the converged passages and its ratio
to the CRLB, NEES coverage of the reported 95 % ellipse, the ambiguity
verdict and the tracking time.  Writes, under ``--out``, ``layouts/*.toml``,
one sweep folder per family and ``layouts.csv`` (the table printed).
"""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

import numpy as np

from shipsense import load_scenario
from shipsense.config import to_toml
from shipsense.design import placement as pl
from shipsense.models.field_model import candidate_model
from shipsense.simulator import sample_passages
from shipsense.sweep import parse_sweep, run_sweep

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
    values = {m: float(pl.value_of_sets(problem, np.sort(c)[None], "D")[0]) for m, c in out.items()}
    return sc, cands, out, values


def write_layouts(name, half, prior_std, folder):
    """Design a family's layouts and write each as a scenario file; returns {method: (path, D value)}."""
    sc, cands, layouts, values = layouts_for(name, half, prior_std)
    template = sc.sensors[0]
    out = {}
    for method, chosen in layouts.items():
        sensors = [template.model_copy(update={"id": f"L{i + 1}", "position": tuple(map(float, cands[c]))})
                   for i, c in enumerate(chosen)]
        path = folder / f"{name}-{method.replace(' + ', '-')}.toml"
        path.write_text(to_toml(sc.model_copy(update={"sensors": sensors, "name": f"{name} {method}"})))
        out[method] = (path, values[method])
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--passages", type=int, default=40)
    ap.add_argument("--method", default="tracker", choices=["tracker", "bank"])
    ap.add_argument("--workers", type=int, default=None, help="local Dask workers (0: serial)")
    ap.add_argument("--out", default="results/layouts")
    args = ap.parse_args(argv)
    out = Path(args.out)
    (out / "layouts").mkdir(parents=True, exist_ok=True)
    lines = ["family,method,d_value,verdict,convergence_rate,rmse_m,rmse_over_crlb,nees_coverage,seconds_per_passage"]
    print(f"{'family':<9} {'method':<14} {'D value':>8} {'verdict':>11} {'converged':>9} {'RMSE [m]':>9} "
          f"{'RMSE/CRLB':>10} {'coverage':>9}")
    for family, (name, half, prior_std) in FAMILIES.items():
        files = write_layouts(name, half, prior_std, out / "layouts")
        spec = parse_sweep({"name": f"layout-study-{family}", "scenario": name, "seed": 10_000,
                            "passages": args.passages, "chunk": 10, "method": args.method,
                            "layouts": [{"name": m, "file": str(p.resolve())} for m, (p, _) in files.items()]},
                           f"layout study ({family})")
        shutil.rmtree(out / f"sweep-{family}", ignore_errors=True)   # an experiment: always from scratch
        run_sweep(spec, out, out / f"sweep-{family}", workers=args.workers)
        import pandas as pd

        res = pd.read_parquet(out / f"sweep-{family}" / "results.parquet")
        for method, (_, d_value) in files.items():
            r = res[res.layout == method].set_index("metric")
            v = {m: float(r.loc[m, "value"]) for m in r.index}
            verdict = r["verdict"].iloc[0]
            print(f"{family:<9} {method:<14} {d_value:>8.2f} {verdict:>11} {v['convergence_rate']:>9.2f} "
                  f"{v['rmse_m']:>9.3g} {v['rmse_over_crlb']:>10.3g} {v['nees_coverage']:>9.2f}", flush=True)
            lines.append(f"{family},{method},{d_value:.6g},{verdict},{v['convergence_rate']:.6g},{v['rmse_m']:.6g},"
                         f"{v['rmse_over_crlb']:.6g},{v['nees_coverage']:.6g},{v['seconds_per_passage']:.6g}")
    (out / "layouts.csv").write_text("\n".join(lines) + "\n")
    print(f"wrote {out / 'layouts.csv'} and the sweep folders under {out}")


if __name__ == "__main__":
    main()
