"""The tracker on ships that turn and change speed: the IMM motion modes against the constant-velocity filter.

Run:  python experiments/manoeuvres.py [--passages 1000] [--family NAME ...] [--out results/manoeuvres]

Families as in ``experiments/tracker_consistency.py``: ``one_magnetometer`` (S0), ``two_magnetometers`` (S2's M1
and M2), ``envelope_p2`` (S1-P2).  Conditions ``clean`` and ``faulty`` (that experiment's faults).  Half of the
passages make one random manoeuvre (a turn of 20-90 degrees at 1-3 deg/s, or a speed change by a factor 0.5-2)
that starts while the ship is within the array's reach (the first half of the passage); the moment's
body-fixed share is drawn per run of chunks (0 or 1 alternately: the tracker must hold on either).  Methods:
``imm`` (``[tracker.motion] model = "imm"``) and ``cv`` (``model = "cv"``), on the same passages.

Per family, condition, method and kind of passage (``manoeuvring`` / ``straight``):

* ``convergence`` and ``convergence_bounded`` (over the passages whose position bound sd at the judged sample is
  at most :data:`~shipsense.trackers.metrics.CRLB_SD_LIMIT_M`; the bound is the PCRLB conditional on the true
  manoeuvres, :func:`shipsense.design.manoeuvre_bound.simulation_bound`);
* on the samples after the manoeuvre ended (manoeuvring passages) or of the second half (straight ones), while
  the method reports a track: ``rmse``, ``rmse_over_bound`` (against the root-mean of the bound's position
  trace on the same samples), ``coverage`` of the reported 95 % ellipse, ``inconsistent`` (the share of those
  samples with that status) and ``manoeuvring`` (with that status).

Writes ``manoeuvres.json``, ``manoeuvres.csv`` and ``turn.png`` (a turning passage: truth, track by status,
95 % ellipses, the motion modes' probabilities over time).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
from tracker_consistency import (  # (this folder: the consistency experiment's families and faults)
    FAMILIES,
    FAULTY,
    passage_arguments,
)

from shipsense import load_scenario, simulate
from shipsense.design.manoeuvre_bound import simulation_bound
from shipsense.trackers import Tracker
from shipsense.trackers.metrics import (
    CHI2_2DOF_95,
    converged_until,
    convergence_allowed,
    judged_sample,
    passage_ends,
)
from shipsense.trackers.tracker.settings import prior_belief

CHUNK = 50


def scenario(family, condition, share):
    sc = load_scenario(FAMILIES[family][0])
    end = sc.period * (sc.steps - 1)
    sc = sc.with_updates(manoeuvres={"body_fixed_share": share, "random": {
        "probability": 0.5, "turn_share": 0.5, "turn_rate_deg_s": [1.0, 3.0], "turn_deg": [20.0, 90.0],
        "speed_factor": [0.5, 2.0], "acceleration": [0.05, 0.3], "start": [0.1 * end, 0.5 * end]}})
    return sc.with_updates(noise=FAULTY) if condition == "faulty" else sc


def chunk_stats(family, condition, seed, passages):
    """Per-passage figures of one chunk of passages, for both methods."""
    sc = scenario(family, condition, float(seed % 2))
    sim = simulate(sc, runs=passages, seed=seed, random=True)
    out = {}
    for method in ("imm", "cv"):
        tr = Tracker(sc, passages=passages, sensors=FAMILIES[family][1], motion={"model": method})
        cols = np.isin([c[0] for c in sim.channels], tr.model.array.ids)
        t0 = time.perf_counter()
        res = tr.track(sim.times, sim.measurements[..., cols])
        seconds = time.perf_counter() - t0
        model = tr.model
        if method == "imm":                 # (the bound of the passages, the same for both methods)
            J0 = np.linalg.inv(model.cov_to_internal(prior_belief(model, sc, tr.bank_config)[1]))
            bound = model.cov_to_si(simulation_bound(model, sim, J0))[..., :2, :2]            # (R, K, 2, 2) m²
            pos_bound = np.trace(bound, axis1=-2, axis2=-1)
        truth = sim.truth
        K = truth.shape[1]
        ends = passage_ends(truth, model.array.positions[:, :2].mean(0), sc.period)
        conv, err, valid = converged_until(res.estimates, truth, ends)
        bounded = convergence_allowed(bound[np.arange(passages), judged_sample(ends)])
        moving = sim.manoeuvre != 0
        manoeuvring = moving.any(axis=1)
        last = np.array([np.flatnonzero(m).max() + 1 if m.any() else K // 2 for m in moving])
        names = res.status_names()
        k = np.arange(K)[None]
        judged_samples = valid & (k >= last[:, None]) & (names != "initialising") & (names != "no data")
        d = res.estimates[..., :2] - truth[..., :2]
        C = res.covs[..., :2, :2]
        q = np.einsum("rki,rkij,rkj->rk", d, np.linalg.inv(C + 1e-300 * np.eye(2)), d)
        out[method] = {"converged": conv, "bounded": bounded, "manoeuvring": manoeuvring, "err": err,
                       "samples": judged_samples, "inside": q <= CHI2_2DOF_95, "bound": pos_bound,
                       "inconsistent": names == "inconsistent", "manoeuvre_status": names == "manoeuvring",
                       "seconds": seconds, "samples_total": passages * K}
    return out


def summarise(parts, method, kind):
    rows = [p[method] for p in parts]
    sel = [r["manoeuvring"] if kind == "manoeuvring" else ~r["manoeuvring"] for r in rows]
    cat = lambda key: np.concatenate([r[key][s] for r, s in zip(rows, sel)])   # noqa: E731
    conv, bounded = cat("converged"), cat("bounded")
    samples = cat("samples")
    err, inside, bound = cat("err")[samples], cat("inside")[samples], cat("bound")[samples]
    return {"passages": int(conv.size), "convergence": float(conv.mean()) if conv.size else None,
            "bounded": int(bounded.sum()),
            "convergence_bounded": float(conv[bounded].mean()) if bounded.any() else None,
            "rmse": float(np.sqrt(np.nanmean(err ** 2))), "rmse_over_bound": float(
                np.sqrt(np.nanmean(err ** 2)) / np.sqrt(np.mean(bound))),
            "coverage": float(inside.mean()), "inconsistent": float(cat("inconsistent")[samples].mean()),
            "manoeuvring": float(cat("manoeuvre_status")[samples].mean()),
            "us_per_sample": 1e6 * sum(r["seconds"] for r in rows) / sum(r["samples_total"] for r in rows)}


def plot_turn(path, seed=2):
    """A turning passage of S2-turn's pair of magnetometers: truth, the track by status with its 95 % ellipses,
    and the motion modes' probabilities over time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Ellipse

    sc = load_scenario("S2-turn")
    sc = sc.with_updates(manoeuvres={**sc.manoeuvres.model_dump(), "turns": [
        {"start": 20.0, "duration": 20.0, "rate_deg_s": 3.0}], "speed_changes": [
        {"start": 45.0, "duration": 10.0, "factor": 0.6}]})
    sim = simulate(sc, runs=1, seed=seed)
    tr = Tracker(sc, sensors=["M1", "M2"])
    cols = np.isin([c[0] for c in sim.channels], tr.model.array.ids)
    res = tr.track(sim.times, sim.measurements[..., cols])
    names = res.status_names()[0]
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 4.5))
    ax.plot(*sim.truth[0, :, :2].T, "k-", lw=1, label="truth")
    colours = {"tracking": "tab:blue", "manoeuvring": "tab:orange", "restarted": "tab:green",
               "inconsistent": "tab:red"}
    for status, colour in colours.items():
        on = names == status
        ax.plot(*res.estimates[0, on, :2].T, ".", ms=3, color=colour, label=status)
    for k in range(0, sim.times.size, 10):
        if names[k] in colours:
            w, V = np.linalg.eigh(res.covs[0, k, :2, :2])
            ax.add_patch(Ellipse(res.estimates[0, k, :2], *(2 * np.sqrt(CHI2_2DOF_95 * np.maximum(w, 0))),
                                 angle=np.degrees(np.arctan2(V[1, 1], V[0, 1])), fill=False, lw=0.6,
                                 color=colours[names[k]]))
    ax.plot(*tr.model.array.positions[:, :2].T, "k^", label="sensors")
    ax.set(xlabel="x (m)", ylabel="y (m)", aspect="equal", title="a turn then a slow-down (S2-turn)")
    ax.legend(fontsize=7)
    for j, name in enumerate(res.mode_names):
        bx.plot(sim.times, res.modes[0, :, j], label=name)
    bx.fill_between(sim.times, 0, 1, where=sim.manoeuvre[0] != 0, color="0.9", label="true manoeuvre")
    bx.set(xlabel="time (s)", ylabel="mode probability", ylim=(0, 1))
    bx.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main(argv=None):
    a = passage_arguments(__doc__.splitlines()[0], "results/manoeuvres").parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    results = {}
    for family in a.family:
        for condition in a.condition:
            parts = []
            for c in range(0, a.passages, CHUNK):
                parts.append(chunk_stats(family, condition, a.seed + c // CHUNK, min(CHUNK, a.passages - c)))
                print(f"{family} {condition}: {c + CHUNK} passages", flush=True)
            for method in ("imm", "cv"):
                for kind in ("manoeuvring", "straight"):
                    key = f"{family}/{condition}/{method}/{kind}"
                    results[key] = summarise(parts, method, kind)
                    print(key, json.dumps(results[key]), flush=True)
    (out / "manoeuvres.json").write_text(json.dumps(results, indent=1))
    keys = list(next(iter(results.values())))
    lines = ["case," + ",".join(keys)] + [f"{case}," + ",".join(str(v[k]) for k in keys) for case, v in results.items()]
    (out / "manoeuvres.csv").write_text("\n".join(lines) + "\n")
    plot_turn(out / "turn.png")
    print(f"wrote {out}/manoeuvres.json, .csv and turn.png")


if __name__ == "__main__":
    main()
