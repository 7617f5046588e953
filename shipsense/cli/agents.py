"""Commands on agents: ``train`` and ``evaluate``."""

from __future__ import annotations

from shipsense.cli.common import EXIT_OK, QUIET, BadInput, first_use, json_kwargs, within_budget

_TRAIN_FLAGS = {"imitation_steps": "--imitation-steps", "imitate_policy": "--imitate", "shaping": "--shaping",
                "env_kwargs": "--env-kwargs", "env_id": "--env"}


def cmd_train(args) -> int:
    from shipsense import budget
    from shipsense.atomic import staged_directory
    from shipsense.envs import training

    if args.timesteps is not None and args.timesteps < 64:
        raise BadInput(f"--timesteps must be >= 64, got {args.timesteps}")
    timesteps = args.timesteps or training.DEFAULT_TIMESTEPS[args.task]
    evaluations = max(1, timesteps // args.eval_every) if args.eval_every else 10
    imitation = args.imitation_steps if args.imitate != "none" else 0
    within_budget(args, budget.training(args.task, timesteps + imitation, evaluations, args.eval_episodes))
    env_kwargs = json_kwargs("--env-kwargs", args.env_kwargs)
    out = args.out or f"results/train-{args.task}"
    if args.task == "scheduling":              # (Passage environments: the tracker observes)
        first_use("train")
    try:
        with staged_directory(out) as stage:   # the models, logs, curve and summary, or nothing
            s = training.train(args.task, args.env, timesteps, stage, args.seed, args.n_envs, args.eval_every,
                               args.eval_episodes, env_kwargs, progress=not QUIET["on"], shaping=args.shaping,
                               imitate_policy=args.imitate, imitation_steps=args.imitation_steps)
    except (RuntimeError, ValueError) as err:
        message = str(err)
        for name, flag in _TRAIN_FLAGS.items():   # the library names its arguments; the command, its flags
            if message.startswith(name):
                message = flag + message[len(name):]
                break
        raise BadInput(message) from None
    best, final = s["best"], s["final"]
    print(f"{s['algorithm']} on {s['env']}: {s['timesteps']} steps in {s['seconds']:.0f} s "
          f"({s['frames_per_second']:.0f} frames/s, {s['n_envs']} envs; {s['own_frames_per_second']:.0f} frames/s "
          f"without the {s['imitation_seconds']:.0f} s of imitation and {s['evaluation_seconds']:.0f} s of held-out "
          f"episodes)")
    for name, p in (("best", best), ("final", final)):
        r = p["return"]
        metrics = ", ".join(f"{k} {m['mean']:.4g}" for k, m in p["metrics"].items())
        print(f"  {name:<5} at {p['timesteps']:>8} steps: held-out return {r['mean']:.4g} +- {r['stderr']:.2g}"
              + (f" ({metrics})" if metrics else ""))
    if s["held_out_baselines"]:
        print("  baselines on the same held-out episodes: "
              + ", ".join(f"{k} {v:.4g}" for k, v in s["held_out_baselines"].items()))
    print(f"wrote {out}/{s['files']['best_model']} (best on held-out seeds {s['held_out_seed']}+), "
          f"{out}/{s['files']['final_model']}, {out}/learning_curve.png, {out}/evaluation.json and "
          f"{out}/tensorboard")
    return EXIT_OK


def cmd_evaluate(args) -> int:
    import json

    from shipsense import budget
    from shipsense.envs.evaluation import evaluate, summary_lines

    within_budget(args, budget.evaluation(args.env_id, args.policy, args.episodes))
    env_kwargs = json_kwargs("--env-kwargs", args.env_kwargs)
    policy_kwargs = json_kwargs("--policy-kwargs", args.policy_kwargs)
    if "Passage" in args.env_id:               # (the tracker observes)
        first_use("evaluate")
    try:
        result = evaluate(args.env_id, args.policy, args.episodes, args.seed, env_kwargs,
                          progress=not QUIET["on"], policy_kwargs=policy_kwargs)
    except ValueError as err:
        message = str(err)
        raise BadInput("--policy-kwargs" + message[len("policy_kwargs"):] if message.startswith("policy_kwargs")
                       else message) from None
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        for line in summary_lines(result):
            print(line)
    return EXIT_OK
