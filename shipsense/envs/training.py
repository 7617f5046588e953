"""Training agents on the environments (stable-baselines3, the ``rl`` extra): ``shipsense train``.

:func:`train` serves both kinds: ``scheduling`` trains PPO, ``placement`` MaskablePPO (with the env's
``action_masks``), each on the environment's vector version through :class:`~shipsense.envs.sb3.VectorEnvAdapter`
(the native ``vector_entry_point`` when the environment has one, else gymnasium's ``SyncVectorEnv`` with same-step
autoreset; the defaults: :data:`DEFAULT_ENVS`), with TensorBoard logs in ``OUT/tensorboard``. Every ``eval_every`` steps
the deterministic agent plays ``eval_episodes`` held-out episodes (seeds :data:`HELD_OUT_SEED` + i; training
environments are seeded from ``seed``); the best one so far is saved as ``OUT/best_model.zip``. At the end:
``OUT/final_model.zip``, ``OUT/learning_curve.json`` and ``OUT/learning_curve.png`` (the held-out mean return with
its standard error against the steps), and ``OUT/evaluation.json`` (the summary). Compare the saved model with the
baselines on other seeds with ``shipsense evaluate ENV --policy OUT/best_model.zip``.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from shipsense.arguments import number

ALGORITHMS = {"scheduling": "PPO", "placement": "MaskablePPO"}
DEFAULT_ENVS = {   # kind: (env id, its arguments when --env is not given)
    "scheduling": ("shipsense/Passage-v1", {}),
    "placement": ("shipsense/ArrayDesign-v1", {}),
}
DEFAULT_TIMESTEPS = {"scheduling": 30_000, "placement": 20_000}
HELD_OUT_SEED = 1_000_000
"""Seeds of the periodic held-out evaluation (training environments are seeded from ``seed``, 0 by default)."""
POLICY_KWARGS = {"net_arch": {"pi": [256, 256], "vf": [256, 256]}}
"""Two hidden layers of 256 for the policy and the value (SB3's default 64 is a bottleneck for ArrayDesign-v1's
one logit per candidate, 81 of them, each to be read off its own gain feature)."""
MODEL_FILES = {"best": "best_model.zip", "final": "final_model.zip"}
CURVE_BASELINES = ("greedy", "round-robin", "random")
"""Baselines that play the held-out episodes once for the learning curve, where the environment offers them
(not ``convex``: seconds per episode)."""
GAMMA = 0.99
"""The agents' discount factor (SB3's default), also the shaping's."""


def _require_rl():
    try:
        import sb3_contrib  # noqa: F401
        import stable_baselines3  # noqa: F401
        import tensorboard  # noqa: F401  (the training logs)
        import torch
    except ImportError as err:
        raise RuntimeError("training needs the rl extra: pip install 'shipsense[rl]' "
                           "(install a CPU build of torch first to avoid a multi-GB download)") from err
    torch.set_num_threads(1)


def make_vector_env(env_id, n_envs, env_kwargs=None):
    """The gymnasium vector env training uses: the native one (``vector_entry_point``: one batched tracker
    or Fisher computation for all environments) when the environment has one, else ``SyncVectorEnv`` with
    same-step autoreset.  A native env autoresets in the next step (:class:`~shipsense.envs.core_env.CoreVectorEnv`)
    and serves SB3 through its partial reset (``reset(options={"reset_mask": ...})``,
    :class:`~shipsense.envs.sb3.VectorEnvAdapter`)."""
    import gymnasium as gym
    from gymnasium.vector import AutoresetMode

    kwargs = env_kwargs or {}
    if gym.spec(env_id).vector_entry_point is not None:
        return gym.make_vec(env_id, num_envs=n_envs, vectorization_mode="vector_entry_point", **kwargs)
    return gym.make_vec(env_id, num_envs=n_envs, vectorization_mode="sync",
                        vector_kwargs={"autoreset_mode": AutoresetMode.SAME_STEP}, **kwargs)


def rollout_steps(timesteps, n_envs):
    """Steps per environment in one PPO rollout: 1024 steps in all, fewer when the whole run is shorter."""
    return max(8, min(1024 // n_envs, -(-timesteps // n_envs)))


DEFAULT_SHAPING = 1.0
"""The shaping weight when the environment declares a potential (Passage-v1; docs: Results, Trained agents)."""
DEFAULT_IMITATION = {"scheduling": "greedy", "placement": "greedy"}
"""The baseline each kind's agent first clones when the environment offers it (docs: Results: on 100 held-out
Passage-v1 passages PPO from the clone beats round-robin, PPO from scratch in the same budget does not; on
ArrayDesign-v1 MaskablePPO from scratch trails greedy, from the clone it starts at greedy's level)."""


def _env_class(env_id):
    import gymnasium as gym
    from gymnasium.envs.registration import load_env_creator

    return load_env_creator(gym.spec(env_id).entry_point)


def shaping_potential(env_id):
    """The shaping potential ``phi(obs)`` the environment ``env_id`` declares (its class's ``potential``), or None."""
    return getattr(_env_class(env_id), "potential", None)


def training_defaults(kind, env_id, shaping=None, imitate_policy=None):
    """``(shaping, imitate_policy)`` with the defaults filled in: :data:`DEFAULT_SHAPING` where the environment
    declares a potential (else 0), and the kind's :data:`DEFAULT_IMITATION` where the environment offers that
    baseline (else none); ``imitate_policy="none"`` turns cloning off."""
    if shaping is None:
        shaping = DEFAULT_SHAPING if shaping_potential(env_id) is not None else 0.0
    if imitate_policy is None:
        want = DEFAULT_IMITATION.get(kind)
        imitate_policy = want if want in getattr(_env_class(env_id), "BASELINES", ()) else None
    elif imitate_policy == "none":
        imitate_policy = None
    return shaping, imitate_policy


def agent_policy(env_id):
    """The policy network of the agent for ``env_id``: ArrayDesign-v1's placement agent scores every candidate with
    one shared network (:class:`~shipsense.envs.placement_policy.CandidatePolicy`: cloned from greedy it picks
    greedy's candidate on unseen sites, a flat network learns the sites by heart), else SB3's ``"MlpPolicy"``."""
    from shipsense.envs.site_design import SiteDesignEnv

    if issubclass(_env_class(env_id), SiteDesignEnv):
        from shipsense.envs.placement_policy import CandidatePolicy

        return CandidatePolicy
    return "MlpPolicy"


def _check(kind, env_id, timesteps, seed, n_envs, eval_every, eval_episodes, env_kwargs):
    import gymnasium as gym

    from shipsense.envs import register_envs

    register_envs()

    if kind not in ALGORITHMS:
        raise ValueError(f"kind must be one of {', '.join(ALGORITHMS)}, got {kind!r}")
    if env_kwargs is not None and not isinstance(env_kwargs, dict):
        raise ValueError(f"env_kwargs must be a dict, got {type(env_kwargs).__name__}")
    if env_id is None:
        env_id, defaults = DEFAULT_ENVS[kind]
        env_kwargs = {**defaults, **(env_kwargs or {})}
    if env_id not in gym.registry:
        known = sorted(k for k in gym.registry if k.startswith("shipsense/"))
        raise ValueError(f"env_id {env_id!r} is not registered (shipsense's: {', '.join(known)})")
    timesteps = number("timesteps", timesteps, 64, 10**9, integer=True)
    seed = number("seed", seed, 0, 2**31 - 1, integer=True)
    n_envs = number("n_envs", n_envs, 1, 256, integer=True)
    rollout = rollout_steps(timesteps, n_envs) * n_envs
    eval_every = number("eval_every", eval_every, 1, 10**9, integer=True) if eval_every is not None else \
        max(timesteps // 10, rollout)
    eval_episodes = number("eval_episodes", eval_episodes, 1, 10**5, integer=True)
    return env_id, timesteps, seed, n_envs, eval_every, eval_episodes, env_kwargs or None


def _eval_callback(env_id, env_kwargs, out, every, episodes, masked, progress, at_start=False):
    import gymnasium as gym
    from stable_baselines3.common.callbacks import BaseCallback
    from tqdm import tqdm

    from shipsense.envs.evaluation import load_policy, run_episodes, summarise

    class HeldOut(BaseCallback):
        """Periodic evaluation of the deterministic agent on held-out seeds; keeps the best model.  The
        environment's cheap baselines (:data:`CURVE_BASELINES`) play the same episodes once, for the curve."""

        def _on_training_start(self):
            t0 = time.perf_counter()
            self.env = gym.make(env_id, **(env_kwargs or {}))
            self.curve, self.best, self.next = [], -np.inf, every
            self.baselines = {}
            for name in (b for b in CURVE_BASELINES if b in getattr(type(self.env.unwrapped), "BASELINES", ())):
                returns, _, _ = run_episodes(self.env, load_policy(self.env, name, seed=HELD_OUT_SEED),
                                             HELD_OUT_SEED, range(episodes))
                self.baselines[name] = float(np.mean(returns))
            self.seconds = time.perf_counter() - t0     # (the held-out episodes' time: not PPO's)
            self.bar = tqdm(total=self.locals["total_timesteps"], desc=f"train {env_id}", unit="step", leave=False,
                            disable=None if progress else True)
            if at_start:   # the policy it starts from (behaviour cloning) is a candidate too
                self.evaluate()

        def _agent(self, obs):
            kw = {"action_masks": self.env.unwrapped.action_masks()} if masked else {}
            return self.model.predict(obs, deterministic=True, **kw)[0]

        def evaluate(self):
            t0 = time.perf_counter()
            returns, _, metrics = run_episodes(self.env, self._agent, HELD_OUT_SEED, range(episodes))
            s = summarise(returns, metrics)
            point = {"timesteps": int(self.num_timesteps), **s}
            self.curve.append(point)
            self.logger.record("eval/mean_return", s["return"]["mean"])
            for key, m in s["metrics"].items():
                self.logger.record(f"eval/{key}", m["mean"])
            if s["return"]["mean"] > self.best:
                self.best = s["return"]["mean"]
                self.model.save(Path(out) / MODEL_FILES["best"])
            self.seconds += time.perf_counter() - t0

        def _on_step(self):
            self.bar.update(self.training_env.num_envs)
            if self.num_timesteps >= self.next:
                self.next += every
                self.evaluate()
            return True

        def _on_training_end(self):
            if not self.curve or self.curve[-1]["timesteps"] != self.num_timesteps:
                self.evaluate()
            self.bar.close()
            self.env.close()

    return HeldOut()


IMITABLE_PLANNERS = ("rollout", "hindsight")
"""Planning baselines (:mod:`shipsense.envs.planning`) that ``--imitate`` clones on a Passage vector env, besides
its own baselines, with ``shipsense evaluate``'s default options: ``rollout`` (a teacher's decision costs a rollout
decision per environment, so cloning it takes minutes, not seconds) and the offline ``hindsight`` (a privileged
teacher: it plans each passage knowing it, the clone sees only the observations)."""


def imitation_teacher(native, env_id, name, seed):
    """The teacher ``teacher(obs) -> actions (num_envs,)`` that :func:`imitate` clones on the native vector env
    ``native``: one of its baselines (``native.baseline(name)``) or, on a Passage vector env, one of
    :data:`IMITABLE_PLANNERS` deciding for every environment of its core from the observer's belief.  A name it
    does not offer raises one ``ValueError``."""
    from shipsense.envs import planning

    base = native.unwrapped
    offered = tuple(getattr(base, "BASELINES", ())) if hasattr(base, "baseline") else ()
    if name in offered:
        return base.baseline(name, seed=seed)
    planners = IMITABLE_PLANNERS if planning.offers(native) else ()
    if name in planners:
        return (planning.Rollout(base.core, seed=seed) if name == "rollout" else planning.Hindsight(base.core)).actions
    raise ValueError(f"imitate_policy: {env_id}'s vector env offers {', '.join(offered + planners) or 'no baseline'}, "
                     f"not {name!r}")


IMITATION_UPDATES = 500
"""Behaviour cloning's least number of gradient steps (minibatches): a short demonstration (a planner's few
thousand steps) is passed over more often than :func:`imitate`'s ``epochs`` (30,000 steps of greedy, 5 epochs of
minibatches of 256, are about 590); with a few hundred steps a clone of a teacher that reads on a third of the steps
learns only its most frequent action (no read)."""


def imitate(model, venv, teacher, steps, epochs=5, batch_size=256):
    """Behaviour cloning before PPO: the policy learns the ``teacher``'s actions and the value net the discounted
    training returns it earns, on ``steps`` environment steps of the teacher in ``venv`` (the SB3 vector env
    training uses, shaping included), over ``epochs`` passes or as many as make :data:`IMITATION_UPDATES`
    minibatches.  Only completed episodes are kept (their returns are known).  A maskable policy (MaskablePPO's)
    learns them under the environments' action masks (``venv.env_method("action_masks")``, recorded with each
    step), as it acts: the log-likelihood of the teacher's action among the allowed ones.  Returns the share of
    the teacher's actions the policy then picks (its deterministic action, masked likewise), over those steps.
    """
    import inspect

    import torch

    policy = model.policy
    masked = "action_masks" in inspect.signature(policy.evaluate_actions).parameters
    obs, n = venv.reset(), venv.num_envs
    rows, live = [], [[] for _ in range(n)]            # finished (obs, action, return, mask) rows; open episodes
    for _ in range(-(-steps // n)):
        masks = np.stack(venv.env_method("action_masks")) if masked else [None] * n
        actions = np.asarray(teacher(obs)).reshape(n)
        nxt, rewards, dones, _ = venv.step(actions)
        for i in range(n):
            live[i].append((obs[i], actions[i], float(rewards[i]), masks[i]))
            if dones[i]:
                ret = 0.0
                for o, a, r, m in reversed(live[i]):
                    ret = r + model.gamma * ret
                    rows.append((o, a, ret, m))
                live[i] = []
        obs = nxt
    if not rows:
        raise ValueError(f"imitation_steps: {steps} steps finished no episode; give more")
    X = torch.as_tensor(np.stack([r[0] for r in rows]), dtype=torch.float32)
    A = torch.as_tensor(np.array([r[1] for r in rows]))
    G = torch.as_tensor(np.array([r[2] for r in rows]), dtype=torch.float32)
    M = np.stack([r[3] for r in rows]) if masked else None

    def given(idx):          # the masks of rows ``idx``, for a maskable policy
        return {"action_masks": M[idx.numpy()] if idx is not None else M} if masked else {}

    gen = torch.Generator().manual_seed(0)
    policy.set_training_mode(True)
    for _ in range(max(int(epochs), -(-IMITATION_UPDATES // -(-len(rows) // batch_size)))):
        for idx in torch.randperm(len(rows), generator=gen).split(batch_size):
            values, logp, _ = policy.evaluate_actions(X[idx], A[idx], **given(idx))
            loss = -logp.mean() + 0.5 * torch.nn.functional.mse_loss(values.flatten(), G[idx])
            policy.optimizer.zero_grad()
            loss.backward()
            policy.optimizer.step()
    policy.set_training_mode(False)
    with torch.no_grad():
        agree = (policy.get_distribution(X, **given(None)).mode() == A).float().mean().item()
    return agree


def plot_learning_curve(curve, path, title, baselines=None):
    """The held-out mean return (with its standard error) against the training steps, as a PNG, with the
    baselines' mean returns on the same episodes (``{name: return}``) as horizontal lines."""
    from shipsense.plotting import plt

    t = [p["timesteps"] for p in curve]
    m = np.array([p["return"]["mean"] for p in curve])
    se = np.array([p["return"]["stderr"] for p in curve])
    fig, ax = plt.subplots(figsize=(6, 4), dpi=100)
    ax.plot(t, m, marker="o", label="agent (deterministic), held-out episodes")
    ax.fill_between(t, m - se, m + se, alpha=0.25)
    for (name, value), style in zip(sorted((baselines or {}).items(), key=lambda kv: -kv[1]), ("--", "-.", ":")):
        ax.axhline(value, color="0.35", ls=style, lw=1, label=f"{name} (same episodes)")
    ax.set_xlabel("training steps")
    ax.set_ylabel("mean return")
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def train(kind, env_id=None, timesteps=None, out=None, seed=0, n_envs=8, eval_every=None, eval_episodes=20,
          env_kwargs=None, progress=True, shaping=None, imitate_policy=None, imitation_steps=30_000):
    """Train the ``kind``'s agent on ``env_id`` (default :data:`DEFAULT_ENVS`) and write its files to ``out``.

    ``shaping`` > 0 adds potential-based reward shaping with the environment's ``potential`` and that weight
    to the training reward (:class:`~shipsense.envs.sb3.PotentialShaping`; the optimal policies do not change,
    the held-out evaluations use the environment's own reward).  ``imitate_policy`` (a baseline the native
    vector env offers, e.g. ``"greedy"``) first clones that policy's actions on ``imitation_steps`` steps
    (:func:`imitate`), and the held-out evaluation at step 0 scores the clone, so the best model is never worse
    than it on those seeds.  None (both): :func:`training_defaults`, the measured best (for Passage-v1: shaping
    1 and a clone of greedy; for ArrayDesign-v1: a clone of greedy, under the masks); ``imitate_policy="none"``:
    PPO from scratch.  Bad arguments raise one
    ``ValueError`` naming the argument.  Returns the summary written to ``out/evaluation.json``; its
    ``frames_per_second`` is the agent's steps over the whole run (behaviour cloning and the held-out episodes
    included), ``own_frames_per_second`` over the time left to the agent's own steps and updates
    (``imitation_seconds`` and ``evaluation_seconds`` taken out).
    """
    timesteps = DEFAULT_TIMESTEPS.get(kind, 0) if timesteps is None else timesteps
    env_id, timesteps, seed, n_envs, eval_every, eval_episodes, env_kwargs = _check(
        kind, env_id, timesteps, seed, n_envs, eval_every, eval_episodes, env_kwargs)
    shaping, imitate_policy = training_defaults(kind, env_id, shaping, imitate_policy)
    shaping = number("shaping", shaping, 0.0, 1e6)
    potential = shaping_potential(env_id) if shaping else None
    if shaping and potential is None:
        raise ValueError(f"shaping: {env_id} declares no shaping potential (its class has no 'potential')")
    if imitate_policy is not None:
        imitation_steps = number("imitation_steps", imitation_steps, 64, 10**8, integer=True)
    _require_rl()
    from stable_baselines3.common.vec_env import VecMonitor

    from shipsense.envs.sb3 import PotentialShaping, VectorEnvAdapter

    out = Path(out if out is not None else f"results/train-{kind}")
    out.mkdir(parents=True, exist_ok=True)
    native = make_vector_env(env_id, n_envs, env_kwargs)
    teacher = None
    if imitate_policy is not None:
        try:
            teacher = imitation_teacher(native, env_id, imitate_policy, seed)
        except ValueError:
            native.close()
            raise
    venv = VecMonitor(VectorEnvAdapter(native))
    if shaping:
        venv = PotentialShaping(venv, potential, shaping, GAMMA)
    venv.seed(seed)
    masked = kind == "placement"
    if masked:
        from sb3_contrib import MaskablePPO as Algo
    else:
        from stable_baselines3 import PPO as Algo
    n_steps = rollout_steps(timesteps, n_envs)
    model = Algo(agent_policy(env_id), venv, n_steps=n_steps, batch_size=min(256, n_steps * n_envs), seed=seed,
                 gamma=GAMMA, device="cpu", verbose=0, tensorboard_log=str(out / "tensorboard"),
                 policy_kwargs=POLICY_KWARGS)
    callback = _eval_callback(env_id, env_kwargs, out, eval_every, eval_episodes, masked, progress,
                              at_start=teacher is not None)
    t0 = time.perf_counter()
    agreement, imitation_seconds = None, 0.0
    if teacher is not None:
        agreement = imitate(model, venv, teacher, imitation_steps)
        venv.seed(seed)
        imitation_seconds = time.perf_counter() - t0
    model.learn(total_timesteps=timesteps, callback=callback, tb_log_name=ALGORITHMS[kind])
    seconds = time.perf_counter() - t0
    own_seconds = max(seconds - imitation_seconds - callback.seconds, 1e-9)   # (the agent's steps and updates)
    model.save(out / MODEL_FILES["final"])
    venv.close()
    curve = callback.curve
    best = max(curve, key=lambda p: p["return"]["mean"])
    (out / "learning_curve.json").write_text(json.dumps(curve, indent=2) + "\n")
    plot_learning_curve(curve, out / "learning_curve.png",
                        f"{ALGORITHMS[kind]} on {env_id}: {eval_episodes} held-out episodes (seeds {HELD_OUT_SEED}+)",
                        callback.baselines)
    summary = {"kind": kind, "algorithm": ALGORITHMS[kind], "env": env_id, "env_kwargs": env_kwargs or {},
               "shaping": shaping, "imitate_policy": imitate_policy, "imitation_agreement": agreement,
               "imitation_steps": imitation_steps if imitate_policy is not None else 0,
               "timesteps": int(model.num_timesteps), "n_envs": n_envs, "seed": seed, "seconds": seconds,
               "frames_per_second": model.num_timesteps / seconds, "imitation_seconds": imitation_seconds,
               "evaluation_seconds": callback.seconds, "own_frames_per_second": model.num_timesteps / own_seconds,
               "held_out_seed": HELD_OUT_SEED,
               "eval_episodes": eval_episodes, "best": best, "final": curve[-1],
               "held_out_baselines": callback.baselines,
               "files": {"best_model": MODEL_FILES["best"], "final_model": MODEL_FILES["final"],
                         "learning_curve": "learning_curve.png", "tensorboard": "tensorboard"}}
    (out / "evaluation.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary
