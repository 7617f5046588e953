"""Several ships: the several-ship tracker on two ships crossing and on one-ship passages.

    PYTHONPATH=. python experiments/several_ships.py --passages 40 --separations 10 20 60
    PYTHONPATH=. python experiments/several_ships.py --passages 40 --families --separations 5 10   # sweep only

Two magnetometers (S2's M1, M2): ``S2-crossing`` random passages (ship 0 from S2's prior, a second ship
crossing it at 30 m at its closest approach to the array centre) and ``S2`` random one-ship passages, the
same seeds for the several-ship tracker (:class:`shipsense.trackers.ships.ShipsTracker`) and the one-ship
tracker.  A true ship counts as present at a sample when its own one-ship position CRLB standard deviation
there (:func:`shipsense.sweep.evaluate.crlb_position`, larger axis) is at most 5 m.  Over the second half of
every passage: the share of samples with the right number of present ships
(:func:`shipsense.trackers.metrics.cardinality_rate`), GOSPA (c = 20 m, p = alpha = 2) and its parts, each
ship's RMSE against its track (labels by :func:`~shipsense.trackers.metrics.label_assignment` over the
passage) and against the square root of the mean position trace of that ship's block of the joint-state
CRLB, each ship's 95 % coverage; on one-ship passages the false-second-ship rate and track 1's RMSE over the
one-ship tracker's (also both RMSEs apart on the passages with and without a second ship born).  Cost:
seconds per passage of both trackers (this machine, this run; a ratio, not a benchmark).
"""

from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

import shipsense
from shipsense.config import load_scenario
from shipsense.design.fisher import pcrlb
from shipsense.models.field_model import model_from_scenario
from shipsense.sweep.evaluate import crlb_position
from shipsense.trackers import Tracker, metrics
from shipsense.trackers.ships import JointModel, ShipsTracker

SENSORS = ["M1", "M2"]
PRESENT_SD_M = 5.0


def presence(sc, model, ships):
    """Which true ships (R, K, J) are present: own one-ship position CRLB sd <= 5 m (and sailing)."""
    out = np.zeros(ships.shape[:3], dtype=bool)
    for j in range(ships.shape[2]):
        s = ships[:, :, j]
        ok = np.isfinite(s[..., 0]).all(axis=1)
        if ok.any():
            out[ok, :, j] = metrics.crlb_sd(crlb_position(sc, model, model.state_from_truth(s[ok]))) <= PRESENT_SD_M
    return out


def joint_bound_sd(sc, model, ships):
    """sqrt of the position trace (R, K, 2) of each ship's block of the two-ship joint CRLB, m."""
    from shipsense.trackers.tracker.settings import resolve_settings

    joint = JointModel(model, 2)
    bank = resolve_settings(sc).bank
    J0 = np.diag(np.tile(model.to_internal(bank.state_std(model.labels)) ** -2.0, 2))
    x = np.concatenate([model.to_internal(model.state_from_truth(ships[:, :, j])) for j in range(2)], axis=-1)
    b = pcrlb(joint, x, J0, per_run=True, Q=np.zeros_like(joint.Q)) * np.outer(joint.x_scale, joint.x_scale)
    n = model.n
    return np.stack([np.sqrt(b[..., j * n, j * n] + b[..., j * n + 1, j * n + 1]) for j in range(2)], axis=-1)


def run(name, passages, seed, separation=None):
    sc = load_scenario(name)
    if separation is not None:          # the crossing's closest approach, m
        sc = sc.model_copy(update={"traffic": sc.traffic.model_copy(update={"separation": float(separation)})})
    model = model_from_scenario(sc, sensors=SENSORS)
    sim = shipsense.simulate(sc, runs=passages, seed=seed, random=True)
    y = sim.measurements[..., :6]
    ships = np.moveaxis(sim.ships, 1, 2) if sim.companions is not None else sim.truth[:, :, None]
    t0 = time.perf_counter()
    r = ShipsTracker(sc, passages=passages, sensors=SENSORS).track(sim.times, y)
    t_ships = time.perf_counter() - t0
    t0 = time.perf_counter()
    one = Tracker(sc, passages=passages, sensors=SENSORS).track(sim.times, y)
    t_one = time.perf_counter() - t0
    here = presence(sc, model, ships)
    truth = np.where(here[..., None], ships, np.nan)
    K = truth.shape[1]
    h = slice(K // 2, None)
    g = metrics.gospa(r.estimates[:, h], truth[:, h])
    a = metrics.label_assignment(r.estimates, truth)
    rmse = metrics.ship_rmse(r.estimates[:, h], truth[:, h], a)
    cover = metrics.ship_coverage(r.estimates[:, h], r.covs[:, h], truth[:, h], a)
    out = {"passages": passages, "card": metrics.cardinality_rate(r.estimates[:, h], truth[:, h]),
           "gospa_m": float(np.mean(g.total)), "gospa_loc_m2": float(np.mean(g.localisation)),
           "gospa_missed_m2": float(np.mean(g.missed)), "gospa_false_m2": float(np.mean(g.false)),
           "rmse_median_m": np.nanmedian(rmse, axis=0), "rmse_mean_m": np.nanmean(rmse, axis=0),
           "coverage": np.nanmean(cover, axis=0), "births": int((r.born[:, 1] >= 0).sum()),
           "track2_ended": int((r.died[:, 1] >= 0).sum()),
           "s_per_passage": (t_ships / passages, t_one / passages)}
    if ships.shape[2] == 2:
        bound = joint_bound_sd(sc, model, ships)[:, h]
        with warnings.catch_warnings():                   # (a ship never present: NaN)
            warnings.simplefilter("ignore", RuntimeWarning)
            ratio = rmse / np.sqrt(np.nanmean(np.where(here[:, h], bound ** 2, np.nan), axis=1))
        out["rmse_over_joint_crlb_median"] = np.nanmedian(ratio, axis=0)
    else:
        out["false_second_rate"] = float(np.mean(r.present[:, h, 1]))
        e1 = np.hypot(*(r.estimates[:, h, 0, :2] - ships[:, h, 0, :2]).transpose(2, 0, 1))
        e0 = np.hypot(*(one.estimates[:, h, :2] - ships[:, h, 0, :2]).transpose(2, 0, 1))
        both = np.isfinite(e1) & np.isfinite(e0) & here[:, h, 0]
        out["track1_rmse_over_one_ship"] = float(np.sqrt(np.mean(e1[both] ** 2) / np.mean(e0[both] ** 2)))
        born = r.born[:, 1] >= 0                          # the passages where a (false) second ship was born
        for name, sel in (("no_birth", ~born), ("birth", born)):
            b = both & sel[:, None]
            out[f"track1_and_one_ship_rmse_m_{name}"] = (int(sel.sum()), float(np.sqrt(np.mean(e1[b] ** 2))),
                                                         float(np.sqrt(np.mean(e0[b] ** 2))))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--passages", type=int, default=30)
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--separations", type=float, nargs="*", default=[],
                    help="also run S2-crossing with these closest approaches of the two ships (m)")
    ap.add_argument("--families", nargs="*", default=["S2-crossing", "S2"], choices=["S2-crossing", "S2"],
                    help="the table's scenarios (none: only the separations)")
    args = ap.parse_args()
    np.set_printoptions(precision=3, suppress=True)
    for name in args.families:
        res = run(name, args.passages, args.seed)
        print(f"{name} (two magnetometers, {res.pop('passages')} random passages, second half):")
        for k, v in res.items():
            print(f"  {k}: {v}")
    for d in args.separations:
        res = run("S2-crossing", args.passages, args.seed, separation=d)
        print(f"S2-crossing at {d:g} m: cardinality {res['card']:.3f}, GOSPA {res['gospa_m']:.2f} m (missed "
              f"{res['gospa_missed_m2']:.1f} m2, false {res['gospa_false_m2']:.1f} m2), births {res['births']}, "
              f"median RMSE {res['rmse_median_m']} m, over the joint bound {res['rmse_over_joint_crlb_median']}, "
              f"coverage {res['coverage']}")


if __name__ == "__main__":
    main()
