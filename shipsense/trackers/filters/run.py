"""Run a filter unit over measured passages, batched over runs, hypotheses or environments.

The time recursion is the only loop: every step is one batched predict and
one batched update over all leading axes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from shipsense.trackers.filters import Belief, FilterUnit, get_filter


@dataclass(frozen=True)
class FilterRun:
    """Output of :func:`run_filter`, in SI units (axes: batch..., steps, ...).

    Attributes
    ----------
    means : (..., steps, n)         posterior means
    covs : (..., steps, n, n)       posterior covariances
    chols : (..., steps, n, n)      their lower Cholesky factors
    eps : (..., steps, m)           innovations (internal measurement units)
    nis : (..., steps)              normalised innovation squared
    loglik : (..., steps)           innovation log-likelihoods ``ln N(eps; 0, S)``
    ok : (..., steps)               False once an element lost positive definiteness
    labels : tuple of str           state component names

    ``means``, ``covs`` and ``chols`` are None unless asked for (``run_filter(store=...)``; by default
    means and covariances).
    """

    means: np.ndarray | None
    covs: np.ndarray | None
    chols: np.ndarray | None
    eps: np.ndarray
    nis: np.ndarray
    loglik: np.ndarray
    ok: np.ndarray
    labels: tuple

    @property
    def cumulative_loglik(self) -> np.ndarray:
        return np.cumsum(self.loglik, axis=-1)


STORABLE = ("means", "covs", "chols")
"""What :func:`run_filter` can keep per step besides the innovations (``store``)."""


def run_filter(unit, model, measurements, x0, P0, mask=None, progress=False, store=("means", "covs")) -> FilterRun:
    """Filter passages with one filter unit.

    Parameters
    ----------
    unit : FilterUnit or str
        A unit from :func:`~shipsense.trackers.filters.get_filter` or its name.
    model : FieldModel or LinearModel
    measurements : ndarray, shape (..., steps, m)
        SI units (``FieldModel``) or model units (``LinearModel``); NaN = missing.
    x0 : ndarray, shape (..., n)
        Initial means (SI), the prior at the first sample.
    P0 : ndarray, shape (..., n, n)
        Initial covariances (SI).
    mask : ndarray of bool, shape (..., steps, m), optional
        False where a component is to be ignored.
    progress : bool
        Show a progress bar over the steps.
    store : sequence of str
        Which of ``"means"``, ``"covs"``, ``"chols"`` to keep per step (the others are None in the result);
        the innovations, log-likelihoods and health flags are always kept.  A factor per step costs a
        Cholesky factorisation (the filters' posteriors are in covariance form) and as much memory as the
        covariances: ask for what you use.

    The leading axes of ``measurements``, ``x0`` and ``P0`` broadcast: a bank
    of H hypotheses over R runs takes ``measurements[:, None]`` (R, 1, steps,
    m) and ``x0`` (R, H, n).  Step 0 is an update of the prior; later steps
    predict, then update.
    """
    store = (store,) if isinstance(store, str) else tuple(store)
    unknown = [s for s in store if s not in STORABLE]
    if unknown:
        raise ValueError(f"store: unknown {unknown[0]!r}; choose from {', '.join(STORABLE)}")
    if isinstance(unit, str):
        unit = get_filter(unit)
    if not isinstance(unit, FilterUnit):
        raise TypeError(f"unit must be a FilterUnit or a filter name, got {type(unit).__name__}")
    y = np.asarray(measurements, dtype=float)
    scale_x = getattr(model, "x_scale", np.ones(model.n))
    scale_y = getattr(model, "y_scale", np.ones(model.m))
    if y.shape[-1] != model.m:
        raise ValueError(f"measurements have {y.shape[-1]} channels, the model {model.m}")
    y = y / scale_y
    x0 = np.asarray(x0, dtype=float) / scale_x
    P0 = np.asarray(P0, dtype=float) / np.outer(scale_x, scale_x)
    batch = np.broadcast_shapes(y.shape[:-2], x0.shape[:-1], P0.shape[:-2])
    steps = y.shape[-2]
    belief = Belief.from_cov(np.broadcast_to(x0, batch + x0.shape[-1:]).copy(),
                             np.broadcast_to(P0, batch + P0.shape[-2:]))
    n, m = model.n, model.m
    means = np.empty(batch + (steps, n)) if "means" in store else None
    covs = np.empty(batch + (steps, n, n)) if "covs" in store else None
    chols = np.empty(batch + (steps, n, n)) if "chols" in store else None
    eps = np.empty(batch + (steps, m))
    nis = np.empty(batch + (steps,))
    loglik = np.empty(batch + (steps,))
    ok = np.empty(batch + (steps,), dtype=bool)
    filt = unit.on(model)                    # (its compiled or numpy steps, chosen once)
    iterator = range(steps)
    if progress:
        from tqdm import tqdm

        iterator = tqdm(iterator, desc=f"{unit.name} x {int(np.prod(batch))}", unit="step", leave=False, disable=None)
    for k in iterator:
        mk = None if mask is None else mask[..., k, :]
        belief, inn = (filt.step if k else filt.update)(belief, y[..., k, :], model, mk)
        if means is not None:
            means[..., k, :] = belief.mean
        if covs is not None:
            covs[..., k, :, :] = belief.cov
        if chols is not None:
            chols[..., k, :, :] = belief.chol
        eps[..., k, :] = inn.eps
        nis[..., k] = inn.nis
        loglik[..., k] = inn.loglik
        ok[..., k] = belief.ok
    if means is not None:
        means *= scale_x
    if covs is not None:
        covs *= np.outer(scale_x, scale_x)
    if chols is not None:
        chols *= scale_x[:, None]
    return FilterRun(means, covs, chols, eps, nis, loglik, ok, tuple(getattr(model, "labels", ())))
