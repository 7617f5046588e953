r"""Compiled filter steps: each filter's predict and update as one call of its compiled kernel over the batch
(:mod:`~shipsense.trackers.filters.kernels`), from beliefs, models and masks as the filter units hold them.

Which form is which.  :meth:`FilterUnit.on <shipsense.trackers.filters.FilterUnit.on>` chooses, once for a
model (what :func:`~shipsense.trackers.filters.run.run_filter`, the bank and the tracker step with), these
compiled steps (:class:`~shipsense.trackers.filters.CompiledSteps`) whenever the model has a compiled
measurement kernel (:func:`shipsense.models.measurement.kernel_of`):

* a :class:`~shipsense.models.field_model.FieldModel` on the fast HED path:
  magnetometers (vector, magnitude or tmi readings; the S0 model), seismic
  bearings (S2) and electrodes (vector, envelope or magnitude readings of the
  HED field; S1, the demo), also with per-element transitions
  (:meth:`~shipsense.models.field_model.FieldModel.stepped`);
* a :class:`~shipsense.models.field_model.LinearModel`.

For those models these kernels are the implementation.  Every other model (the series HED path; user models
with a Python ``h``) runs the generic numpy steps of the filter modules (``ukf.update`` and so on;
:class:`~shipsense.trackers.filters.NumpySteps`), which the tests also hold these steps equal to.  An element
whose step fails numerically here (an innovation or posterior covariance that is not positive definite, a
non-finite result) makes the whole step rerun on the numpy steps, which flag and repair such elements (the
kernels stop at them).

The update kernels take their arrays in named bundles (:class:`~shipsense.trackers.filters.kernels.Prior`,
:class:`~shipsense.trackers.filters.kernels.Readings`, :class:`~shipsense.trackers.filters.kernels.UpdateSpec`,
:class:`~shipsense.trackers.filters.kernels.Posterior`), through an entry that takes their fields flat
(:mod:`~shipsense.trackers.filters.kernels` says why).

The results equal the numpy steps' to rounding (tests/trackers/filters/test_fused.py), with one difference by
design: the Huber update's reweighting stops for each element when its weights settle, where the numpy
update iterates until the whole batch has settled (an element that settled moves by less than 1e-9 of
its noise variances per further iteration), so a compiled element equals the numpy update of that
element alone.

A batch of ``shipsense.parallel.SPLIT_MIN`` (512) elements or more runs as contiguous chunks in threads
(:mod:`shipsense.parallel`; the kernels release the GIL).
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from shipsense.defaults import HUBER_GAMMA, N_PU
from shipsense.parallel import SPLIT_MIN, in_chunks
from shipsense.trackers.filters.cdkf import H_STIRLING
from shipsense.trackers.filters.core import Belief, BeliefWithCov, Innovation, prior_health, sqrt_psd
from shipsense.trackers.filters.kernels import CDKF, EKF, HUBER, PUEKF, SRCDKF, UKF, UPDATE_KERNELS
from shipsense.trackers.filters.time_update import predict_kernel
from shipsense.trackers.filters.ukf import merwe_weights

# -- threads --------------------------------------------------------------------------------------------------

_PREDICT_ROWS = frozenset({0, 1, 2, 3, 4, 6, 7, 8, 9})    # the predict kernel's arguments with a row per element
_UPDATE_ROWS = frozenset({0, 1, 2, 3, 4, 15, 16, 17, 18, 19, 20, 21, 22, 23})   # (its Prior's, Readings' and
#                                                                                Posterior's fields)


def _rows(a, lo, hi, nb):
    """Rows ``lo:hi`` of a kernel argument with a row per element (its arrays of ``nb`` rows, in a bundle)."""
    if isinstance(a, tuple):
        return tuple(_rows(v, lo, hi, nb) for v in a)
    return a[lo:hi] if a.shape[0] == nb else a


def _split(kernel, rows, nb, *args):
    """``kernel(*args)`` (True if every element is ok), over contiguous chunks of the ``nb`` elements in threads
    when the batch is large (:func:`shipsense.parallel.in_chunks`): the arguments (or bundles) at positions
    ``rows`` that have a row per element are sliced."""
    if nb < SPLIT_MIN:              # (in_chunks would not split it: called here, without its machinery)
        return bool(kernel(*args))

    def chunk(lo, hi):
        if lo == 0 and hi == nb:
            return kernel(*args)
        return kernel(*(_rows(a, lo, hi, nb) if i in rows else a for i, a in enumerate(args)))

    return all(in_chunks(chunk, nb))


# -- numpy-facing steps ---------------------------------------------------------------------------------------

def _batch(*shapes):
    """The broadcast of batch shapes (the common case, all equal, without numpy's general machinery)."""
    if len(shapes) == 2 and shapes[0] == shapes[1]:
        return shapes[0]
    shapes = [sh for sh in shapes if sh]      # () broadcasts to anything
    first = shapes[0] if shapes else ()
    for other in shapes[1:]:
        if other != first:
            return np.broadcast_shapes(*shapes)
    return first


def _shaped(a, batch):
    """A kernel's (B, ...) output with its batch axes restored."""
    return a if len(batch) == 1 else a.reshape(batch + a.shape[1:])


def _flag(ok, batch):
    """A copy of the health flag ``ok`` broadcast to ``batch``."""
    ok = np.asarray(ok)
    return ok.copy() if ok.shape == batch else np.broadcast_to(ok, batch).copy()


def _flat(a, batch, tail):
    """``a`` broadcast to ``batch + tail`` as a writable C-contiguous (B, *tail) array (one compiled signature)."""
    a = np.asarray(a)
    full = batch + tail
    if a.shape != full:
        if a.shape[len(a.shape) - len(tail):] == tail and a.size == math.prod(full):   # only axes of length 1 added
            return np.array(a, order="C").reshape((-1,) + tail)
        a = np.broadcast_to(a, full).copy()
    elif not (a.flags.c_contiguous and a.flags.writeable):
        a = a.copy()
    return a if len(batch) == 1 else a.reshape((-1,) + tail)


def per_element(a, batch, n):
    """A transition matrix (n, n) or per-element (..., n, n) as (1 or B, n, n)."""
    a = np.asarray(a, dtype=float)
    if a.ndim == 2:
        return np.ascontiguousarray(a).reshape(1, n, n)
    return _flat(a, batch, (n, n))


def predict(belief: Belief, model, square_root: bool = False):
    """The compiled time update (same result as :func:`~shipsense.trackers.filters.core.predict`); None if an
    element failed (the caller then runs the numpy step)."""
    mean = np.asarray(belief.mean, dtype=float)
    n = mean.shape[-1]
    A = np.asarray(model.A, dtype=float)
    batch = _batch(mean.shape[:-1], A.shape[:-2])
    if square_root:
        src = belief.chol
        sqQ = noise_root(model.Q, batch, n)
        Qf = np.zeros((1, 1, 1))
    else:
        cached = getattr(belief, "_cov", None)
        src = cached if cached is not None else belief.chol @ np.swapaxes(belief.chol, -1, -2)
        Qf = per_element(model.Q, batch, n)
        sqQ = no_sqrt(n)
    X = _flat(mean, batch, (n,))
    B = X.shape[0]
    mean_out = np.empty((B, n))
    P_out = np.empty((B, n, n)) if not square_root else np.empty((1, n, n))
    L_out = np.zeros((B, n, n))
    ok = np.empty(B, dtype=bool)
    if not _split(predict_kernel, _PREDICT_ROWS, B, X, _flat(src, batch, (n, n)), per_element(A, batch, n), Qf, sqQ,
                  square_root, mean_out, P_out, L_out, ok):
        return None
    mean_out, L_out = _shaped(mean_out, batch), _shaped(L_out, batch)
    if square_root:
        return Belief(mean_out, L_out, _flag(belief.ok, batch))
    return BeliefWithCov.with_cov(mean_out, L_out, _flag(prior_health(belief), batch), _shaped(P_out, batch))


def noise_root(Q, batch, n):
    """The square-root time update's root of the process noise ``Q`` (n, n) shared, (1, n, k) (the columns of
    :func:`~shipsense.trackers.filters.core.sqrt_psd` that are not zero), or per element (..., n, n) over
    ``batch``, (B, n, n) (its eigen-decomposition's)."""
    Q = np.asarray(Q, dtype=float)
    if Q.ndim == 2:
        return _shared_sqrt(n, np.ascontiguousarray(Q).tobytes())
    w, V = np.linalg.eigh(np.broadcast_to(Q, batch + (n, n)))
    return _flat(V * np.sqrt(np.clip(w, 0.0, None))[..., None, :], batch, (n, n))


_FILTER_CODES = {"ukf": UKF, "ckf": UKF, "huber_ukf": HUBER, "cdkf": CDKF, "srcdkf": SRCDKF, "ekf": EKF,
                 "puekf": PUEKF}


def filter_code(name):
    """The compiled update kernel's code of filter ``name`` (the CKF runs the UKF's with its own points)."""
    try:
        return _FILTER_CODES[name]
    except KeyError:
        raise ValueError(f"no compiled update for filter {name!r}; offered: {', '.join(_FILTER_CODES)}") from None


def update(name, belief: Belief, y, model, spec, mask=None, **options):
    """The compiled measurement update of filter ``name`` (same result as its module's ``update``); None if an
    element failed numerically (the caller then runs the numpy step, which flags and repairs it)."""
    mean = np.asarray(belief.mean, dtype=float)
    y = np.asarray(y, dtype=float)
    n, m = mean.shape[-1], y.shape[-1]
    batch = (_batch(mean.shape[:-1], y.shape[:-1]) if mask is None
             else _batch(mean.shape[:-1], y.shape[:-1], np.shape(mask)[:-1]))
    consts = filter_constants(name, n, options)
    cov_form = consts[0] != SRCDKF
    P = belief.cov if cov_form else _NO_COV
    X = _flat(mean, batch, (n,))
    mask_f = _all_read(m) if mask is None else _flat(np.asarray(mask, dtype=bool), batch, (m,))
    L = belief.chol if consts[0] not in (EKF, PUEKF) else P   # the linearised filters do not read the factor
    out = _run_update(consts, X, _flat(L, batch, (n, n)), _flat(P, batch, (n, n)) if cov_form else _NO_COV,
                      _flat(y, batch, (m,)), mask_f, model, spec)
    if out is None:
        return None
    mean_out, P_out, L_out, inn = out
    inn = Innovation(*inn) if len(batch) == 1 else Innovation(*(_shaped(a, batch) for a in inn))
    mean_out, P_out = _shaped(mean_out, batch), _shaped(P_out, batch)
    if not cov_form:
        return Belief(mean_out, P_out, _flag(belief.ok, batch)), inn
    return BeliefWithCov.with_cov(mean_out, _shaped(L_out, batch), _flag(prior_health(belief), batch), P_out), inn


def _run_update(consts, X, L, P, y, mask, model, spec):
    """The update kernel of ``consts`` (:func:`filter_constants`) on flat (B, ...) arguments: ``(mean, P, L,
    (eps, S, loglik, nis, m))`` (B, ...), or None if an element failed."""
    filt = consts[0]
    nb, n = X.shape
    m = y.shape[1]
    post = (np.empty((nb, n)), np.empty((nb, n, n)), np.zeros((nb, n, n)) if filt != SRCDKF else _NO_COV,
            np.empty((nb, m)), np.empty((nb, m, m)), np.empty(nb), np.empty(nb), np.empty(nb, dtype=np.int64),
            np.empty(nb, dtype=bool))           # (kernels.Posterior's fields)
    # the entry takes the fields of the kernel's bundles kernels.Prior, Readings, UpdateSpec and Posterior, flat
    if not _split(UPDATE_KERNELS[filt], _UPDATE_ROWS, nb, X, L, P, y, mask, noise_variances(model), spec, *consts[1:],
                  *post):
        return None
    mean_out, P_out, L_out = post[:3]
    return mean_out, P_out, L_out, post[3:8]


def filter_constants(name, n, options):
    """The update kernel's constants of filter ``name`` on ``n`` states with keyword ``options``: ``(code,
    spread, center, Wm, Wc, h, gamma, iterations, n_pu)`` (kept for the options' last few values)."""
    if not options:
        return _constants_of(name, n, ())
    items = tuple(sorted(options.items()))
    try:
        hash(items)
    except TypeError:    # an option value that is not hashable
        return _constants_of.__wrapped__(name, n, items)
    return _constants_of(name, n, items)


@lru_cache(maxsize=64)
def _constants_of(name, n, items):
    options = dict(items)
    spread, center, Wm, Wc = 1.0, 1, _NO_WEIGHTS, _NO_WEIGHTS
    h, gamma, iterations, n_pu = H_STIRLING, HUBER_GAMMA, 10, 1
    filt = filter_code(name)
    if name in ("ukf", "huber_ukf"):
        spread, Wm, Wc = _merwe(merwe_weights, n, options.get("alpha", 1.0), options.get("beta", 2.0),
                                options.get("kappa", 0.0))
        gamma = float(options.get("gamma", HUBER_GAMMA))
        iterations = int(options.get("iterations", 10))
    elif name == "ckf":
        center, spread = 0, float(np.sqrt(n))
        Wm = Wc = _ckf_weights(n)
    elif name in ("cdkf", "srcdkf"):
        h = float(options.get("h", H_STIRLING))
    elif name == "puekf":
        n_pu = int(options.get("n_pu", N_PU))
        if n_pu < 1:
            raise ValueError(f"n_pu must be >= 1, got {n_pu}")
    return filt, spread, center, Wm, Wc, h, gamma, iterations, n_pu


def noise_variances(model):
    """The model's measurement noise variances as a contiguous float array (no copy when they are one)."""
    return np.ascontiguousarray(model.R, dtype=float)


@lru_cache(maxsize=64)
def _all_read(m):
    """The mask of a step that reads every channel: one row, which the kernel uses for every element."""
    return np.ones((1, m), dtype=bool)


_NO_WEIGHTS = np.zeros(1)
_NO_COV = np.zeros((1, 1, 1))


@lru_cache(maxsize=64)
def no_sqrt(n):
    """The covariance-form predict's (empty) square root of Q, (1, n, 0)."""
    return np.zeros((1, n, 0))


@lru_cache(maxsize=64)
def _shared_sqrt(n, data):
    """The square root of a shared Q (the columns of :func:`sqrt_psd` that are not zero) as (1, n, k)."""
    sq = sqrt_psd(np.frombuffer(data, dtype=float).reshape(n, n))
    return np.ascontiguousarray(sq[:, np.abs(sq).max(axis=0) > 0]).reshape(1, n, -1)


@lru_cache(maxsize=64)
def _ckf_weights(n):
    return np.full(2 * n, 0.5 / n)


@lru_cache(maxsize=64)
def _merwe(weights, n, alpha, beta, kappa):
    """The unscented weights as writable arrays (a read-only array is another compiled signature)."""
    spread, Wm, Wc = weights(n, alpha, beta, kappa)
    return spread, Wm.copy(), Wc.copy()


