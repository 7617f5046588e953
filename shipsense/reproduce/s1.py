"""S1: electrode array, shaft-rate envelope, PUEKF bank.

The electric source study's experiments 1-3: signal symmetry, array P1 (collinear) vs P2, raw-signal chain.
"""

from __future__ import annotations

import numpy as np

from shipsense.config import load_scenario
from shipsense.models.field_model import model_from_scenario
from shipsense.physics.array import SensorArray
from shipsense.physics.motion import cv_positions
from shipsense.reproduce.common import (
    LEAN,
    Output,
    Stages,
    bank_summary,
    bar_charts,
    finish,
    global_init_summary,
    rmse_plot,
)
from shipsense.simulator import simulate
from shipsense.trackers.bank.bank import run_bank
from shipsense.trackers.bank.seeding import seed_hypotheses
from shipsense.trackers.filters import get_filter
from shipsense.trackers.metrics import converged, rmse_k
from shipsense.trackers.tracker.settings import resolve_settings

SYMMETRY_SENSORS = ((0.0, 5.0), (0.0, 0.0), (5.0, 0.0))
SYMMETRY_BEARINGS = (np.pi / 4, 3 * np.pi / 4, 5 * np.pi / 4, 7 * np.pi / 4)
AMBIGUOUS_RUN_FRACTION = 0.5
HYPOTHESIS_RUN_FRACTION = 0.5   # a hypothesis "converges" (or "reaches the mirror") in at least half the runs


def mirror_truth(truth, positions):
    """The passages ``truth`` (R, K, n) reflected across the line through the sensors ``positions`` (S, 2)
    (their principal axis): positions and velocities mirrored, the other states unchanged."""
    c = positions.mean(axis=0)
    _, _, vt = np.linalg.svd(positions - c)
    d = vt[0]
    M = 2.0 * np.outer(d, d) - np.eye(2)
    out = truth.copy()
    out[..., 0:2] = c + (truth[..., 0:2] - c) @ M.T
    out[..., 2:4] = truth[..., 2:4] @ M.T
    return out


def hypothesis_rates(bank, truth, positions):
    """Per hypothesis (1-based, level-major as the study numbers them): the share of runs in which it
    converges to the truth and to the truth's mirror image across the sensors' line."""
    mirror = mirror_truth(truth, positions)
    conv = converged(bank.positions, truth[:, None]).mean(axis=0)      # (H,): every hypothesis at once
    mirr = converged(bank.positions, mirror[:, None]).mean(axis=0)
    return conv.tolist(), mirr.tolist()


def symmetry_table(sc, o):
    """Exp. 1: which of four passages through the array centre give identical envelopes, per sensor and channel."""
    medium = sc.medium.physics()
    depth = -sc.medium.water_depth
    array = SensorArray(ids=["(0,5)", "(0,0)", "(5,0)"], types=["electrode"] * 3, kinds=["envelope"] * 3,
                        positions=[[x, y, depth] for x, y in SYMMETRY_SENSORS], medium=medium)
    speed, start_range = 7.0, 212.0
    T = sc.period
    t = np.arange(0.0, 2 * start_range / speed + T / 2, T)
    starts = start_range * np.stack([np.cos(SYMMETRY_BEARINGS), np.sin(SYMMETRY_BEARINGS)], -1)
    vel = -speed * starts / start_range
    xy = cv_positions(starts, vel, t)                                              # (4, K, 2)
    src = np.concatenate([xy, np.full(xy.shape[:-1] + (1,), sc.passage.z)], -1)
    dip = np.concatenate([sc.passage.p * vel / speed, np.zeros((4, 1))], -1)[:, None, :]
    env = array.measure(src, dipoles=dip)                                          # (4, K, 9)
    rows, table = [], []
    for c, (sid, ch) in enumerate(array.channels):
        scale = np.abs(env[..., c]).max()
        groups, seen = [], set()
        for i in range(4):
            if i in seen:
                continue
            g = [j for j in range(4) if np.abs(env[j, :, c] - env[i, :, c]).max() <= 1e-9 * scale]
            seen.update(g)
            if len(g) > 1:
                groups.append([j + 1 for j in g])
        rows.append([sid, ch, " ".join("{" + ",".join(map(str, g)) + "}" for g in groups) or "-"])
        table.append({"sensor": sid, "channel": ch, "identical_passages": groups})
    o.csv("symmetry_table.csv", ["sensor", "channel", "passages with identical envelopes (1..4 = bearings "
                                 "pi/4, 3pi/4, 5pi/4, 7pi/4)"], rows)
    o.figure("symmetry.png", _symmetry_figure, t, env, [f"sensor {sid} |{ch}|" for sid, ch in array.channels])
    return table


def _symmetry_figure(t, env, titles):
    """Exp. 1's figure: each channel's envelope (``env``: passage, time, channel) of the four passages."""
    from shipsense.plotting import plt

    fig, ax = plt.subplots(3, 3, figsize=(12, 8), layout="constrained", sharex=True)
    for c in range(9):
        a = ax[c // 3, c % 3]
        for i in range(4):
            a.plot(t, 1e6 * env[i, :, c], ls=["-", "--", ":", "-."][i], label=f"passage {i + 1}")
        a.set_title(titles[c], fontsize=9)
        a.grid(alpha=0.3)
    ax[0, 0].legend(fontsize=7)
    ax[2, 1].set_xlabel("time [s]")
    ax[1, 0].set_ylabel("envelope [uV/m]")
    fig.suptitle("S1 exp. 1: envelopes of four passages through the array centre")
    return fig


def _arrays_figure(arrays):
    """The two arrays (tag -> (array, fraction of ambiguous runs)) side by side."""
    from shipsense.plotting import draw_array, plt

    fig, ax = plt.subplots(1, 2, figsize=(11, 5), layout="constrained")
    for a, (tag, (array, ambiguous)) in zip(ax, arrays.items()):
        draw_array(a, array)
        a.set_title(f"{tag}: ambiguous in {100 * ambiguous:.0f} % of runs")
        a.set_aspect("equal")
        a.grid(alpha=0.3)
    return fig


def bank_for(sc, runs, seed, unit, o=None, tag=None, chain=None):
    """Bank over simulated passages of a scenario; returns (summary, bank, truth)."""
    if chain is not None:
        sc = sc.with_updates(envelope_chain={"mode": chain})
    sim = simulate(sc, runs=runs, seed=seed)
    model = model_from_scenario(sc)
    truth = model.state_from_truth(sim.truth)
    bank = resolve_settings(sc).bank
    seeds, P0 = seed_hypotheses(model, sim.measurements[:, 0], bank)
    b = run_bank(unit, model, sim.measurements, seeds, P0, store=LEAN)
    summ, _ = bank_summary(b, truth, centre=model.array.positions[:, :2].mean(axis=0))
    amb = b.ambiguities(nats=bank.ambiguity_nats, distance=bank.ambiguity_distance)
    counts = {}
    for pairs in amb:
        for i, j, _, _ in pairs:
            counts[(i, j)] = counts.get((i, j), 0) + 1
    summ["ambiguous_pairs"] = sorted([[i + 1, j + 1] for (i, j), v in counts.items()     # 1-based, as the study
                                      if v >= AMBIGUOUS_RUN_FRACTION * runs])
    summ["ambiguous_run_fraction"] = float(np.mean([bool(p) for p in amb]))
    conv, mirr = hypothesis_rates(b, truth, model.array.positions[:, :2])
    for h, (c, m) in enumerate(zip(conv, mirr)):
        summ["hypotheses"][h].update(convergence_rate=c, mirror_rate=m)
    summ["converged_hypotheses"] = [h + 1 for h, c in enumerate(conv) if c >= HYPOTHESIS_RUN_FRACTION]
    summ["mirror_hypotheses"] = [h + 1 for h, m in enumerate(mirr) if m >= HYPOTHESIS_RUN_FRACTION]
    if o is not None:
        bar_charts(o, f"{tag}_bars.png", f"S1 {tag}: per-hypothesis TRMSE and likelihood ({runs} runs)",
                   summ["hypotheses"])
    return summ, b, truth


def run(runs=100, out="results/S1", seed=0, progress=True):
    """Run the S1 experiment set; returns the summary dictionary (also written to ``out/summary.json``)."""
    o = Output(out)
    st = Stages(["symmetry", "P1", "P2", "filters", "raw", "global", "figures"], "S1", progress)
    return finish(o, st, _study(o, st, runs, seed))     # (the figures once the runs' arrays are gone)


def _study(o, st, runs, seed):
    """The study's runs, tables and figures to draw (``o``), its stages ``st`` but the figures; returns the
    summary."""
    p1, p2 = load_scenario("S1-P1"), load_scenario("S1-P2")
    p2_settings = resolve_settings(p2)
    unit = p2_settings.study_unit()
    st.step("symmetry")
    sym = symmetry_table(p1, o)
    st.done()
    result, curves = {}, {}
    for tag, sc in (("P1", p1), ("P2", p2)):
        st.step(tag)
        summ, b, truth = bank_for(sc, runs, seed, unit, o, tag)
        result[tag] = summ
        curves[f"{tag} selected"] = rmse_k(b.selected_means, truth)
        o.csv(f"{tag}_hypotheses.csv", ["hypothesis", "range_m", "bearing_from_x_rad", "trmse_m", "mean_loglik",
                                        "convergence_rate", "mirror_rate"],
              [[i + 1, h["range_m"], h["bearing_rad"], h["trmse_m"], h["mean_loglik"], h["convergence_rate"],
                h["mirror_rate"]] for i, h in enumerate(summ["hypotheses"])])
        st.done()
    rmse_plot(o, "P1_vs_P2_rmse.png", f"S1 exp. 2: selected estimate, {unit.name} (N_pu = {p2_settings.n_pu})",
              p2.times, curves)
    st.step("filters")
    compare = {}
    for name, u in (("ekf (N_pu = 1)", get_filter("puekf", n_pu=1)),
                    (f"puekf (N_pu = {p2_settings.n_pu})", unit),
                    ("puekf (N_pu = 10)", get_filter("puekf", n_pu=10)), ("ukf", get_filter("ukf"))):
        summ, b, truth = bank_for(p2, runs, seed, u)
        compare[name] = {"selected_mrmse_r_m": summ["selected_mrmse_m"]["r"],
                         "convergence_rate": summ["convergence_rate"],
                         "selection_accuracy": summ["selection_accuracy"]}
    o.csv("P2_filters.csv", ["filter", "selected_mrmse_r_m", "convergence_rate", "selection_accuracy"],
          [[k, v["selected_mrmse_r_m"], v["convergence_rate"], v["selection_accuracy"]] for k, v in compare.items()])
    st.done()
    st.step("raw chain")
    raw, b_raw, truth_raw = bank_for(p2, runs, seed, unit, chain="raw")
    raw_chain = {"ideal_mrmse_r_m": result["P2"]["selected_mrmse_m"]["r"],
                 "raw_mrmse_r_m": raw["selected_mrmse_m"]["r"],
                 "raw_convergence_rate": raw["convergence_rate"]}
    st.done()
    # beyond the source: the project's tracker on P2 (global initialiser seeding the same PUEKF)
    st.step("global initialiser")
    sim = simulate(p2, runs=runs, seed=seed)
    model = model_from_scenario(p2)
    gi = global_init_summary(unit, model, sim.measurements, model.state_from_truth(sim.truth), p2, snr_start=50.0)
    st.done()
    o.figure("arrays.png", _arrays_figure, {tag: (sc.array(), result[tag]["ambiguous_run_fraction"])
                                            for tag, sc in (("P1", p1), ("P2", p2))})
    return {"scenario": "S1", "runs": runs, "seed": seed, "seconds": None,     # (finish: every stage's)
            "filter": unit.name, "n_pu": p2_settings.n_pu, **result, "symmetry_table": sym, "raw_chain": raw_chain,
            "P2_filters": compare, "P2_global_init": gi}
