"""Detection: where a passage's signal starts, and where its refinement window ends.

The strength of a sample is its strongest field channel's signal-to-noise
ratio (:func:`strongest_snr`); a passage is detected when it exceeds a
threshold (:func:`detection_start`), and its window ends ``window`` samples
later or once the signal has fallen past its peak (:func:`fit_end`).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from shipsense import numba_cache


def window_samples(model, K, window_s=15.0):
    """Samples W of the fitted window: ``window_s`` seconds, at least 4, less than the K samples."""
    return int(np.clip(round(window_s / model.period), 4, K - 1))


def strongest_snr(model, y):
    """The strongest field channel's SNR per sample (R, K) of measurements in internal units (R, K, m):
    ``max_i |y_i| / sqrt(R_i)`` over the field channels, a missing value counting 0 and an infinite one the
    dtype's largest (compiled, :func:`strongest_kernel`; the tracker calls it every sample)."""
    a = np.asarray(y)
    big = DOUBLE_MAX
    if a.dtype != np.float64 or not a.dtype.isnative:     # (the tracker's own samples, native doubles, as they are)
        if a.dtype.kind == "c":
            a = np.abs(a)                                 # the modulus
        if a.dtype.kind != "f":
            a = a.astype(float)
        big = float(np.finfo(a.dtype).max)
        if a.dtype not in (np.float32, np.float64) or not a.dtype.isnative:   # (float16, long double, byte-swapped)
            with np.errstate(over="ignore", invalid="ignore"):
                a = np.minimum(np.abs(a), big).astype(float)   # clamped at their own largest, then as doubles
            big = DOUBLE_MAX
    out = np.empty(a.shape[:-1])
    strongest_kernel(np.ascontiguousarray(a).reshape(-1, a.shape[-1]), ~model.axial, np.sqrt(model.R), big,
               out.reshape(-1))
    return out if out.ndim else out[()]


DOUBLE_MAX = float(np.finfo(np.float64).max)


@njit(cache=True, error_model="numpy", nogil=True)
def strongest_kernel(y, field, std, big, out):
    """``out[s] = max_i (min(|y[s, i]|, big) / std[i] if field[i] else 0)`` (NaN -> 0; the max NaN if any
    ratio is, as numpy's)."""
    for s in range(y.shape[0]):
        best = 0.0
        for i in range(y.shape[1]):
            v = 0.0
            if field[i]:
                a = abs(y[s, i])
                if a != a:
                    a = 0.0
                v = min(a, big) / std[i]
            if i == 0:
                best = v
            elif best == best and not v <= best:
                best = v
        out[s] = best


def detection_start(model, measurements, snr_start=5.0, window=0):
    """First sample (R,) at which some field channel exceeds ``snr_start`` noise standard deviations.

    The adaptive start of :func:`global_init`'s window (0 if never; at most
    ``K - window - 1`` so that the window fits).  ``measurements`` (R, K, m) SI.
    """
    y = np.asarray(measurements, dtype=float) / model.y_scale
    K = y.shape[1]
    snr = strongest_snr(model, y)
    above = snr > snr_start
    k0 = np.where(above.any(axis=1), np.argmax(above, axis=1), 0)
    return np.minimum(k0, K - window - 1).clip(0)


def fit_end(model, measurements, k0, window, through_peak=None):
    """End (exclusive, (R,)) of the refinement window that starts at ``k0``: ``k0 + window``, or with
    ``through_peak`` (a fraction) the first later sample at which the strongest channel's SNR has
    fallen below that fraction of its maximum since ``k0`` -- the fit then spans the closest
    approach -- if the passage gets there (else ``k0 + window``); at most ``K - 1``."""
    y = np.asarray(measurements, dtype=float) / model.y_scale
    R, K = y.shape[:2]
    k0 = np.asarray(k0, dtype=int)
    end = np.minimum(k0 + window, K - 1)
    if through_peak is None:
        return end
    snr = strongest_snr(model, y)
    k = np.arange(K)[None, :]
    since = np.where(k >= k0[:, None], snr, 0.0)
    peak = np.maximum.accumulate(since, axis=1)
    past = (k >= end[:, None]) & (since < through_peak * peak) & (k < K - 1)
    return np.where(past.any(axis=1), np.argmax(past, axis=1), end)


numba_cache.key_on_sources(globals())   # the caches follow the files these kernels are compiled from
