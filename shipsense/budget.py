"""The work budget: a command's memory and time, estimated from its inputs before any of it is allocated.

A command multiplies its inputs (runs x steps x hypotheses x channels, candidates x passages, rows of a
recording) into a :class:`Work` estimate and calls :func:`enforce`, which refuses work above the limits with
one line naming the flag that raises them (``--max-memory GB``, ``--max-minutes MIN``), before anything is
allocated: ``--runs 1e9`` is a message, not a 67 GB allocation or a run that never ends.

The rates are measured on this project's reference machine (2 cores; ``shipsense reproduce S0|S1|S2 --runs N``
at two N, ``benchmarks/track_rows.py``, ``benchmarks/check.py`` on S0, S2 and S1-P2), rounded towards the fast
side, so that the estimate refuses only work that is certainly beyond the limit and never a run that would
have fitted. They are an order-of-magnitude guard, not a prediction: a faster machine finishes sooner.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from shipsense.errors import ShipsenseError

MEMORY_LIMIT_GB = 8.0
"""Largest estimated memory a command allocates unless ``--max-memory`` says otherwise (GB)."""
TIME_LIMIT_MINUTES = 180.0
"""Longest estimated run a command starts unless ``--max-minutes`` says otherwise (minutes)."""

# measured rates (reference machine), on the fast side
SIMULATE_S_PER_VALUE = 2e-8           # per run x step x channel: kernels, noise, envelope chain
TRACK_S_PER_VALUE = 1.5e-4            # the project's tracker, per sample x channel (a recording's row; track_rows.py)
TRACK_BYTES_PER_SAMPLE = 3_000.0      # estimates, covariances, status and the recording's own arrays, per sample
TRACK_BYTES_PER_CHANNEL = 2.8e6       # the initialiser's grid, per channel (track of 100 and 200 vector
#                                       magnetometers, 300 steps: 2.9 MB a channel above one magnetometer's run)
RECORDING_BYTES_PER_LINE = 20.0       # a CSV line "time,sensor,channel,value" is at least this long
RECORDING_BYTES_PER_VALUE = 8.0       # a NetCDF/HDF5 or miniSEED value: float64, at most this long uncompressed
STUDY_S_PER_RUN = {"S0": 0.15, "S1": 0.3, "S2": 0.5}
STUDY_BYTES_PER_RUN = {"S0": 3e6, "S1": 1e6, "S2": 2e7}
WIDE_S_PER_PASSAGE = 0.3              # three families, one process (shipsense reproduce wide)
WIDE_BYTES_PER_CHUNK = 5e8            # one chunk of passages in one worker
CHECK_S_PER_VALUE = 1.5e-4            # ambiguity search per passage x step x channel (benchmarks/check.py)
PPO_S_PER_STEP = {"scheduling": 4e-3, "placement": 2e-3}   # PPO on Passage-v1 (16 envs) and on ArrayDesign-v1
TRAIN_EVALUATION_S = {"scheduling": 120.0, "placement": 40.0}   # a held-out evaluation, per 200 episodes
EVALUATE_S_PER_EPISODE = {"convex": 5.0, "rollout": 5.0, "hindsight": 1.5}   # convex: design_array per site (S1-P2,
# 81 candidates); rollout, hindsight: Passage-v1 planning baselines at their defaults; the others far less
DESIGN_S_PER_VALUE = 5e-7             # Fisher build per candidate x passage x step x channel (benchmarks/design.py)


class WorkTooLarge(ShipsenseError):
    """A command's estimated memory or time is above the limit; the message names the flag that raises it."""


@dataclass(frozen=True)
class Work:
    """An estimate of a command's work.

    Attributes
    ----------
    what : str
        The work in the user's words, e.g. ``"2000 runs of S0 (300 steps)"``.
    bytes : float
        Peak memory it allocates, roughly (bytes).
    seconds : float
        Wall time on the reference machine, roughly (s).
    fewer : str
        What to reduce to make it smaller, e.g. ``"--runs"``.
    """

    what: str
    bytes: float
    seconds: float
    fewer: str



def sequence(works, what: str, fewer: str) -> Work:
    """Works run one after another: their times add up, the peak memory is the largest one's."""
    works = list(works)
    return Work(what, max(w.bytes for w in works), sum(w.seconds for w in works), fewer)


def _duration(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.2g} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} minutes"
    if seconds < 2 * 86400:
        return f"{seconds / 3600:.1f} hours"
    return f"{seconds / 86400:.3g} days"


def check_limits(max_memory_gb: float, max_minutes: float) -> None:
    """Refuse limits that are not positive finite numbers (the flags' own values)."""
    for flag, value in (("--max-memory", max_memory_gb), ("--max-minutes", max_minutes)):
        if not (isinstance(value, (int, float)) and value == value and 0 < value < float("inf")):
            raise WorkTooLarge(f"{flag} must be a positive finite number, got {value!r}")


def enforce(work: Work, max_memory_gb: float = MEMORY_LIMIT_GB, max_minutes: float = TIME_LIMIT_MINUTES) -> Work:
    """Raise :class:`WorkTooLarge` when ``work`` is estimated above either limit; return it otherwise."""
    check_limits(max_memory_gb, max_minutes)
    if work.bytes > max_memory_gb * 1e9:
        raise WorkTooLarge(f"{work.what} would need about {work.bytes / 1e9:.3g} GB of memory (limit "
                           f"{max_memory_gb:g} GB): use fewer {work.fewer}, or raise --max-memory")
    if work.seconds > max_minutes * 60:
        raise WorkTooLarge(f"{work.what} would take about {_duration(work.seconds)} on a 2-core machine (limit "
                           f"{max_minutes:g} minutes): use fewer {work.fewer}, or raise --max-minutes")
    return work


def simulation(scenario, runs: int) -> Work:
    """A :func:`shipsense.simulate` of ``runs`` runs of the scenario."""
    from shipsense.simulator import simulation_bytes

    values = float(runs) * scenario.steps * scenario.array().n_channels
    return Work(f"{runs} runs of {scenario.steps} steps of {scenario.name}", simulation_bytes(scenario, runs),
                values * SIMULATE_S_PER_VALUE, "--runs (or the scenario's steps)")


def tracking(scenario, rows: int, what: str | None = None) -> Work:
    """Tracking one passage of ``rows`` samples (a simulated passage, or a recording's distinct times): the work
    of each sample grows with the array's channels (every channel is a row of a recording), and the
    initialiser's grid holds every channel's predicted field."""
    channels = scenario.array().n_channels
    return Work(what or f"tracking {rows} samples of {scenario.name} ({channels} channels)",
                float(rows) * TRACK_BYTES_PER_SAMPLE + channels * TRACK_BYTES_PER_CHANNEL,
                float(rows) * channels * TRACK_S_PER_VALUE,
                "samples (the scenario's steps, or a shorter recording) or sensors")


def recording(path, scenario) -> Work:
    """Reading and tracking a recording, from its size and format alone (before it is parsed)."""
    from pathlib import Path

    from shipsense.recording.formats import format_of

    size = Path(path).stat().st_size
    lines = size / (RECORDING_BYTES_PER_LINE if format_of(path) == "csv" else RECORDING_BYTES_PER_VALUE)
    samples = lines / max(1, scenario.array().n_channels)    # every channel of a sample is one line
    return tracking(scenario, int(samples), what=f"the recording {path} ({size / 1e6:.3g} MB)")


def study(key: str, runs: int | None) -> Work:
    """``shipsense reproduce KEY --runs N`` (one study, or all of them)."""
    from shipsense.reproduce import EXPERIMENTS

    key = key.upper()
    if key == "ALL":
        return sequence((study(k, runs) for k in ("S0", "S1", "S2", "WIDE")),
                        f"reproduce all with {runs or 'the default'} runs", "--runs")
    n = runs or EXPERIMENTS[key][1]
    if key == "WIDE":
        return Work(f"the wide study with {n} passages per family", WIDE_BYTES_PER_CHUNK,
                    3 * n * WIDE_S_PER_PASSAGE, "--runs")
    return Work(f"{n} runs of {key}", 3e8 + n * STUDY_BYTES_PER_RUN[key], n * STUDY_S_PER_RUN[key], "--runs")


def check(scenario, passages: int) -> Work:
    """``shipsense check`` of one layout: the ambiguity search over ``passages`` prior passages."""
    values = passages * scenario.steps * scenario.array().n_channels
    return Work(f"checking {scenario.name} on {passages} passages of {scenario.steps} steps", values * 64 * 8.0,
                values * CHECK_S_PER_VALUE, "--passages (or the scenario's steps)")


SUBSET_S_PER_WORK = 2e-7              # the search over subsets, per subset value (benchmarks/design_certificate.py)


def subset_search(k: int, candidates: int, work: int | None, guard_seconds: float) -> float:
    """Seconds of ``shipsense design``'s search over subsets (:func:`shipsense.design.placement.place`), on the
    fast side: the tables it certainly computes (the pair values; for k = 4 also every triple's), at most its
    work limit and its time guard; 0 when it does not run."""
    from shipsense.design.placement import EXACT_MAX_K

    if k > EXACT_MAX_K or work == 0:
        return 0.0
    n = float(candidates)
    tables = n * (n - 1) / 2 + (n * (n - 1) * (n - 2) / 6 if k == 4 else 0.0)
    return float(min(tables if work is None else min(tables, work), guard_seconds / SUBSET_S_PER_WORK)
                 * SUBSET_S_PER_WORK)


def design(scenario, candidates: int, passages: int, search_seconds: float = 0.0) -> Work:
    """``shipsense design``: per-candidate Fisher information over ``passages`` prior passages (the relaxation,
    rounding and check cost less at these sizes; benchmarks/design.py), plus ``search_seconds`` (the search over
    subsets, :func:`subset_search`)."""
    array = scenario.array()
    channels = int(np.sum(array.channel_sensor == 0))   # the template sensor's channels
    d = 8                                               # parameters of a passage, at most
    values = float(candidates) * passages * scenario.steps * channels
    return Work(f"designing from {candidates} candidates and {passages} passages of {scenario.steps} steps",
                candidates * passages * d * d * 8.0 * 4 + values * d * 8.0 / max(1, scenario.steps),
                values * DESIGN_S_PER_VALUE + search_seconds, "candidates or --passages")


def training(task: str, timesteps: int, evaluations: int = 10, eval_episodes: int = 20) -> Work:
    """``shipsense train TASK --timesteps N`` with ``evaluations`` held-out evaluations of ``eval_episodes``."""
    evaluation = TRAIN_EVALUATION_S[task] * evaluations * eval_episodes / 200.0
    return Work(f"training {task} for {timesteps} steps", 2e9,
                timesteps * PPO_S_PER_STEP[task] + evaluation, "--timesteps")


def evaluation(env_id: str, policy: str, episodes: int) -> Work:
    """``shipsense evaluate ENV --policy P --episodes N``."""
    return Work(f"evaluating {policy} on {episodes} episodes of {env_id}", 1e9,
                episodes * EVALUATE_S_PER_EPISODE.get(policy, 0.05), "--episodes")
