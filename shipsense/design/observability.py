r"""Observability and ambiguity of an array: local rank and global mirror / multi-start search.

Local: rank and condition number of the passage Fisher information
:math:`J(\theta)` (internal units) for passages drawn from a prior.  Global: a
*different* passage :math:`\theta'`, far from :math:`\theta`, whose
predictions match,

.. math::  d(\theta, \theta') = \sum_k \| h(x_k(\theta)) - h(x_k(\theta')) \|^2_{R^{-1}}

small (chi-square units).  The Fisher information can be full rank while the
mirror passage gives identical measurements (collinear envelope sensors), so
the search is global:

1. **symmetry seeds**: the passage mirrored across vertical planes through
   every pair of sensors and through each sensor at several angles, with the
   moment transformed correctly -- axial for the magnetic moment
   (:math:`m' = \det(M) M m`), polar for the electric dipole (it follows the
   mirrored keel) -- each plane once, the :data:`MIRROR_REFINE` closest
   candidates as they stand refined by least squares;
2. **multi-start least squares**: batched Levenberg–Marquardt from random
   passages far from :math:`\theta`.

Every passage's candidates are refined together, in batches of about
:data:`FIT_CHUNK` Jacobian entries.  Far apart means a mean distance between
the two tracks above ``far`` metres.

Manoeuvring passages (a scenario's ``[manoeuvres]``, drawn as the simulator draws them:
:func:`scenario_passages`): the Fisher information follows each passage's true motion
(:class:`~shipsense.design.fisher.PassageMotion`); the global search compares straight passages from the
same initial states (the motion the tracker's global initialiser fits on a window).  The verdict uses the actual
measurement model, so identical layouts can differ by measurement kind (vector vs
total-field magnetometers on a line; vector vs magnitude electrodes on a line).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from shipsense.design.fisher import passage_fim
from shipsense.json_numbers import finite_or_none
from shipsense.models.transitions import powers
from shipsense.trackers.fit.least_squares import fit_passages

DEFAULT_CHI2 = 25.0
"""A far-apart passage closer than this (chi-square units, ~5 sigma) is an ambiguity."""
DEFAULT_FAR = 20.0
"""Tracks farther apart than this (mean distance, m) count as different passages."""
DEGENERATE_CONDITION = 1e12


@dataclass(frozen=True)
class Ambiguity:
    """A pair of far-apart passages with nearly identical measurements (SI states)."""

    passage: np.ndarray
    alternative: np.ndarray
    chi2: float
    distance_m: float
    source: str

    def to_json(self, labels):
        return {"passage": dict(zip(labels, map(float, self.passage))),
                "alternative": dict(zip(labels, map(float, self.alternative))),
                "chi2": float(self.chi2), "distance_m": float(self.distance_m), "source": self.source}


@dataclass(frozen=True)
class Verdict:
    """The outcome of :func:`check_array`."""

    verdict: str
    min_chi2: float
    pairs: list = field(default_factory=list)
    fim_rank: int = 0
    fim_condition: float = float("inf")
    passages: int = 0
    labels: tuple = ()
    manoeuvring: int = 0      # of the passages, how many manoeuvre (their Fisher information follows it)

    def to_json(self):
        return {"verdict": self.verdict, "min_chi2": finite_or_none(self.min_chi2),
                "pairs": [p.to_json(self.labels) for p in self.pairs], "fim_rank": int(self.fim_rank),
                "fim_condition": finite_or_none(self.fim_condition), "passages": self.passages}


# -- discrepancy and least squares ------------------------------------------------
def _whitened(model, y, ref):
    d = model.residual(y, ref)
    return d / np.sqrt(model.R)


def discrepancy(model, theta, theta_alt, steps, stride=1):
    """``d(theta, theta')`` in chi-square units, batched over leading axes (internal units)."""
    Ak = powers(model.A, steps)[::stride]
    x = np.einsum("kij,...j->...ki", Ak, theta)
    xa = np.einsum("kij,...j->...ki", Ak, theta_alt)
    r = _whitened(model, model.h(xa), model.h(x))
    return stride * np.sum(r * r, axis=(-1, -2))


def track_distance(model, theta, theta_alt, steps):
    """Mean distance (m) between the positions of two passages over the passage."""
    Ak = powers(model.A, steps)
    p = np.einsum("kij,...j->...ki", Ak[:, :2], theta)
    pa = np.einsum("kij,...j->...ki", Ak[:, :2], theta_alt)
    return np.linalg.norm(p - pa, axis=-1).mean(axis=-1)


FIRST_USE = ("compiling the least-squares and measurement kernels on their first use on this machine (about 20-25 s "
             "on two cores; cached for later runs -- in CI, keep NUMBA_CACHE_DIR between jobs: docs, "
             "\"Design and the CI gate\")")


def first_use_notice():
    """:data:`FIRST_USE` if the kernels the analysis runs (the Levenberg-Marquardt fits' and the measurement
    kernel's: ``shipsense check`` and ``design``) are not yet compiled on disk for the current sources, else
    None."""
    from shipsense import numba_cache
    from shipsense.models import measurement
    from shipsense.trackers.fit import lm

    ready = numba_cache.cached(lm.lm_kernel, lm.lm_loop, lm.normal_equations,
                               measurement.batch_kernel, measurement.batch_loop)
    return None if ready else FIRST_USE


LM_STRIDE = 2
"""Every LM_STRIDE-th sample enters the refinement fits (their chi-square is then taken on every sample)."""
LM_ITERATIONS = 40
FIT_CHUNK = 2.5e5
"""Jacobian entries (rows x samples x channels x states) of one batched refinement fit (2 MB: batches that
fit in cache were as fast as larger ones, or faster, on S1-P2 and S2-field-trial)."""
MIRROR_REFINE = 24
"""Mirror candidates refined per passage (the closest as they stand; :func:`_search`)."""


# -- candidates -------------------------------------------------------------------
def mirror(model, theta, point, direction):
    """Passages mirrored across the vertical plane through ``point`` along ``direction`` (internal units)."""
    u = np.asarray(direction, float) / np.linalg.norm(direction)
    M2 = 2.0 * np.outer(u, u) - np.eye(2)
    c = np.asarray(point, float)[:2]
    out = np.array(theta, dtype=float)
    out[..., 0:2] = c + (out[..., 0:2] - c) @ M2.T
    out[..., 2:4] = out[..., 2:4] @ M2.T
    labels = model.labels
    if "mx" in labels:
        i = labels.index("mx")
        M = np.eye(3)
        M[:2, :2] = M2
        out[..., i:i + 3] = -(out[..., i:i + 3] @ M.T)        # axial: det(M) M m with det(M) = -1
    return out                                                # z, p unchanged; the keel follows v


def mirror_lines(model, angles=6):
    """Distinct vertical mirror planes of an array: lines ``(point, direction)`` through every pair of sensors and
    through each sensor at ``angles`` angles, each line once (a line through several sensors, e.g. a collinear
    array's, or a sensor's line that is also a pair's, would otherwise give the same candidates again)."""
    pos = np.unique(np.round(model.array.positions[:, :2], 6), axis=0)
    lines = []
    for i in range(len(pos)):
        for j in range(i + 1, len(pos)):
            lines.append((pos[i], pos[j] - pos[i]))
        for a in np.arange(angles) * np.pi / angles:
            lines.append((pos[i], np.array([np.cos(a), np.sin(a)])))
    seen, out = set(), []
    for c, d in lines:
        a = np.arctan2(d[1], d[0]) % np.pi
        if a > np.pi - 1e-9:
            a = 0.0
        offset = -np.sin(a) * c[0] + np.cos(a) * c[1]          # signed distance of the line from the origin
        key = (round(a, 9), round(offset, 6))
        if key not in seen:
            seen.add(key)
            out.append((c, d))
    return out


def mirror_candidates(model, theta, angles=6, lines=None):
    """Mirror images of ``theta`` across the lines of :func:`mirror_lines` (or ``lines``), (L, ..., n)."""
    lines = mirror_lines(model, angles) if lines is None else lines
    return np.stack([mirror(model, theta, c, d) for c, d in lines])


def _random_starts(model, theta, count, far, rng):
    """Random passages around the array, each at least ``far`` from theta's start."""
    n = model.n
    starts = np.repeat(theta[None], count, axis=0)
    centre = model.array.positions[:, :2].mean(axis=0)
    r0 = max(np.linalg.norm(theta[:2] - centre), 2 * far)
    ang = rng.uniform(0, 2 * np.pi, count)
    rad = r0 * rng.uniform(0.5, 1.5, count)
    starts[:, 0:2] = centre + rad[:, None] * np.stack([np.cos(ang), np.sin(ang)], -1)
    speed = np.linalg.norm(theta[2:4]) * rng.uniform(0.7, 1.3, count)
    head = np.arctan2(centre[1] - starts[:, 1], centre[0] - starts[:, 0]) + rng.uniform(-0.5, 0.5, count)
    starts[:, 2:4] = speed[:, None] * np.stack([np.cos(head), np.sin(head)], -1)
    labels = model.labels
    if "mx" in labels:
        i = labels.index("mx")
        mag = np.linalg.norm(theta[i:i + 3]) * np.exp(rng.uniform(-1, 1, count))
        d = rng.standard_normal((count, 3))
        starts[:, i:i + 3] = mag[:, None] * d / np.linalg.norm(d, axis=-1, keepdims=True)
    if "p" in labels:
        starts[:, labels.index("p")] *= np.exp(rng.uniform(-0.7, 0.7, count))
    assert starts.shape[1] == n
    return starts


def ambiguity_search(model, theta, steps, *, far=DEFAULT_FAR, starts=24, seed=0, refine=True):
    """Far-apart passages that best match ``theta`` (internal units), best first.

    Returns a list of ``(theta_alt, chi2, distance_m, source)``.
    """
    return _search(model, np.asarray(theta, float)[None], steps, far=far, starts=starts, seeds=[seed],
                   refine=refine)[0]


def _search(model, thetas, steps, *, far, starts, seeds, refine=True, progress=False, mirrors=None):
    """:func:`ambiguity_search` of each passage ``thetas`` (P, n) (``seeds[i]`` for passage i's random starts):
    every candidate of every passage refined in one batched least-squares fit (in chunks that bound memory).

    Of each passage's mirror candidates only the ``mirrors`` (default :data:`MIRROR_REFINE`) with the smallest
    discrepancy as they stand are refined; the others keep their exact discrepancy.  A symmetry of the layout,
    exact or nearly so -- what the mirror seeds are for -- is among the closest mirrors; the rest are far
    passages like the random starts, and a large array's O(S^2) of them would otherwise dominate the cost.
    Returns one list per passage.
    """
    mirrors = MIRROR_REFINE if mirrors is None else mirrors
    lines = mirror_lines(model)
    inits, ref, source, directs, fitted = [], [], [], [], []
    for i, theta in enumerate(thetas):
        cands = [("mirror", mirror_candidates(model, theta, lines=lines))]
        if starts:
            cands.append(("search", _random_starts(model, theta, starts, far, np.random.default_rng(seeds[i]))))
        for name, init in cands:
            direct = discrepancy(model, theta, init, steps)
            fit = np.full(len(init), refine)
            if name == "mirror" and len(init) > mirrors:
                fit[np.argsort(direct, kind="stable")[mirrors:]] = False
            inits.append(init)
            directs.append(direct)
            fitted.append(fit)
            ref += [i] * len(init)
            source += [name] * len(init)
    init, chi2, fitted = np.concatenate(inits), np.concatenate(directs), np.concatenate(fitted)
    ref = np.array(ref)
    alt = init.copy()
    Ak = powers(model.A, steps)[::LM_STRIDE]
    y_ref = model.h(np.einsum("kij,pj->pki", Ak, thetas))                   # (P, K', m)
    # rows per chunk: the fit's Jacobian (rows, K', m, n) kept to about FIT_CHUNK numbers
    chunk = max(8, int(FIT_CHUNK // (len(Ak) * model.m * model.n)))
    todo = np.flatnonzero(fitted)
    bounds = range(0, len(todo), chunk)
    if progress:
        from tqdm import tqdm

        bounds = tqdm(bounds, desc="ambiguity search", unit="chunk", leave=False, disable=None)
    for b in bounds:
        rows = todo[b:b + chunk]
        fit, _ = fit_passages(model, y_ref[ref[rows]], init[rows], steps, LM_STRIDE, LM_ITERATIONS)
        c = discrepancy(model, thetas[ref[rows]], fit, steps)
        better = c < chi2[rows]                             # the exact mirror may beat the refinement
        alt[rows] = np.where(better[:, None], fit, init[rows])
        chi2[rows] = np.where(better, c, chi2[rows])
    dist = track_distance(model, thetas[ref], alt, steps)
    found = [[] for _ in thetas]
    for a, c, d, i, src in zip(alt, chi2, dist, ref, source):
        if d > far and np.isfinite(c):
            found[i].append((a, float(c), float(d), src))
    for f in found:
        f.sort(key=lambda t: t[1])
    return found


def check_array(model, thetas, steps, *, far=DEFAULT_FAR, chi2_threshold=DEFAULT_CHI2, starts=24, seed=0,
                progress=False, motion=None):
    """Verdict of an array (through its model) on passages ``thetas`` (P, n) (internal units).

    ``degenerate`` if the Fisher information of some passage is numerically
    rank deficient or its condition number (internal units) exceeds 1e12; else ``ambiguous`` if some passage
    has a far-apart alternative within ``chi2_threshold``; else ``observable``.  The candidates of all
    passages are refined together (one batched fit), passage ``i``'s random starts drawn with seed ``seed + i``.
    ``motion`` (:class:`~shipsense.design.fisher.PassageMotion`, optional): the passages' manoeuvres, for their
    Fisher information (module docstring).
    """
    thetas = np.atleast_2d(np.asarray(thetas, dtype=float))
    J = passage_fim(model, thetas, steps, stride=2, motion=motion)
    w = np.linalg.eigvalsh(J)
    top = w.max(axis=-1, keepdims=True)
    rank = int((w > model.n * np.finfo(float).eps * top).sum(axis=-1).min())   # numerical rank
    cond = float(np.max(w[:, -1] / np.maximum(w[:, 0], 1e-300)))
    pairs, best = [], np.inf
    searched = _search(model, thetas, steps, far=far, starts=starts, seeds=seed + np.arange(len(thetas)),
                       progress=progress)
    for i, found in enumerate(searched):
        if found:
            best = min(best, found[0][1])
            for alt, chi2, dist, source in found:
                if chi2 < chi2_threshold:
                    pairs.append(_ambiguity(model, thetas[i], alt, chi2, dist, source))
                    break                                   # the best pair per passage
    if rank < model.n or cond > DEGENERATE_CONDITION:
        verdict = "degenerate"
    elif best < chi2_threshold:
        verdict = "ambiguous"
    else:
        verdict = "observable"
    return Verdict(verdict, best, pairs, rank, cond, len(thetas), tuple(model.labels),
                   0 if motion is None else int(motion.manoeuvring.sum()))


def mirror_screen(model, thetas, steps, *, far=DEFAULT_FAR, stride=2, lines=None):
    """The smallest discrepancy (chi-square units) of a far-apart mirror image of passages ``thetas`` (P, n)
    across the array's own symmetry lines (:func:`mirror_lines`), unrefined: the first stage of
    :func:`check_array` without its least-squares refinement and random starts: a quick screen.

    A layout with an exact mirror symmetry for the passages -- e.g. collinear sensors -- scores 0 (exactly
    ambiguous); a value below the threshold is an ambiguity :func:`check_array` would report too, but a value
    above it does not prove the layout observable (the refinement can find closer alternatives).
    Returns ``inf`` when no mirror image is farther than ``far`` from its passage.
    """
    thetas = np.atleast_2d(np.asarray(thetas, dtype=float))
    alts = mirror_candidates(model, thetas, lines=lines)                      # (L, P, n)
    d = discrepancy(model, thetas[None], alts, steps, stride)
    dist = track_distance(model, thetas[None], alts, steps)
    d = np.where(dist > far, d, np.inf)
    return float(d.min()) if d.size else float("inf")


def _ambiguity(model, theta, alt, chi2, dist, source):
    return Ambiguity(model.to_si(theta), model.to_si(alt), chi2, dist, source)


def scenario_passages(scenario, passages=8, seed=0):
    """A scenario's array and the passages a check draws: ``(scenario, model, thetas, motion)``, ``thetas``
    (P, n) internal units, ``passages`` from its ``[prior]`` (its nominal passage without one), with the
    manoeuvres of its ``[manoeuvres]`` table (the simulator's draws,
    :func:`~shipsense.simulator.sample_manoeuvring_passages`) as their ``motion``
    (:func:`~shipsense.design.manoeuvre_bound.passage_motion`; None when no passage manoeuvres)."""
    from shipsense.config import load_scenario
    from shipsense.design.manoeuvre_bound import passage_motion
    from shipsense.models.field_model import model_from_scenario
    from shipsense.simulator import sample_manoeuvring_passages

    sc = load_scenario(scenario)
    model = model_from_scenario(sc)
    truth, manoeuvres = sample_manoeuvring_passages(sc, passages if sc.prior is not None else 1, seed=seed,
                                                    random=sc.prior is not None)
    motion = passage_motion(model, truth, manoeuvres, sc.times)
    return sc, model, model.to_internal(model.state_from_truth(truth)), motion


def check_scenario(scenario, passages=8, seed=0, progress=False, **kwargs):
    """Verdict for a scenario's array: passages from its ``[prior]`` (or its nominal passage), with their
    manoeuvres."""
    sc, model, thetas, motion = scenario_passages(scenario, passages, seed)
    return check_array(model, thetas, sc.steps, seed=seed, progress=progress, motion=motion, **kwargs)
