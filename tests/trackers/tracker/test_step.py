"""The tracker's compiled step (shipsense/trackers/tracker/step.py) gives the step by step path's numbers to
the bit, and leaves everything as it was when it does not apply or an element fails."""

import numpy as np
import pytest

from shipsense import simulate
from shipsense.trackers.tracker.tracker import Tracker

FIELDS = ("estimates", "covs", "status", "gap_nats", "ambiguous", "hypotheses")


def _track(scenario, runs, seed, compiled, samples=None, jitter=0.0, **options):
    sim = simulate(scenario, runs=runs, seed=seed)
    times = np.broadcast_to(sim.times, sim.measurements.shape[:2])
    if jitter:                                    # irregular sampling: a transition per passage and sample
        times = times + np.random.default_rng(seed).uniform(-jitter, jitter, times.shape) * (times[0, 1] - times[0, 0])
    trk = Tracker(scenario, passages=runs, **options)
    used = []
    if compiled and trk._compiled is not None:
        step = trk._compiled

        def counting(*args):
            left = step(*args)
            used.append(left.size == 0)
            return left

        trk._compiled = type("Counting", (), {"__call__": staticmethod(counting)})()
    else:
        trk._compiled = None
    K = samples or sim.measurements.shape[1]
    res = trk.track(times[:, :K], sim.measurements[:, :K])
    return res, trk, used


@pytest.mark.parametrize("scenario, runs, options", [
    ("S2", 6, {}),                                  # magnetometers and a bearing, the environments' model
    ("S2-field-trial", 4, {}),                      # robust: the Huber UKF; dropouts
    ("S1-P1", 4, {}),                               # electrodes: the state bounds (depth, p >= 0)
    ("S2", 3, {"method": "bank", "unit": "cdkf"}),  # the studies' bank (12 hypotheses, its own output), a CDKF
    ("S0", 3, {"unit": "ekf"}),                     # the other filters' kernels
    ("S0", 3, {"unit": "puekf"}),
    ("S2", 3, {"unit": "ckf"}),
    ("S2", 4, {"jitter": 0.2}),                     # irregular sampling (the model's stepped transitions)
    ("S2", 3, {"unit": "srcdkf"}),                  # the square-root filter (its factor's time update)
    ("S2", 3, {"method": "bank", "unit": "srcdkf", "jitter": 0.2}),   # with process noise, per-sample roots
])
def test_tracked_passages_equal_the_step_by_step_path_bit_for_bit(scenario, runs, options):
    fast, trk, used = _track(scenario, runs, 7, True, **options)
    slow, _, _ = _track(scenario, runs, 7, False, **options)
    assert used and all(used)                     # the compiled step ran (and was not refused)
    for f in FIELDS:
        np.testing.assert_array_equal(getattr(fast, f), getattr(slow, f), err_msg=f)
    assert [(g.passage, g.start_s, g.end_s) for g in fast.gaps] == [(g.passage, g.start_s, g.end_s)
                                                                     for g in slow.gaps]


def _running_pair(scenario, runs, seed):
    """Two trackers of the same passages, the second without the compiled step, fed until every passage
    runs; returns them, the simulation and the next sample."""
    sim = simulate(scenario, runs=runs, seed=seed)
    pair = [Tracker(scenario, passages=runs) for _ in range(2)]
    pair[1]._compiled = None
    k = 0
    while not (pair[0].state.phase == 2).all():                          # (2: _RUNNING)
        for trk in pair:
            trk.update(sim.times[k], sim.measurements[:, k])
        k += 1
    return pair, sim, k


def _assert_same_sample(a, b):
    for f in ("estimate", "cov", "status", "gap_nats", "ambiguous", "hypotheses", "selected"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f)


def test_means_out_of_the_state_bounds_are_clipped_as_numpy_clips_them():
    """Electrodes: hypotheses with the keel dipole p far below its bound 0 and the depth above the surface
    are clipped back in the kernel as np.clip does in BankState.step."""
    pair, sim, k = _running_pair("S1-P1", 2, 3)
    lo, hi = pair[0].filter_model.state_bounds
    p, z = pair[0].model.labels.index("p"), pair[0].model.labels.index("z")
    for trk in pair:
        trk.bank.belief.mean[::2, p] = -50.0 / trk.model.x_scale[p]
        trk.bank.belief.mean[1::3, z] = 3.0 / trk.model.x_scale[z]
    before = pair[0].bank.belief.mean.copy()
    a, b = (trk.update(sim.times[k], sim.measurements[:, k]) for trk in pair)
    _assert_same_sample(a, b)
    mean = pair[0].bank.belief.mean
    live = ~np.isneginf(pair[0].bank.cum.ravel())       # (a repeat, -inf, is not stepped: kept as it was)
    assert live.any() and (mean[live, p] == lo[p]).any() and (mean[live, z] == hi[z]).any()   # clipped, not moved
    np.testing.assert_array_equal(mean[live], pair[1].bank.belief.mean[live])
    np.testing.assert_array_equal(mean[~live], before[~live])


def test_a_failed_element_leaves_the_state_untouched_and_the_numpy_path_takes_the_step():
    pair, sim, k = _running_pair("S2", 2, 5)
    for trk in pair:
        trk.bank.belief.chol[0] = np.nan                           # one hypothesis of passage 0 broken
    trk = pair[0]
    names = ("nis", "cons", "cons_n", "cons_tests", "cons_fails", "cons_now", "excess", "own", "trusted")
    before = {name: np.copy(getattr(trk.state, name)) for name in names}
    bank = [a.copy() for a in (trk.bank.belief.mean, trk.bank.belief.chol, trk.bank.cum)]
    out = trk.prior_sample()
    blank = [np.copy(getattr(out, f)) for f in ("estimate", "cov", "status")]
    np.testing.assert_array_equal(trk._compiled_step(np.arange(2), sim.measurements[:, k] / trk.model.y_scale, out),
                                  [0, 1])
    for name in names:
        np.testing.assert_array_equal(getattr(trk.state, name), before[name], err_msg=name)
    for now, was in zip((trk.bank.belief.mean, trk.bank.belief.chol, trk.bank.cum, out.estimate, out.cov,
                         out.status), bank + blank):
        np.testing.assert_array_equal(now, was)
    _assert_same_sample(*(t.update(sim.times[k], sim.measurements[:, k]) for t in pair))


def test_passages_stepped_in_chunks_on_threads_equal_one_chunk_and_a_failed_chunk_falls_back(monkeypatch):
    """24 passages (120 hypothesis rows): stepped in two chunks (20 and 4 passages: THREAD_ROWS rows) on two
    threads, the samples equal those on one thread, and the step by step path's, bit for bit.  With a
    hypothesis of passage 0 broken, the first chunk writes nothing and its passages take the step by step
    path (their samples equal that path's on those passages alone), the second chunk's passages are stepped
    as if nothing had failed -- on one thread as on two (the chunks do not follow the threads).  (The step
    by step path on all 24 would move every passage at rounding: its Cholesky repair re-factors the whole
    batch.)"""
    import copy

    from shipsense.trackers.tracker import step as tracker_step

    runs = 24
    assert tracker_step.THREAD_ROWS <= runs * 5 < 2 * tracker_step.THREAD_ROWS
    sim = simulate("S2", runs=runs, seed=4)
    trackers = [Tracker("S2", passages=runs) for _ in range(3)]
    trackers[2]._compiled = None
    k = 0
    while not (trackers[0].state.phase == 2).all():                     # (2: _RUNNING)
        for trk, threads in zip(trackers, ("2", "1", "1")):
            monkeypatch.setenv("SHIPSENSE_THREADS", threads)
            trk.update(sim.times[k], sim.measurements[:, k])
        k += 1
    calls = []
    kernel = trackers[0]._compiled.kernel
    monkeypatch.setattr(trackers[0]._compiled, "kernel", lambda runs, *a: calls.append(len(runs)) or kernel(runs, *a))
    for j in range(k, k + 4):
        samples = []
        for trk, threads in zip(trackers, ("2", "1", "1")):
            monkeypatch.setenv("SHIPSENSE_THREADS", threads)
            samples.append(trk.update(sim.times[j], sim.measurements[:, j]))
        _assert_same_sample(samples[0], samples[1])
        _assert_same_sample(samples[0], samples[2])
        assert sorted(calls) == [4, 20]                           # two chunks a sample
        calls.clear()
    t, y = sim.times[k + 4], sim.measurements[:, k + 4]
    results = {}
    for threads in ("2", "1"):
        monkeypatch.setenv("SHIPSENSE_THREADS", threads)
        broken, healthy, numpy_path = (copy.deepcopy(trackers[1]) for _ in range(3))
        for trk in (broken, numpy_path):
            trk.bank.belief.chol[0] = np.nan                       # passage 0's first hypothesis
        numpy_path._compiled = None
        a, b = broken.update(t, y), healthy.update(t, y)
        first = numpy_path.update(t, y[:20], passages=np.arange(20))
        for f in ("estimate", "cov", "status", "gap_nats", "ambiguous", "hypotheses", "selected"):
            np.testing.assert_array_equal(getattr(a, f)[20:], getattr(b, f)[20:], err_msg=f)
            np.testing.assert_array_equal(getattr(a, f)[:20], getattr(first, f), err_msg=f)
        results[threads] = a
    _assert_same_sample(results["2"], results["1"])


def test_a_passage_whose_every_hypothesis_is_a_repeat_is_stepped():
    """Repeats (-inf) are skipped only while their passage has another hypothesis: with every one -inf (an
    absurd sample sends them there) the passage's hypotheses are all stepped, as by the step by step path --
    by the compiled step itself, every sample (an element it fails on sends its chunk to that path)."""
    pair, sim, k = _running_pair("S2", 3, 6)
    for trk in pair:
        trk.bank.cum[1] = -np.inf
    taken = []
    kernel = pair[0]._compiled.kernel
    pair[0]._compiled.kernel = lambda runs, *a: taken.append(kernel(runs, *a)) or taken[-1]
    for j in range(k, k + 5):
        _assert_same_sample(*(trk.update(sim.times[j], sim.measurements[:, j]) for trk in pair))
    assert len(taken) == 5 and all(taken)


def test_a_large_batch_takes_the_compiled_step_with_the_same_numbers():
    """110 passages (550 hypothesis rows, beyond the filters' own thread split at 512): the compiled step
    runs (six chunks) and its samples equal the step by step path's bit for bit."""
    pair, sim, k = _running_pair("S2", 110, 8)
    calls, taken = [], []
    kernel = pair[0]._compiled.kernel
    pair[0]._compiled.kernel = lambda runs, *a: calls.append(len(runs)) or taken.append(kernel(runs, *a)) or taken[-1]
    for j in range(k, k + 3):
        _assert_same_sample(*(trk.update(sim.times[j], sim.measurements[:, j]) for trk in pair))
    assert sum(calls) == 3 * 110 and max(calls) == 20 and all(taken)     # (none fell back to the step by step path)


def test_a_refused_sample_writes_nothing():
    """update's checks (compiled with the sample's handling, tracker_step.prepare_sample) refuse a passage out of
    range or given twice, a pending passage, a time that is not finite or not later, and passages that are
    not a sequence of indices, before anything is written."""
    sim = simulate("S2", runs=2, seed=1)
    names = ("phase", "n", "last_t", "y_hist", "t_hist", "cons_now", "k0", "peak", "snr")
    pending = Tracker("S2", passages=2)
    k = 0
    while not pending.pending().any():
        pending.update(sim.times[k], sim.measurements[:, k], defer_fits=True)
        k += 1
    first = int(np.flatnonzero(pending.pending())[0])
    fresh = Tracker("S2", passages=2)
    for j in range(3):
        fresh.update(sim.times[j], sim.measurements[:, j])
    t, y = sim.times[3], sim.measurements[:, 3]
    cases = [(pending, (sim.times[k], sim.measurements[:, k]), {}, ValueError,
              f"passage {first} has its window fits deferred"),
             (fresh, (t, y[:1]), {"passages": [5]}, IndexError, "out of bounds"),
             (fresh, (np.nan, y[:1]), {"passages": [1]}, ValueError, "times must be finite"),
             (fresh, (sim.times[2], y), {}, ValueError, "time must increase: passage 0"),
             (fresh, (t, y), {"passages": [1, -1]}, ValueError, "passage -1 is given twice"),
             (fresh, (t, y[:1]), {"passages": 1}, ValueError, "passages must be a sequence"),
             (fresh, (t, y), {"passages": [[0, 1]]}, ValueError, "passages must be a sequence")]
    for trk, args, kwargs, error, message in cases:
        before = {name: np.copy(getattr(trk.state, name)) for name in names}
        with pytest.raises(error, match=message):
            trk.update(*args, **kwargs)
        for name in names:
            np.testing.assert_array_equal(getattr(trk.state, name), before[name], err_msg=name)
    assert fresh.update(t, y[1:], passages=[-1]).status.shape == (1,)      # a negative index, as numpy's
    assert fresh.state.n.tolist() == [3, 4]
