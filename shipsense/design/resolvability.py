r"""Two-ship resolvability: the smallest separation at which an array tells two ships apart.

Fields superpose: with two ships the array reads :math:`y_k = h(x_{1,k}) + h(x_{2,k}) + v_k`.  For the
stacked initial state :math:`\Theta = [\theta_1; \theta_2]` (deterministic constant-velocity motion,
:math:`x_{s,k} = A^k \theta_s`, as in :mod:`~shipsense.design.fisher`) the Jacobian of sample ``k`` is
:math:`[G_{1k}\; G_{2k}]` with :math:`G_{sk} = H(x_{s,k}) A^k` (the sum's derivative with respect to one
ship is that ship's own Jacobian), so the joint Fisher information is

.. math::  J(\Theta) = \sum_k [G_{1k}\; G_{2k}]^T R^{-1} [G_{1k}\; G_{2k}]
           = \begin{bmatrix} J_{11} & J_{12} \\ J_{21} & J_{22} \end{bmatrix},

its diagonal blocks the one-ship Fisher informations (:func:`~shipsense.design.fisher.passage_fim`) and its
cross blocks :math:`J_{12} = \sum_k G_{1k}^T R^{-1} G_{2k}` the overlap of the two ships' field signatures:
they vanish as the ships' fields stop overlapping, and when the ships coincide the two column blocks are
equal and :math:`J` is singular.  Seismic bearing channels do not superpose (the eigen-bearing of two
sources is that of the louder one); they are left out of the joint information here, which can only make
the separation larger (a conservative figure).

**Criterion** (the statistical resolution limit of Smith, "Statistical resolution limits and the complexified
Cramér-Rao bound", IEEE TSP 53(5), 2005; Lee, "The Cramér-Rao bound on frequency estimates of signals closely
spaced in frequency", IEEE TSP 40(6), 1992): two ships at separation :math:`d` are told apart when the
Cramér-Rao standard deviation of the separation's estimate is at most the separation itself,

.. math::  \sigma_\delta(d) = \min_k \sqrt{g_k^T J^{-1} g_k} \le d, \qquad
           g_k = \big[u_k^T P A^k,\; -u_k^T P A^k\big],

:math:`\delta_k = u_k^T P (x_{1,k} - x_{2,k})` the separation at sample ``k`` along the true separation's
unit vector :math:`u_k` (:math:`P` picks the horizontal position), every other component of both ships
(velocities, moments, source heights, dipoles) a nuisance parameter estimated with it; the separation
counts as resolved when it is so at some sample of the passage (the best-informed one, near the closest
approach).  The criterion is relative to the separation, so it asks the array to resolve the pair, not to
localise each ship to a fixed accuracy (that is :data:`~shipsense.trackers.metrics.CRLB_SD_LIMIT_M`'s
question, about one ship).

**Geometry** (the hardest standard case): twin ships -- the same velocity, moment, source height and dipole
as a passage drawn from the prior -- abreast on parallel lines :math:`d/2` either side of the drawn line,
passing at the same time.  Each draw's resolvable separation is the smallest ``d`` of a geometric grid
(:data:`SEPARATIONS_M`, steps of :math:`2^{1/8}`, about 9 %) at which the criterion holds (infinite if none
does: the ships then stay unresolved up to the grid's end); the array's is the order statistic
that a share ``share`` (default :data:`RESOLVE_SHARE`) of the draws reach: at least that share of the drawn
pairs is told apart at a separation no larger than it.  Adding sensors adds information to every sample
(:math:`J` grows in the Loewner order), so a larger array never has a larger resolvable separation than its
subset.

The figure is a bound, local to the pair: no unbiased estimator tells the ships apart closer than it, and an
array whose figure is large cannot; estimators leave the bound at small separations and low signal (the
threshold effect Smith describes), and the point-dipole model stops holding when the ships are closer than
their own length, so a tracker needs more separation than the figure.  ``shipsense check`` reports it
(:mod:`~shipsense.design.gate`); ``shipsense design --criterion resolvability`` maximises
:func:`set_values`, the criterion at a fixed separation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from shipsense.design.fisher import weighted_jacobian
from shipsense.json_numbers import finite_or_none
from shipsense.models.transitions import powers

SEPARATIONS_M = 0.5 * 2.0 ** (np.arange(0, 89) / 8.0)
"""The separations tried (m): 0.5 m to 1024 m in steps of :math:`2^{1/8}` (about 9 %)."""
RESOLVE_SHARE = 0.9
"""Share of the drawn passage pairs that must be told apart at the reported separation."""
JOINT_BLOCK = 2_000_000
"""Whitened Jacobian entries (pairs x samples x channels x 2n) evaluated at once (16 MB)."""
STRIDE = 2
"""Every STRIDE-th sample enters the joint information (weighted by STRIDE), as in the observability check."""
NULL_TOLERANCE = 1e-13
"""Eigenvalues of the Jacobi-scaled joint information (unit diagonal, so eigenvalues in [0, 2n]) up to this
count as zero: rounding level, a few hundred times the double precision (a tolerance relative to the largest
eigenvalue would let a larger array's extra information push a real direction under it)."""


@dataclass(frozen=True)
class Resolvability:
    """The outcome of :func:`resolvable_separation`: the array's resolvable separation ``separation_m`` (m;
    ``inf`` if fewer than ``share`` of the draws are told apart within the grid), the share of draws it holds
    for, and each draw's own figure ``per_draw_m`` (P,) (m; ``inf`` where none on the grid)."""

    separation_m: float
    share: float
    per_draw_m: np.ndarray

    def describe(self) -> str:
        """One line of text: the separation, the share and what it means."""
        P = len(self.per_draw_m)
        pairs = f"{self.share:.0%} of {P} drawn pair{'s' * (P != 1)}"
        if not np.isfinite(self.separation_m):
            return (f"two ships: fewer than {pairs} told apart at any separation up to {SEPARATIONS_M[-1]:.0f} m "
                    f"({np.isfinite(self.per_draw_m).sum()} of them are)")
        at_most = "at most " if self.separation_m <= SEPARATIONS_M[0] else ""
        return (f"two ships told apart from a separation of {at_most}{self.separation_m:.3g} m ({pairs}; twin ships "
                f"abreast; joint Fisher information: the separation's CRLB sd <= the separation)")

    def to_json(self):
        return {"separation_m": finite_or_none(self.separation_m), "share": self.share,
                "per_draw_m": [finite_or_none(x) for x in self.per_draw_m],
                "criterion": "CRLB sd of the separation <= separation (Smith 2005)",
                "geometry": "twin ships abreast on parallel lines, the drawn passage between them"}


def superposing(model):
    """Boolean (m,): the channels whose readings add over ships (every channel but seismic bearings)."""
    return ~np.asarray(model.axial, dtype=bool)


def joint_fim(model, theta1, theta2, steps, *, stride=1, per_sensor=False, block=JOINT_BLOCK):
    """Joint Fisher information of two ships' passages about their stacked initial states (internal units).

    Parameters
    ----------
    model : FieldModel
    theta1, theta2 : ndarray, shape (..., n)
        The two ships' initial states (internal units), broadcast together.
    steps : int
        Samples in the passage.
    stride : int
        Use every ``stride``-th sample, weighted by ``stride``.
    per_sensor : bool
        One matrix per sensor (..., S, 2n, 2n) instead of the sum: the joint information is additive over
        sensors, as the one-ship information is.
    block : int
        Whitened Jacobian entries evaluated at once (bounds the memory).

    Returns
    -------
    J : ndarray, shape (..., 2n, 2n) or (..., S, 2n, 2n)
        Ordered ``[theta1; theta2]``; bearing channels left out (:func:`superposing`).
    """
    t1, t2 = np.broadcast_arrays(np.asarray(theta1, dtype=float), np.asarray(theta2, dtype=float))
    batch, n = t1.shape[:-1], t1.shape[-1]
    f1, f2 = t1.reshape(-1, n), t2.reshape(-1, n)
    Ak = powers(model.A, steps)[::stride]
    keep = superposing(model)
    sensor = model.array.channel_sensor[keep]
    S = len(model.array.ids)
    order = np.argsort(sensor, kind="stable")
    present = np.unique(sensor)
    starts = np.searchsorted(sensor[order], present)
    m, K = int(keep.sum()), len(Ak)
    out = np.zeros((len(f1), S, 2 * n, 2 * n) if per_sensor else (len(f1), 2 * n, 2 * n))
    chunk = max(1, block // max(1, K * m * 2 * n))
    for b0 in range(0, len(f1), chunk):
        W = np.concatenate([weighted_jacobian(model, f1[b0:b0 + chunk], Ak),
                            weighted_jacobian(model, f2[b0:b0 + chunk], Ak)], axis=-1)[:, :, keep]
        if per_sensor:
            per = np.einsum("bkcn,bkcp->bcnp", W[:, :, order], W[:, :, order])
            if len(present):
                out[b0:b0 + chunk, present] = np.add.reduceat(per, starts, axis=1)
        else:
            out[b0:b0 + chunk] = np.einsum("bkcn,bkcp->bnp", W, W)
    return stride * out.reshape(batch + out.shape[1:])


def separation_sd(model, J, theta1, theta2, steps, *, stride=1):
    r"""The Cramér-Rao standard deviation of the two ships' separation, at its best-informed sample (m).

    :math:`\min_k \sqrt{g_k^T J^{-1} g_k}` (module docstring), every other component of both states a
    nuisance parameter.  Where :math:`J` is singular and :math:`g_k` is not in its range (two coincident
    ships) the bound is infinite.

    Parameters
    ----------
    model : FieldModel
    J : ndarray, shape (..., 2n, 2n)
        Joint information (:func:`joint_fim`, the same ``stride``).
    theta1, theta2 : ndarray, shape (..., n)
        The ships' initial states (internal units; positions in m).
    steps, stride : int

    Returns
    -------
    sd : ndarray, shape (...)
    """
    J = np.asarray(J, dtype=float)
    t1, t2 = np.broadcast_arrays(np.asarray(theta1, dtype=float), np.asarray(theta2, dtype=float))
    Ak = powers(model.A, steps)[::stride]
    PA = Ak[:, :2]                                                     # (K, 2, n): positions at sample k
    rel = np.einsum("kij,...j->...ki", PA, t1 - t2)                   # (..., K, 2)
    dist = np.linalg.norm(rel, axis=-1, keepdims=True)
    u = np.where(dist > 0, rel / np.where(dist > 0, dist, 1.0), np.array([1.0, 0.0]))
    a = np.einsum("...ki,kij->...kj", u, PA)                           # (..., K, n)
    g = np.concatenate([a, -a], axis=-1)                               # (..., K, 2n)
    # the K gradients span a space of small dimension (2 for parallel ships: P A^k is affine in k): reduce them
    # once per pair, g_k = coef_k Z, so the quadratic forms cost R x R per sample instead of 2n x 2n
    U, S, Zt = np.linalg.svd(g, full_matrices=False)
    R = max(1, int((S > 1e-13 * S[..., :1]).sum(axis=-1).max()))
    coef, Z = U[..., :R] * S[..., None, :R], Zt[..., :R, :]            # (..., K, R), (..., R, 2n)
    # Jacobi scaling, then the eigen-decomposition: scale-free null space of a singular J
    d = np.sqrt(np.clip(np.diagonal(J, axis1=-2, axis2=-1), 0, None))
    d = np.where(d > 0, d, 1.0)
    w, V = np.linalg.eigh(J / (d[..., :, None] * d[..., None, :]))
    null = w <= NULL_TOLERANCE
    proj = (Z / d[..., None, :]) @ V                                    # (..., R, 2n)
    inv_w = np.where(null, 0.0, 1.0 / np.where(null, 1.0, w))

    def form(weights):   # coef_k^T (proj diag(weights) proj^T) coef_k for every sample k
        pw = proj * weights[..., None, :]
        if R > 4:
            return np.sum((coef @ (pw @ np.swapaxes(proj, -1, -2))) * coef, axis=-1)
        out = 0.0                                                       # few terms: elementwise beats tiny matmuls
        for r in range(R):
            for q in range(r, R):
                Mrq = np.sum(pw[..., r, :] * proj[..., q, :], axis=-1)[..., None]
                out = out + (1 + (q > r)) * coef[..., r] * coef[..., q] * Mrq
        return out

    var = form(inv_w)
    var = np.where(form(null.astype(float)) > 1e-12 * form(np.ones_like(w)), np.inf, var)
    return np.sqrt(np.min(var, axis=-1))


def abreast(model, thetas, separations):
    """Twin ships abreast: ``thetas`` (P, n) shifted by ``+-d/2`` across their course, for every ``d`` of
    ``separations`` (D,) m; returns ``(theta1, theta2)``, each (P, D, n) (internal units)."""
    thetas = np.atleast_2d(np.asarray(thetas, dtype=float))
    v = thetas[:, 2:4]
    speed = np.linalg.norm(v, axis=-1, keepdims=True)
    c = np.where(speed > 0, v / np.where(speed > 0, speed, 1.0), np.array([1.0, 0.0]))
    normal = np.stack([-c[:, 1], c[:, 0]], axis=-1)                    # left of the course
    shift = 0.5 * np.asarray(separations, dtype=float)[None, :, None] * normal[:, None, :]   # (P, D, 2)
    t1 = np.repeat(thetas[:, None], len(np.atleast_1d(separations)), axis=1)
    t2 = t1.copy()
    t1[..., :2] += shift
    t2[..., :2] -= shift
    return t1, t2


def resolved(model, thetas, steps, separations=SEPARATIONS_M, *, stride=STRIDE, J=None):
    """Whether each drawn passage's twin pair is told apart at each separation: (P, D) booleans.

    ``J`` (P, D, 2n, 2n), optional: the joint information of :func:`abreast`'s pairs, if already computed
    (a subset's sum of per-sensor matrices in the design search)."""
    separations = np.asarray(separations, dtype=float)
    t1, t2 = abreast(model, thetas, separations)
    if J is None:
        J = joint_fim(model, t1, t2, steps, stride=stride)
    return separation_sd(model, J, t1, t2, steps, stride=stride) <= separations


def first_resolved(ok, separations=SEPARATIONS_M):
    """Each row's smallest separation at which ``ok`` (..., D) holds (``inf`` if none does)."""
    ok = np.asarray(ok, dtype=bool)
    first = np.argmax(ok, axis=-1)
    return np.where(ok.any(axis=-1), np.asarray(separations, dtype=float)[first], np.inf)


def share_statistic(per_draw, share=RESOLVE_SHARE):
    """The separation that a share ``share`` of the draws reach: the ``ceil(share P)``-th smallest of
    ``per_draw`` (..., P) (no interpolation, so ``inf`` when fewer than that share are resolved)."""
    per_draw = np.sort(np.asarray(per_draw, dtype=float), axis=-1)
    rank = max(1, int(np.ceil(share * per_draw.shape[-1] - 1e-9)))
    return per_draw[..., rank - 1]


def resolvable_separation(model, thetas, steps, *, share=RESOLVE_SHARE, separations=SEPARATIONS_M,
                          stride=STRIDE):
    """The smallest separation at which the array of ``model`` tells two ships apart (module docstring).

    Parameters
    ----------
    model : FieldModel
    thetas : ndarray, shape (P, n)
        Passages drawn from the prior (internal units): each is the centre line of a twin pair.
    steps : int
        Samples in a passage.
    share : float in (0, 1]
        Share of the draws the figure holds for.
    separations : ndarray, shape (D,)
        Increasing separations tried (m).

    Returns
    -------
    Resolvability
    """
    if not 0 < share <= 1:
        raise ValueError(f"share must be in (0, 1], got {share}")
    per_draw = first_resolved(resolved(model, thetas, steps, separations, stride=stride), separations)
    return Resolvability(float(share_statistic(per_draw, share)), float(share), per_draw)


def scenario_resolvability(scenario, passages=8, seed=0, share=RESOLVE_SHARE):
    """:func:`resolvable_separation` of a scenario's array over passages from its ``[prior]`` (the nominal
    passage without one), the same draws as :func:`~shipsense.design.observability.check_scenario`'s."""
    from shipsense.design.observability import scenario_passages

    sc, model, thetas, _ = scenario_passages(scenario, passages, seed)
    return resolvable_separation(model, thetas, sc.steps, share=share)


# -- design: the value of a set of candidate sensors --------------------------------------------------------
DESIGN_SEPARATION_M = 20.0
"""Default separation (m) at which ``design --criterion resolvability`` values a layout: the smallest
closest-approach separation of the project's two-ship tracking experiments."""
EXHAUSTIVE_SETS = 20_000
"""The design search values every k-subset when there are at most this many; otherwise the best of
:data:`RANDOM_STARTS` random sets, improved by exchanges."""
RANDOM_STARTS = 1000


def candidate_information(model, thetas, steps, separation=DESIGN_SEPARATION_M, *, stride=STRIDE):
    """Per-candidate joint information of the twin pairs of ``thetas`` (P, n) at ``separation`` (m):
    ``(J, theta1, theta2)``, J (P, N, 2n, 2n) for the N sensors of the candidate ``model`` (one sensor per
    candidate), the pairs (P, n) each.  A set's joint information is the sum of its candidates'."""
    t1, t2 = abreast(model, thetas, [separation])
    t1, t2 = t1[:, 0], t2[:, 0]
    return joint_fim(model, t1, t2, steps, stride=stride, per_sensor=True), t1, t2


def set_values(model, information, steps, sets, separation=DESIGN_SEPARATION_M, *, share=RESOLVE_SHARE,
               stride=STRIDE, chunk=4096):
    r"""The resolvability criterion of candidate sets ``sets`` (B, k) (indices): to maximise.

    .. math::  V(T) = -\ln \rho_{(q)}(T), \qquad \rho_p(T) = \sigma_{\delta,p}(d_0; J_T) / d_0,

    :math:`\rho_{(q)}` the share statistic (:func:`share_statistic`, share ``q``) over the drawn pairs of the
    ratio of the separation's CRLB sd to the separation :math:`d_0`, with the set's joint information
    :math:`J_T = \sum_{i \in T} J_i`.  :math:`V \ge 0` exactly when at least the share ``q`` of the pairs is
    told apart at :math:`d_0` (the criterion of :func:`resolvable_separation`), and every unit of ``V`` is a
    factor ``e`` of margin; ``-inf`` where the pairs are not seen apart at all.  More sensors never lower it.

    ``information``: :func:`candidate_information`'s ``(J, theta1, theta2)``; ``model`` gives the transition.
    Returns (B,).
    """
    J, t1, t2 = information
    sets = np.atleast_2d(np.asarray(sets))
    out = np.empty(len(sets))
    for b0 in range(0, len(sets), chunk):
        idx = sets[b0:b0 + chunk]
        M = J[:, idx[:, 0]]
        for i in range(1, idx.shape[1]):                                  # the set's sum, one member at a time
            M = M + J[:, idx[:, i]]
        M = np.swapaxes(M, 0, 1)                                           # (b, P, 2n, 2n)
        ratio = separation_sd(model, M, t1, t2, steps, stride=stride) / separation
        with np.errstate(divide="ignore"):
            out[b0:b0 + chunk] = -np.log(share_statistic(ratio, share))
    return out


def best_set(values, N, k, *, exhaustive=EXHAUSTIVE_SETS, starts=RANDOM_STARTS, seed=0, max_rounds=50):
    """The k-subset of N candidates with the largest ``values(sets)`` (a function of (B, k) index arrays).

    Every subset is valued when there are at most ``exhaustive`` of them (the result is then optimal);
    otherwise the best of ``starts`` random sets is improved by exchanges (replace one chosen candidate by
    the best other, all N x k exchanges valued at once, while the value improves).

    Returns
    -------
    chosen : ndarray, shape (k,)
    value : float
    complete : bool
        Whether every subset was valued.
    evaluated : int
        Sets valued.
    """
    from itertools import combinations
    from math import comb

    total = comb(N, k)
    if total <= exhaustive:
        sets = np.array(list(combinations(range(N), k)), dtype=np.int64).reshape(total, k)
        vals = values(sets)
        best = int(np.argmax(vals))
        return sets[best], float(vals[best]), True, total
    rng = np.random.default_rng(seed)
    sets = np.sort(np.argsort(rng.random((starts, N)), axis=1)[:, :k], axis=1)
    vals = values(sets)
    evaluated = len(sets)
    chosen, value = sets[int(np.argmax(vals))], float(vals.max())
    for _ in range(max_rounds):
        trial = np.repeat(chosen[None], k * N, axis=0).reshape(k, N, k)
        trial[np.arange(k), :, np.arange(k)] = np.arange(N)              # slot i takes candidate j
        trial = trial.reshape(-1, k)
        ordered = np.sort(trial, axis=1)
        trial = trial[np.all(ordered[:, 1:] != ordered[:, :-1], axis=1)]   # no candidate twice
        vals = values(trial)
        evaluated += len(trial)
        j = int(np.argmax(vals))
        if not vals[j] > value:
            break
        chosen, value = np.sort(trial[j]), float(vals[j])
    return chosen, value, False, evaluated
