"""``shipsense/Passage-v1``: read ``k`` of the array's sensors per step while the tracker follows a passing ship.

## Description

One episode is one ship passage drawn from the scenario's prior past its
array.  The project's tracker (:class:`shipsense.trackers.Tracker`, its
covariance calibrated: docs: Results) runs inside the environment as the
observer.  It sees every sensor's first sample (the detection); from then on
the agent chooses at every step which sensors to read, at most ``k`` of them
(a seabed node's energy budget), each read costing ``energy_cost``.  The
agent sees the observer's output and what the observer predicts each sensor
would tell it, never the truth.

## Action space

``Discrete(A)``: an index into ``PassageV1Env.subsets``, every subset of
the ``S`` sensors with at most ``k`` members, in order of size then
lexicographic: action 0 reads nothing, actions ``1 .. S`` read one sensor
(sensor ``a - 1``), then the pairs, ...  An over-budget choice cannot be
expressed.  ``A = sum_{j <= k} C(S, j)``.

## Observation space

``Box(-1, 1, (9 + 2 S,), float32)``, all finite (``position_scale``: 1.5 x the prior's farthest start):

| index | content |
| --- | --- |
| 0-1 | the observer's position estimate relative to the array centroid / ``position_scale``, clipped |
| 2-3 | its velocity / 10 m/s, clipped |
| 4-5 | ``log10(std_x) / 3``, ``log10(std_y) / 3`` of its position covariance, clipped (1 mm .. 1 km) |
| 6 | the position correlation coefficient |
| 7 | the observer's status / 4 (0 no data, 0.25 initialising, 0.5 tracking, 0.75 restarted, 1 inconsistent) |
| 8 | elapsed fraction of the passage |
| 9 .. 8+S | per sensor: steps since it was last read / (K - 1), clipped to 1 |
| 9+S .. 8+2S | per sensor: its predicted information gain ``g / (1 + g)`` (below) |

``g`` is the drop (nats) of the log-det of the position covariance if that
sensor alone were read at the next step (:mod:`shipsense.design.information_gain`),
linearised at the observer's one-step prediction with the observer's own
noise model; 0 while the observer has no track (its estimate is then the
prior's mean, where a linearisation means nothing).

## Rewards

``-ln(1 + error / error_scale) - energy_cost * reads`` per step, with
``error`` the distance (m) of the observer's position estimate from the
truth after the step.  The error term uses the truth (the environment has
it), not the observer's covariance: a reward on the observer's own
covariance would pay an optimistic observer for being optimistic.  It is
logarithmic (metre-level improvements count while a 1 km error is not a
thousand times a 1 m one) but **not capped**: a diverged observer keeps
earning ever more negative rewards (10 km off: -9.2 per step with the
default 1 m scale).  Both terms are in ``info``.

## Starting state

A passage drawn from the scenario's ``[prior]`` (start range, bearing, course
offset, speed, moment) under the seed.  **Run-in**: the observer reads every
sensor from the first sample until it reports a track (its detection and the
global fit of its first window, 15 s of samples for magnetometers); the
agent's control starts there (the observation's elapsed
fraction says where).  While the observer has no track its estimate is the
prior's mean whatever is read, so those samples would add the same large
errors to every policy's return and hide the scheduling (on S2, before the
run-in, they made up most of every baseline's return: docs: Results).  A
passage that never gets a track leaves the agent one step.  The run-in does
not depend on the agent, so the environment does the run-ins of its next
passages ahead, in batches, on the process's background thread while the
agent steps (:mod:`shipsense.envs.prefetch`; episodes are the same to the
bit; ``SHIPSENSE_THREADS=1`` keeps everything on the calling thread).

## Episode end

Terminated at the passage's last sample (``K`` the scenario's ``steps``;
the episode has ``K - 1 - run-in`` steps).  No truncation.

## Info keys

Every step: ``error`` (m), ``nees`` (the position's normalised squared
error under the observer's covariance), ``inside95`` (``nees <= 5.991``),
``reads``, ``error_term``, ``energy_term``, ``truth`` and ``estimate`` (m),
``status``.  At the episode's end also ``episode_metrics``: ``mean_error_m``
(the task metric: the mean position error over the episode's steps),
``final_error_m``, ``coverage95`` (share of steps with the truth inside
the observer's 95 % ellipse), ``reads_per_step``, ``energy`` (the episode's
energy cost) and ``return`` -- plain floats.

## Baselines

:meth:`PassageV1Env.baseline` (``BASELINES``): ``random`` (a uniformly
random subset of exactly ``k`` sensors), ``round-robin`` (the ``k`` sensors
read longest ago; ties to the lowest index), ``greedy`` (the subset of ``k``
sensors with the largest predicted drop of the position covariance's
log-det, all subsets searched; round-robin while the observer has no track).

## Arguments

``scenario`` (shipped name or TOML path), ``overrides`` (dict of top-level
scenario fields, e.g. ``{"steps": 60}``), ``k`` (reads per step, default 1),
``energy_cost`` (per read, default 0.01), ``error_scale`` (m, default 1),
``render_mode`` (``"rgb_array"`` or ``"human"``).  All JSON-able; a bad
value raises one ``ValueError`` naming the argument.

## Variants (registered)

``shipsense.envs.PASSAGE_V1_VARIANTS`` (S2's noise, 0.5 nT magnetometers):

* ``shipsense/Passage-v1``: four vector magnetometers on a line 40 m apart,
  one read per step, 100 samples, starts 100-160 m out: which magnetometer
  is near the ship changes along the passage.
* ``shipsense/PassageEasy-v1``: S2's array (two magnetometers and a bearing
  accelerometer within 10 m), one read per step.
* ``shipsense/PassageHard-v1``: six magnetometers 30 m apart, 2 of 6 per
  step, 10 % outliers (10 sigma), 10 % dropouts, starts 100-250 m out,
  moments 3e3-3e4 A m^2, 120 samples.

Their ``reward_threshold`` is the greedy baseline's mean return on held-out
passages (docs: Results, ``experiments/passage_baselines.py``); for the hard
variant the best baseline's (random), as greedy, which trusts an observer
that loses most of those passages, scores worse there.  Keyword
arguments to ``gymnasium.make`` replace a variant's: ``overrides`` replaces
its whole ``overrides`` dict.

## Version history

* v1: the agent picks a subset of at most ``k`` sensors (``Discrete``, no
  trimming), uncapped log-error reward, time since each read and predicted
  information gains observed, episode metrics and baselines.  Since
  2026-11-26 the vector env's seeded partial reset reseeds only the masked
  sub-environments (gymnasium's ``SyncVectorEnv`` rule; it reseeded all, so
  the others' later blocks of passages came from the new seeds): no
  version bump, as the dynamics, reward and spaces are unchanged.
* v0 (``shipsense/Passage-v0``): a ``MultiBinary`` action trimmed to
  ``max_reads``, the error reward capped at 100 m, the hypotheses'
  likelihoods and the SNRs of the sensors read observed.  Retired on
  2026-11-28: its module, registration and tests removed (it could not run
  on v1's core as arguments); the docs' Results keep its figures.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from shipsense.envs.core_env import SEED_HIGH, ClosesItsFigure, CoreVectorEnv, RebuiltOnUnpickle, seed_ahead
from shipsense.envs.passage_core import CHI2_2_95, PassageV1Core, action_of, subsets

BASELINES = ("random", "round-robin", "greedy")


def observation_potential(obs):
    """``-1/2 ln det`` (nats, position in m) of the observer's position covariance as observations (..., obs_dim)
    state it (indices 4-6; the stds' clip at 1 mm .. 1 km and a correlation of at most 1 - 1e-6 in magnitude):
    the potential of ``shipsense train scheduling --shaping`` (:class:`~shipsense.envs.sb3.PotentialShaping`).
    A read that shrinks the covariance raises it by about the predicted gain of the observation's last
    columns."""
    obs = np.asarray(obs, dtype=float)
    rho2 = np.minimum(obs[..., 6] ** 2, 1.0 - 1e-6)
    return -0.5 * (6.0 * np.log(10.0) * (obs[..., 4] + obs[..., 5]) + np.log1p(-rho2))


def passage_spaces(core):
    """The observation and action spaces of a Passage core's environments."""
    low = -np.ones(core.obs_dim, dtype=np.float32)
    low[7:9] = 0.0
    low[9:] = 0.0
    return spaces.Box(low, np.ones(core.obs_dim, dtype=np.float32), dtype=np.float32), \
        spaces.Discrete(len(core.subsets))


class _Policy:
    """A baseline policy: ``policy(obs) -> action`` (reads the environment's internal state; ``obs`` unused)."""

    def __init__(self, core, name, seed, single):
        self.core, self.name, self.single = core, name, single
        self.rng = np.random.default_rng(seed)

    def __call__(self, obs=None):
        c = self.core
        a = (c.random_actions(self.rng) if self.name == "random" else
             c.round_robin_actions() if self.name == "round-robin" else c.greedy_actions())
        return int(a[0]) if self.single else a

    def __repr__(self):
        return f"<{self.name} baseline of a Passage environment>"


def _check_baseline(name):
    if name not in BASELINES:
        raise ValueError(f"unknown baseline {name!r}; offered: {', '.join(BASELINES)}")


class PassageV1Env(RebuiltOnUnpickle, ClosesItsFigure, gym.Env):
    __doc__ = __doc__
    metadata = {"render_modes": ["rgb_array", "human"], "render_fps": 4}
    BASELINES = BASELINES
    potential = staticmethod(observation_potential)

    def __init__(self, scenario="S2", overrides=None, k=1, energy_cost=0.01, error_scale=1.0, render_mode=None):
        self.adopt_core(lambda: PassageV1Core(1, scenario, overrides, k, energy_cost, error_scale), render_mode,
                        dict(scenario=scenario, overrides=overrides, k=k, energy_cost=energy_cost,
                             error_scale=error_scale))

    def adopt_core(self, make_core, render_mode, kwargs):
        """Set this environment up on the core ``make_core()`` (of one environment) with its spaces, after
        checking ``render_mode``; ``kwargs``: the constructor's other arguments (what a pickle of the environment
        rebuilds it from)."""
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']}, got {render_mode!r}")
        self.core = make_core()
        self.observation_space, self.action_space = passage_spaces(self.core)
        self.subsets = self.core.subsets
        self.render_mode = render_mode
        self._started = False
        self._fig = None
        self._kwargs = {**kwargs, "render_mode": render_mode}

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        obs = self.core.reset_envs([0], [int(self.np_random.integers(SEED_HIGH))], fresh=seed is not None,
                                   ahead=lambda e, j: seed_ahead(self.np_random, j))
        self._started = True
        if self.render_mode == "human":
            self.render()
        return obs[0], {}

    def expect_seeds(self, seeds):
        """Announce that the next resets will be ``reset(seed=s)`` for ``s`` in ``seeds``, in that order (an
        evaluation's episodes, :func:`~shipsense.envs.evaluation.run_episodes`): their passages and run-ins are
        then done ahead on the background thread, in batches.  Optional: every episode is the same with or
        without it, and a reset with another seed, or none, draws its passage as ever."""
        from gymnasium.utils import seeding

        self.core.expect(int(seeding.np_random(int(s))[0].integers(SEED_HIGH)) for s in seeds)   # (as needed)

    def step(self, action):
        if not self._started:
            raise RuntimeError("call reset() before step()")
        if self.core.k[0] >= self.core.K - 1:
            raise RuntimeError("the passage has ended: call reset()")
        if not (0 <= action < self.action_space.n if type(action) is int else self.action_space.contains(action)):
            raise ValueError(f"action must be an integer in [0, {self.action_space.n}), got {action!r}")
        rewards, terminated, _, info = self.core.step(np.array([int(action)]))
        obs = self.core.observe()[0]
        info = {k: v[0] for k, v in info.items()}
        done = bool(terminated[0])
        if done:
            info["episode_metrics"] = {k: float(v[0]) for k, v in self.core.episode_metrics([0]).items()}
        if self.render_mode == "human":
            self.render()
        return obs, float(rewards[0]), done, False, info

    def close(self):
        self.core.drop_pending()
        super().close()

    def baseline(self, name, seed=None):
        """The baseline policy ``name`` (one of :attr:`BASELINES`): ``policy(obs) -> action``; ``seed`` seeds
        ``random``'s own generator (the environment's is left alone)."""
        _check_baseline(name)
        return _Policy(self.core, name, seed, single=True)

    def render(self):
        if self.render_mode == "rgb_array":
            return self.core.render(0)
        if self.render_mode == "human":
            from shipsense.plotting import plt

            img = self.core.render(0)
            if self._fig is None:
                plt.ion()
                self._fig, ax = plt.subplots()
                ax.set_axis_off()
                self._img = ax.imshow(img)
            else:
                self._img.set_data(img)
            self._fig.canvas.draw_idle()
            plt.pause(1.0 / self.metadata["render_fps"])
        return None


class PassageV1VectorEnv(CoreVectorEnv):
    """Native vector version of ``shipsense/Passage-v1``: one :class:`PassageV1Core` (one batched tracker) for
    all sub-environments, on :class:`~shipsense.envs.core_env.CoreVectorEnv` (next-step autoreset, gymnasium's
    vector ``info`` with ``_key`` masks, an int or a list of seeds, the partial reset
    ``reset(options={"reset_mask": mask})`` that SB3's adapter, :class:`~shipsense.envs.sb3.VectorEnvAdapter`,
    calls in the step an episode ends).

    Sub-environment ``i`` reset with an integer ``seed`` behaves exactly like a single :class:`PassageV1Env`
    reset with ``seed + i``.  A seeded partial reset reseeds only the masked sub-environments; the others'
    streams and the run-ins done ahead for them are kept.
    """

    BASELINES = BASELINES
    potential = staticmethod(observation_potential)
    """The shaping potential of training (:func:`observation_potential`)."""

    def __init__(self, num_envs=1, scenario="S2", overrides=None, k=1, energy_cost=0.01, error_scale=1.0,
                 render_mode=None):
        self.check_render_mode(render_mode)
        self.start_on(PassageV1Core(num_envs, scenario, overrides, k, energy_cost, error_scale), render_mode)

    def start_on(self, core, render_mode):
        """Set this vector environment up on ``core`` (of ``num_envs`` environments) with its spaces."""
        CoreVectorEnv.__init__(self, core, passage_spaces(core), render_mode)
        self.subsets = core.subsets

    def close_extras(self, **kwargs):
        self.core.drop_pending()

    def baseline(self, name, seed=None):
        """The batched baseline policy ``name``: ``policy(obs) -> actions`` (num_envs,)."""
        _check_baseline(name)
        return _Policy(self.core, name, seed, single=False)


__all__ = ["BASELINES", "CHI2_2_95", "PassageV1Core", "PassageV1Env", "PassageV1VectorEnv", "action_of",
           "observation_potential", "passage_spaces", "subsets"]

