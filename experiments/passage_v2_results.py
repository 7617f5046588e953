"""Passage-v2's results: every baseline, the planners and a trained agent on the same held-out passages, paired.

Each policy is run by ``shipsense evaluate``'s :func:`~shipsense.envs.evaluation.evaluate` on the passages of
seeds ``seed .. seed + episodes - 1`` (in ``shards`` processes, shard ``j`` the seeds ``seed + j * episodes /
shards`` on: a planner's own generator is seeded by its shard's first seed), so every policy plays the same
passages and the differences are paired passage by passage.  A policy's result is kept in ``OUT/POLICY.json``
(the shards' ``per_episode`` lists joined in seed order) and not run again when that file exists.  With
``--train DIR`` (a ``shipsense train`` output folder) its ``best_model.zip`` is evaluated as ``agent``, and its
learning curve (the held-out mean return against the training frames, with the baselines' levels on the same
held-out passages) is printed as a table and drawn in ``OUT/learning_curve.png``.

Run:  PYTHONPATH=. python experiments/passage_v2_results.py --out results/passage-v2 [--episodes 200]
      [--seed 2100000] [--shards 2] [--rollout '{"horizon": 8}'] [--train results/train-scheduling-v2]
      [--policies random round-robin greedy greedy-threshold rollout hindsight]

Prints, per policy: mean return +- standard error, the paired difference to greedy (mean +- s.e., how many
standard errors, better / worse on how many passages), the checkpoint error (m), reads per step and compute
per decision (ms); then rollout - greedy-threshold, hindsight - rollout and agent - each baseline, paired.
Time: the rollout dominates (its compute per decision times about 60 decisions per passage).
"""

from __future__ import annotations

import argparse
import json
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

ENV_ID = "shipsense/Passage-v2"
POLICIES = ("random", "round-robin", "greedy", "greedy-threshold", "rollout", "hindsight")


def _shard(job):
    from shipsense.envs.evaluation import evaluate

    policy, episodes, seed, kwargs = job
    return evaluate(ENV_ID, policy, episodes, seed, policy_kwargs=kwargs or None)


def run_policy(policy, episodes, seed, shards, kwargs, pool):
    """``evaluate``'s result for ``policy`` over seeds ``seed ..``, the shards' episodes joined in seed order."""
    size = -(-episodes // shards)
    jobs = [(policy, min(size, episodes - lo), seed + lo, kwargs) for lo in range(0, episodes, size)]
    parts = list(pool.map(_shard, jobs))
    per = {key: [v for p in parts for v in p["per_episode"][key]] for key in parts[0]["per_episode"]}
    decisions = sum(p["length"] * p["episodes"] for p in parts)
    return {"policy": policy, "episodes": episodes, "seed": seed, "shards": len(jobs), "policy_kwargs": kwargs or {},
            "policy_settings": parts[0]["policy_settings"], "per_episode": per,
            "seconds_per_decision": sum(p["seconds_per_decision"] * p["length"] * p["episodes"] for p in parts)
            / decisions}


def paired(a, b):
    """Mean, standard error, mean / s.e., better and worse counts of ``a - b`` (per passage)."""
    d = np.asarray(a) - np.asarray(b)
    se = float(d.std(ddof=1) / np.sqrt(d.size))
    return {"mean": float(d.mean()), "stderr": se, "z": float(d.mean() / se) if se > 0 else float("inf"),
            "better": int((d > 1e-12).sum()), "worse": int((d < -1e-12).sum()), "sd": float(d.std(ddof=1)),
            "median": float(np.median(d))}


def fmt_pair(p):
    return (f"{p['mean']:+.2f} +- {p['stderr']:.2f} ({p['z']:.1f} s.e.; {p['better']} / {p['worse']}; "
            f"sd {p['sd']:.1f}, median {p['median']:+.2f})")


def curve_table(train_dir, baselines):
    """The training run's held-out curve as rows (frames, mean, s.e.) and its baselines' levels; a PNG beside."""
    curve = json.loads((train_dir / "learning_curve.json").read_text())
    summary = json.loads((train_dir / "evaluation.json").read_text())
    rows = [(p["timesteps"], p["return"]["mean"], p["return"]["stderr"]) for p in curve]
    return rows, summary.get("held_out_baselines", {}), summary


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--episodes", type=int, default=200)
    ap.add_argument("--seed", type=int, default=2_100_000)
    ap.add_argument("--shards", type=int, default=2)
    ap.add_argument("--policies", nargs="+", default=list(POLICIES))
    ap.add_argument("--rollout", default="{}", help="rollout's options, JSON (default: evaluate's)")
    ap.add_argument("--train", type=Path, default=None, help="a shipsense train output folder (the agent)")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    policies = list(args.policies) + (["agent"] if args.train else [])
    results = {}
    with ProcessPoolExecutor(max_workers=args.shards) as pool:
        for name in policies:
            path = args.out / f"{name}.json"
            if not path.exists():
                policy = str(args.train / "best_model.zip") if name == "agent" else name
                kwargs = json.loads(args.rollout) if name == "rollout" else {}
                result = run_policy(policy, args.episodes, args.seed, args.shards, kwargs, pool)
                path.write_text(json.dumps(result) + "\n")
            results[name] = json.loads(path.read_text())
    ret = {n: np.asarray(r["per_episode"]["return"]) for n, r in results.items()}
    print(f"{ENV_ID}: {args.episodes} held-out passages, seeds {args.seed}-{args.seed + args.episodes - 1}")
    for name, r in results.items():
        x, per = ret[name], r["per_episode"]
        line = f"{name:>17}: {x.mean():8.2f} +- {x.std(ddof=1) / np.sqrt(x.size):.2f}"
        if "greedy" in ret and name != "greedy":
            line += "  vs greedy " + fmt_pair(paired(x, ret["greedy"]))
        line += (f"  checkpoint error {np.mean(per['checkpoint_error_m']):.3f} m, reads/step "
                 f"{np.mean(per['reads_per_step']):.2f}, {1e3 * r['seconds_per_decision']:.3g} ms/decision")
        print(line)
    for a, b in (("rollout", "greedy-threshold"), ("hindsight", "rollout"), ("agent", "greedy"),
                 ("agent", "greedy-threshold"), ("agent", "rollout"), ("agent", "round-robin"),
                 ("agent", "random"), ("agent", "hindsight")):
        if a in ret and b in ret:
            print(f"{a} - {b}: {fmt_pair(paired(ret[a], ret[b]))}")
    if args.train:
        rows, levels, summary = curve_table(args.train, results)
        print(f"learning curve ({summary['eval_episodes']} held-out passages, seeds {summary['held_out_seed']}+; "
              f"baselines there: " + ", ".join(f"{k} {v:.2f}" for k, v in levels.items()) + ")")
        for frames, mean, se in rows:
            print(f"  {frames:>8} frames: {mean:8.2f} +- {se:.2f}")
        from shipsense.envs.training import plot_learning_curve

        plot_learning_curve(json.loads((args.train / "learning_curve.json").read_text()),
                            args.out / "learning_curve.png", f"PPO on {ENV_ID}", levels)


if __name__ == "__main__":
    main()
