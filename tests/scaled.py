"""Comparisons at each quantity's own scale, for results that equal each other up to rounding.

Two computations of one filter (another batch size, another order of the same algebra, another BLAS kernel)
agree to rounding *relative to the scale of what they compute*, not entry by entry: a covariance entry of 1e-10
beside diagonals of 7 is rounding noise, and the rounding of a long recursion on a nearly singular model grows
with its conditioning and differs between machines. These helpers say what "equal" means for each kind of
quantity, so a test can be tight and still pass on every machine.
"""

import numpy as np


def cov_deviation(a, b):
    """Largest difference of two covariance stacks ``(..., n, n)`` in correlation units of ``b``."""
    sd = np.sqrt(np.abs(np.einsum("...ii->...i", b)))
    return float(np.max(np.abs(a - b) / (sd[..., :, None] * sd[..., None, :] + 1e-300)))


def assert_cov_close(a, b, tol):
    """Covariances equal to ``tol`` in correlation units (each entry against sqrt(P_ii P_jj))."""
    dev = cov_deviation(np.asarray(a), np.asarray(b))
    assert dev <= tol, f"covariances differ by {dev:.3g} in correlation units (allowed {tol:g})"


def assert_factor_close(a, b, tol):
    """Cholesky factors equal to ``tol``: compared through the covariances they stand for (a factor is unique)."""
    a, b = np.asarray(a), np.asarray(b)
    assert_cov_close(a @ np.swapaxes(a, -1, -2), b @ np.swapaxes(b, -1, -2), tol)


def assert_loglik_close(a, b, nats=1e-6):
    """Log-likelihoods equal to ``nats`` (absolute: 1e-6 nats is a likelihood ratio of 1 + 1e-6)."""
    dev = float(np.max(np.abs(np.asarray(a) - np.asarray(b))))
    assert dev <= nats, f"log-likelihoods differ by {dev:.3g} nats (allowed {nats:g})"


def close(a, b, tol):
    """True when arrays are equal to ``tol`` of their own scale (square stacks as covariances, else relative to
    max(|b|, 1))."""
    a, b = np.asarray(a), np.asarray(b)
    if a.ndim >= 2 and a.shape[-1] == a.shape[-2]:
        return cov_deviation(a, b) <= tol
    return bool(np.all(np.abs(a - b) <= tol * np.maximum(np.abs(b), 1.0)))
