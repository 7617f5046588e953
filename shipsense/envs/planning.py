r"""Planning baselines of the Passage environments: ``greedy-threshold``, ``rollout`` and the offline ``hindsight``
reference (``shipsense evaluate --policy NAME``).

They run on any environment whose core is a :class:`~shipsense.envs.passage_core.PassageV1Core` (the single
environments of ``shipsense/Passage-v1``, ``shipsense/Passage-v2`` and their variants), and need nothing of it
but its spaces, its observer and its reward's parts (its error weights, wake-up cost and budget).

``greedy-threshold``
    The greedy baseline's subset (the ``k`` sensors with the largest predicted drop :math:`g` of the
    position covariance's log-det, :mod:`shipsense.design.information_gain`) when its predicted gain exceeds a
    threshold :math:`\tau` (nats), else no read.  :math:`\tau = 0` is the greedy baseline (a subset of positive
    gain is always read).  :math:`\tau` is given, or fitted by :func:`fit_threshold`: the grid
    :data:`THRESHOLDS`' value with the largest mean return over training episodes (seeds from
    :data:`FIT_SEED`, far from ``shipsense evaluate``'s held-out seeds).  While the observer has no track it is
    the greedy baseline (round-robin).

``rollout``
    One step of policy improvement over greedy by Monte Carlo rollouts (Bertsekas' rollout algorithm).  At
    every decision, for each action :math:`a` and each of :math:`F` futures :math:`f`,

    .. math::  Q(a) = \frac{1}{F} \sum_f \Big[\sum_{j=1}^{H} r_j(a, f)
               - \Big(\sum_{t > k + H} w_t\Big) \ln\big(1 + e_H(a, f) / e_s\big)\Big],

    the return of :math:`H` steps that read :math:`a` first and then follow greedy, with the environment's
    own reward :math:`r_t = -w_t \ln(1 + e_t / e_s) - \text{energy}_t` (:math:`e` the observer's error
    against the future's truth, :math:`w_t` the core's error weights, ``error_weights``: 1 at every step in
    Passage-v1; the energy the reads' and, in Passage-v2, the wake-ups'), and the last step's error held for
    the samples left in the passage after the horizon, as they will weigh it (:data:`TAILS`: a read goes on
    paying off after it; in Passage-v1, :math:`T - H` times the last error term).  A future is drawn
    **from the observer's belief**, never from the environment's passage: the ship's state
    :math:`x_0 \sim \mathcal N(\hat x, P)` from the observer's selected estimate and its
    covariance, carried by the observer's motion model (``x_{j+1} = A x_j``), its samples
    :math:`y_j = h(x_j) + v_j` with the scenario's noise (its outliers and dropouts too).  Every action meets
    the same futures (common random numbers: the differences of :math:`Q` are not buried in the futures'
    spread).  The observer of every (action, future) pair is a copy of the environment's, all of them one
    batch of a sibling tracker (:meth:`~shipsense.envs.passage_core.PassageV1Core.twin`), so a decision costs
    :math:`H` batched steps of :math:`A F` passages.  The action of the largest :math:`Q` is taken (ties to the
    lowest index).

``hindsight``
    The offline reference no fair policy should pass: at the start of each episode it reads the environment's
    true passage and chooses the whole schedule :math:`a_{1..T}` maximising the **linearised** return

    .. math::  \sum_{t=1}^{T} -w_t \ln\!\Big(1 + \sqrt{\operatorname{tr} P^{pp}_t} / e_s\Big) - c\,|a_t|
               - c_w\,|a_t \setminus a_{t-1}|, \qquad
               P_t^{-1} = A^{-T} P_{t-1}^{-1} A^{-1} + \sum_{s \in a_t} J_{s,t},

    subject to :math:`\sum_t |a_t|` within the reads left (:class:`ScheduleCosts`: the core's error
    weights :math:`w_t`, wake-up cost :math:`c_w` and budget; none but :math:`c` in Passage-v1),

    from the observer's covariance :math:`P_0` at the start of control, with :math:`J_{s,t}` the Fisher
    information of sensor :math:`s`'s samples at :math:`t` (:mod:`shipsense.design.fisher`'s
    :math:`H^T R^{-1} H`, the observer's noise model, linearised at the **true** state; a dropped sample
    gives none), by beam search (:func:`plan_schedule`: every schedule while the beam holds them all, hence
    exact on short passages) followed by coordinate ascent.  The schedule is then replayed through the
    environment, so that it is scored in the environment's reward like every other policy.

Every policy is a callable ``policy(obs) -> action`` and has ``describe()``, the settings it ran with (a
fitted threshold, a planner's sizes).
"""

from __future__ import annotations

import numpy as np

from shipsense.arguments import number
from shipsense.envs.passage_core import PassageV1Core
from shipsense.physics.noise import dropout_mask
from shipsense.physics.seismic import wrap_axial
from shipsense.trackers.tracker.results import INITIALISING, NO_DATA

PLANNERS = ("greedy-threshold", "rollout", "hindsight")
"""The planning baselines' names (``shipsense evaluate --policy``)."""
THRESHOLDS = (0.0, 0.005, 0.01, 0.02, 0.03, 0.05, 0.075, 0.1, 0.15, 0.2, 0.3, 0.5)
"""The thresholds (nats) :func:`fit_threshold` tries by default."""
FIT_SEED = 3_000_000
"""First seed of :func:`fit_threshold`'s training episodes (away from ``shipsense evaluate``'s held-out seeds,
2,000,000 and up, and from ``shipsense train``'s held-out evaluations, 1,000,000 and up)."""
FIT_EPISODES = 30
"""Training episodes of :func:`fit_threshold`."""
ROLLOUT_HORIZON = 8
"""Rollout's default horizon (steps), on every Passage environment: chosen on training passages of
``shipsense/Passage-v2`` (seeds 4,200,000 and up, paired against greedy and against horizon 4, the earlier default;
docs: Results), whose checkpoints are about 25 samples apart: a longer look ahead simulates more of the way from a
read to the checkpoint it pays at."""
ROLLOUT_SAMPLES = 32
"""Rollout's default number of futures drawn from the observer's belief per decision."""
TAILS = ("hold", "none")
"""What a rollout counts after its horizon: ``hold``, the last simulated step's error term for every step left
in the passage (reads go on paying off after the horizon; without it, a short horizon sees a read's energy
but little of its gain); ``none``, nothing."""


def offers(env):
    """Whether ``env`` (a single environment, wrapped or not) runs on a Passage core the planners can drive."""
    return isinstance(getattr(env.unwrapped, "core", None), PassageV1Core)


def planner(env, name, seed=None, **options):
    """The planning baseline ``name`` (one of :data:`PLANNERS`) for the single environment ``env``:
    ``policy(obs) -> action``.  ``seed`` seeds a policy's own generator (rollout's futures); ``options``:
    ``threshold`` (greedy-threshold: nats, default fitted), ``fit_episodes``, ``fit_seed`` (its fit);
    ``horizon``, ``samples``, ``tail`` (rollout, :data:`TAILS`); ``beam`` (hindsight).  A bad name or option
    raises one ``ValueError``."""
    if not offers(env):
        raise ValueError(f"policy {name!r} needs a Passage environment")
    core = env.unwrapped.core
    allowed = {"greedy-threshold": ("threshold", "fit_episodes", "fit_seed"),
               "rollout": ("horizon", "samples", "tail"), "hindsight": ("beam",)}
    if name not in allowed:
        raise ValueError(f"unknown planner {name!r}; offered: {', '.join(PLANNERS)}")
    unknown = sorted(set(options) - set(allowed[name]))
    if unknown:
        raise ValueError(f"policy_kwargs: {name} takes {', '.join(allowed[name])}, not {', '.join(unknown)}")
    if name == "greedy-threshold":
        return GreedyThreshold(core, **options)
    if name == "rollout":
        return Rollout(core, seed=seed, **options)
    return Hindsight(core, **options)


def _blind(core, rows):
    """Whether the observers of environments ``rows`` have no track yet (no data or initialising)."""
    status = core.last.status[rows]
    return (status == NO_DATA) | (status == INITIALISING)


def threshold_actions(core, threshold):
    """Greedy's subset where its predicted gain exceeds ``threshold`` (nats; a scalar or one per environment),
    else action 0 (no read); greedy (round-robin) while an observer has no track.  Actions (E,)."""
    rows = np.arange(core.E)
    greedy = core.greedy_actions()
    keep = _blind(core, rows) | (core.gains[rows, greedy] > threshold)
    return np.where(keep, greedy, 0)


class GreedyThreshold:
    """``greedy-threshold`` (the module docstring) on a core's environment 0: ``policy(obs) -> action``."""

    def __init__(self, core, threshold=None, fit_episodes=FIT_EPISODES, fit_seed=FIT_SEED):
        self.core = core
        self.fit = None
        if threshold is None:
            self.fit = fit_threshold(core, episodes=fit_episodes, seed=fit_seed)
            threshold = self.fit["threshold"]
        self.threshold = number("threshold", threshold, 0.0, 1e3)

    def __call__(self, obs=None):
        return int(threshold_actions(self.core, self.threshold)[0])

    def describe(self):
        return {"threshold": self.threshold, **({"fit": self.fit} if self.fit is not None else {})}


def episode_seed(seed):
    """The passage seed a single Passage environment's ``reset(seed=seed)`` hands its core."""
    from gymnasium.utils import seeding

    from shipsense.envs.core_env import SEED_HIGH

    return int(seeding.np_random(int(seed))[0].integers(SEED_HIGH))


def run_batch(core, seeds, act):
    """Run one episode per seed on a :meth:`~shipsense.envs.passage_core.PassageV1Core.twin` of ``core``
    (environment ``i`` the episode a single environment reset with ``seeds[i]`` meets; a seed given twice is
    drawn and run in once, then copied), every step's actions ``act(twin) -> (E,)``.  Returns the episodes'
    returns (E,)."""
    distinct, which = np.unique(np.asarray(seeds, dtype=np.int64), return_inverse=True)
    first = core.twin(distinct.size)             # (each passage and its run-in once)
    first.reset_envs(np.arange(distinct.size), [episode_seed(s) for s in distinct.tolist()], fresh=True)
    twin = core.twin(len(seeds))
    twin.copy_envs(first, which, np.arange(twin.E))
    twin.y[:], twin.truth[:] = first.y[which], first.truth[which]
    live = twin.k < twin.K - 1
    while live.any():
        twin.step(act(twin), envs=np.flatnonzero(live))
        live = twin.k < twin.K - 1
    return twin.returns.copy()


def fit_threshold(core, thresholds=THRESHOLDS, episodes=FIT_EPISODES, seed=FIT_SEED):
    """The threshold (nats) of ``thresholds`` with the largest mean return of ``greedy-threshold`` over
    ``episodes`` training episodes (seeds ``seed, seed + 1, ...``, the same episodes for every threshold: all
    of them one batch of ``len(thresholds) x episodes`` environments; ties to the smallest).  Returns
    ``threshold``, ``grid`` (the thresholds), ``mean_return`` (per threshold), ``episodes``, ``seed``."""
    episodes = number("fit_episodes", episodes, 1, 10_000, integer=True)
    seed = number("fit_seed", seed, 0, 2**31 - 1 - episodes, integer=True)
    grid = np.asarray(thresholds, dtype=float)
    per_row = np.repeat(grid, episodes)
    returns = run_batch(core, [seed + i for _ in grid for i in range(episodes)],
                        lambda twin: threshold_actions(twin, per_row))
    means = returns.reshape(grid.size, episodes).mean(axis=1)
    best = int(np.argmax(means))
    return {"threshold": float(grid[best]), "grid": grid.tolist(), "mean_return": means.tolist(),
            "episodes": episodes, "seed": seed}


# -- rollout --------------------------------------------------------------------------------------------------
def belief_futures(core, e, rng, samples, steps):
    """``samples`` futures of environment ``e`` drawn from its observer's belief, ``steps`` samples after the
    current one: the truths (samples, steps + 1, n) SI (the current sample first) and the samples
    (samples, steps + 1, m) SI (the first row NaN: it is the past).  The state is drawn from the observer's
    estimate and covariance (a symmetric square root, negative eigenvalues clipped), carried by the model's
    transition; the samples are the model's readings with the scenario's noise (outliers, dropouts; bearings
    wrapped).  Reads ``rng`` only -- never the environment's passage nor its generator."""
    model, sc = core.model, core.scenario
    est, cov = core.last.estimate[e], core.last.cov[e]
    w, V = np.linalg.eigh(0.5 * (cov + cov.T))
    root = V * np.sqrt(np.clip(w, 0.0, None))
    x0 = est + rng.standard_normal((samples, est.size)) @ root.T
    x = model.to_internal(x0)
    states = np.empty((samples, steps + 1, est.size))
    for j in range(steps + 1):
        states[:, j] = x
        x = x @ model.A.T
    truth = model.to_si(states)
    clean = model.h(states) * model.y_scale
    shape = clean.shape
    noise = np.asarray(sc.channel_std) * rng.standard_normal(shape)
    if sc.noise.model == "contaminated":
        noise = np.where(rng.random(shape) < sc.noise.eps, sc.noise.outlier_scale * noise, noise)
    y = clean + noise
    if model.axial.any():
        y[..., model.axial] = wrap_axial(y[..., model.axial])
    y = np.where(dropout_mask(rng, shape, sc.noise.dropout), y, np.nan)
    y[:, 0] = np.nan
    return truth, y


class Rollout:
    """``rollout`` (the module docstring) on a core's environments: ``policy(obs) -> action`` (environment 0's;
    a core of several environments decides for each in turn, ``actions()``)."""

    def __init__(self, core, horizon=ROLLOUT_HORIZON, samples=ROLLOUT_SAMPLES, seed=None, tail="hold"):
        self.core = core
        self.horizon = number("horizon", horizon, 1, 10_000, integer=True)
        self.samples = number("samples", samples, 1, 100_000, integer=True)
        if tail not in TAILS:
            raise ValueError(f"tail must be one of {', '.join(TAILS)}, got {tail!r}")
        self.tail = tail
        self.rng = np.random.default_rng(seed)
        self.A = len(core.subsets)
        self.twin = None
        self.last_values = None   # the last decision's Q (A,)

    def __call__(self, obs=None):
        return int(self.decide(0))

    def actions(self, obs=None):
        """The decision of every environment of the core (E,): a teacher of several environments at once
        (``shipsense train scheduling --imitate rollout``)."""
        return np.array([self.decide(e) for e in range(self.core.E)])

    def describe(self):
        return {"horizon": self.horizon, "samples": self.samples, "tail": self.tail, "candidates": self.A}

    def decide(self, e):
        """Environment ``e``'s action: greedy's while its observer has no track or its passage is over (a vector
        environment's step before its autoreset), else the action of the largest mean rollout return
        (:meth:`values`)."""
        core = self.core
        if _blind(core, [e])[0] or core.k[e] >= core.K - 1:
            return int(core.greedy_actions()[e])
        q = self.values(e)
        self.last_values = q
        return int(np.argmax(q))

    def values(self, e):
        """The mean return (A,) over the futures of each action followed by greedy, ``horizon`` steps (fewer at
        the passage's end)."""
        core, A, F = self.core, self.A, self.samples
        steps = min(self.horizon, core.K - 1 - int(core.k[e]))
        if self.twin is None:
            self.twin = core.twin(A * F)
        twin = self.twin
        rows = np.arange(A * F)
        twin.copy_envs(core, np.full(A * F, e), rows)
        truth, y = belief_futures(core, e, self.rng, F, steps)
        k = int(core.k[e])
        twin.truth[:, k:k + steps + 1] = np.tile(truth, (A, 1, 1))      # row a * F + f: action a, future f
        twin.y[:, k:k + steps + 1] = np.tile(y, (A, 1, 1))
        twin.returns[:] = 0.0
        actions = np.repeat(np.arange(A), F)
        for _ in range(steps):
            _, _, _, info = twin.step(actions)
            actions = twin.greedy_actions()
        value = twin.returns.copy()
        if self.tail == "hold":             # the last error term held to the passage's end, as it will count
            value += core.error_weights[k + steps + 1:].sum() * -np.log1p(info["error"] / core.error_scale)
        return value.reshape(A, F).mean(axis=1)


# -- hindsight ------------------------------------------------------------------------------------------------
def sensor_information(core, e):
    """Fisher information (T, S, n, n) (internal units) of each sensor's samples at each of environment ``e``'s
    steps ``start + 1 .. K - 1``, linearised at its **true** states with the observer's noise model; a dropped
    sample (NaN) gives none.  Offline: reads the environment's passage."""
    model = core.model
    ks = np.arange(int(core.start[e]) + 1, core.K)
    H = model.H(model.to_internal(core.truth[e, ks]))                        # (T, m, n)
    present = np.isfinite(core.y[e, ks])                                      # (T, m)
    Rinv = 1.0 / core.tracker.filter_model.R
    w = np.where(present, Rinv[None], 0.0)
    out = np.zeros((ks.size, core.S, model.n, model.n))
    for s in range(core.S):
        ch = core.sensor_of == s
        out[:, s] = np.einsum("tia,ti,tib->tab", H[:, ch], w[:, ch], H[:, ch])
    return out


class ScheduleCosts:
    """What a schedule's linearised return counts besides the error (a Passage core's reward): the error
    term's weight per step ``weights`` (T,) (default 1), ``wake_cost`` per sensor read that was not read at the
    step before (``last``, (S,) bool, the sensors read before the first step), and ``budget``, the reads left
    (a schedule that reads more is infeasible: return ``-inf``)."""

    def __init__(self, T, S, weights=None, wake_cost=0.0, last=None, budget=np.inf):
        self.weights = np.ones(T) if weights is None else np.asarray(weights, dtype=float)
        self.wake_cost = float(wake_cost)
        self.last = np.ones(S, dtype=bool) if last is None else np.asarray(last, dtype=bool)
        self.budget = float(budget)

    @classmethod
    def of(cls, core, e):
        """Environment ``e``'s costs from its next step to its passage's end (a Passage core)."""
        k = int(core.k[e])
        return cls(core.K - 1 - k, core.S, core.error_weights[k + 1:], core.wake_cost, core.last_read[e],
                   core.budget - core.reads[e])


def linearised_rewards(info0, J, Ainv, subsets, schedules, energy_cost, error_scale, costs=None):
    """The linearised return (the module docstring) of each of ``schedules`` (B, T) (action indices), from the
    initial information ``info0`` (n, n), sensors' information ``J`` (T, S, n, n), ``Ainv`` the transition's
    inverse, ``costs`` a :class:`ScheduleCosts` (default: none but ``energy_cost`` per read).  Returns (B,)."""
    schedules = np.asarray(schedules)
    B, T = schedules.shape
    costs = costs or ScheduleCosts(T, subsets.shape[1])
    Y = np.broadcast_to(info0, (B,) + info0.shape).copy()
    last = np.broadcast_to(costs.last, (B, subsets.shape[1]))
    used = np.zeros(B)
    total = np.zeros(B)
    for t in range(T):
        Y, r, last, used = _advance(Y, J[t], Ainv, subsets, schedules[:, t], energy_cost, error_scale, costs, t,
                                    last, used)
        total += r
    return total


def _advance(Y, Jt, Ainv, subsets, actions, energy_cost, error_scale, costs, t, last, used):
    """One step ``t`` of the information recursion for informations ``Y`` (B, n, n) under ``actions`` (B,), the
    sensors ``last`` (B, S) read at the step before, ``used`` (B,) reads so far: the new informations, the
    step's linearised rewards (``-inf`` over the budget), the reads and the reads so far."""
    read = subsets[actions]
    Y = Ainv.T @ Y @ Ainv + np.einsum("bs,sij->bij", read.astype(float), Jt)
    Y = 0.5 * (Y + np.swapaxes(Y, 1, 2))
    P = np.linalg.inv(Y)
    err = np.sqrt(np.clip(P[:, 0, 0] + P[:, 1, 1], 0.0, None))
    count = read.sum(axis=1)
    r = -costs.weights[t] * np.log1p(err / error_scale) - energy_cost * count
    if costs.wake_cost:
        r = r - costs.wake_cost * (read & ~last).sum(axis=1)
    used = used + count
    if np.isfinite(costs.budget):
        r = np.where(used > costs.budget, -np.inf, r)
    return Y, r, read, used


def plan_schedule(info0, J, Ainv, subsets, energy_cost, error_scale, beam=256, sweeps=3, costs=None):
    """The schedule (T,) (action indices) of the largest linearised return, and that return: beam search (the
    ``beam`` partial schedules of the largest return so far kept at each step; every schedule while
    ``A^t <= beam``, so exact for short passages), then up to ``sweeps`` sweeps of coordinate ascent (each
    step's action changed alone, kept where the whole return grows).  The returned value is never below the
    beam's best nor, with ``A^T <= beam``, below any schedule's.  ``costs``: :func:`linearised_rewards`'."""
    A, T = len(subsets), J.shape[0]
    n = info0.shape[0]
    costs = costs or ScheduleCosts(T, subsets.shape[1])
    Y = info0[None].copy()
    last, used = costs.last[None].copy(), np.zeros(1)
    score = np.zeros(1)
    paths = np.zeros((1, 0), dtype=np.int64)
    for t in range(T):
        b = Y.shape[0]
        acts = np.tile(np.arange(A), b)
        Yn, r, ln, un = _advance(np.repeat(Y, A, axis=0), J[t], Ainv, subsets, acts, energy_cost, error_scale,
                                 costs, t, np.repeat(last, A, axis=0), np.repeat(used, A))
        s = np.repeat(score, A) + r
        keep = np.argsort(-s, kind="stable")[:beam]
        Y, score, last, used = Yn[keep], s[keep], ln[keep], un[keep]
        paths = np.concatenate([np.repeat(paths, A, axis=0)[keep], acts[keep, None]], axis=1)
    best = paths[0].copy()
    value = float(score[0])
    for _ in range(int(sweeps)):
        improved = False
        for t in range(T):
            trial = np.repeat(best[None], A, axis=0)
            trial[:, t] = np.arange(A)
            v = linearised_rewards(info0.reshape(n, n), J, Ainv, subsets, trial, energy_cost, error_scale, costs)
            a = int(np.argmax(v))
            if v[a] > value + 1e-12:
                best, value, improved = trial[a], float(v[a]), True
        if not improved:
            break
    return best, value


class Hindsight:
    """``hindsight`` (the module docstring) on a core's environments: plans at the first step of each episode, then
    replays the schedule; ``policy(obs) -> action`` is environment 0's, ``actions()`` every environment's (a
    teacher of a vector environment, ``shipsense train scheduling --imitate hindsight``)."""

    def __init__(self, core, beam=256):
        self.core = core
        self.beam = number("beam", beam, 1, 1_000_000, integer=True)
        self.plans = {}                       # environment -> (its schedule, its linearised value)

    @property
    def schedule(self):
        """Environment 0's schedule (action indices from its first step), or None before its first decision."""
        return self.plans.get(0, (None, None))[0]

    @property
    def value(self):
        """The linearised return of environment 0's schedule, or None."""
        return self.plans.get(0, (None, None))[1]

    def problem(self, e=0):
        """Environment ``e``'s linearised problem: initial information (n, n), sensors' information (T, S, n, n),
        the transition's inverse (internal units)."""
        core = self.core
        P0 = core.model.cov_to_internal(core.last.cov[e])
        info0 = np.linalg.inv(0.5 * (P0 + P0.T))
        return info0, sensor_information(core, e), np.linalg.inv(core.model.A)

    def decide(self, e):
        """Environment ``e``'s action: its schedule's at this step, planned at the episode's first step; greedy's
        once its passage is over (a vector environment's step before its autoreset)."""
        core = self.core
        k, start = int(core.k[e]), int(core.start[e])
        if k >= core.K - 1:
            return int(core.greedy_actions()[e])
        if k == start or e not in self.plans:
            info0, J, Ainv = self.problem(e)
            self.plans[e] = plan_schedule(info0, J, Ainv, core.subsets, core.energy_cost, core.error_scale,
                                          beam=self.beam, costs=ScheduleCosts.of(core, e))
        return int(self.plans[e][0][k - start])

    def __call__(self, obs=None):
        return self.decide(0)

    def actions(self, obs=None):
        """The decision of every environment of the core (E,)."""
        return np.array([self.decide(e) for e in range(self.core.E)])

    def describe(self):
        return {"beam": self.beam}


__all__ = ["FIT_EPISODES", "FIT_SEED", "PLANNERS", "ROLLOUT_HORIZON", "ROLLOUT_SAMPLES", "THRESHOLDS",
           "GreedyThreshold", "Hindsight", "Rollout", "ScheduleCosts", "belief_futures", "episode_seed",
           "fit_threshold", "linearised_rewards", "offers", "plan_schedule", "planner", "run_batch",
           "sensor_information", "threshold_actions"]
