"""The compiled report of a bank's selection (:func:`shipsense.trackers.bank.selection.report`) against its numpy
definition: argmax, the mixture mean-square error, the gap, the ambiguity flag and the hypothesis count,
including the edge cases a bank meets (padded -inf hypotheses, a NaN log-likelihood, ties)."""

import numpy as np
import pytest

from shipsense.trackers.bank.selection import mixture_mse, report


def _numpy_report(mean, chol, runs, H, xs, cum, mixture, nats, far_m, excess):
    n = mean.shape[1]
    rows = (runs[:, None] * H + np.arange(H)).ravel()
    means = (mean[rows] * xs).reshape(len(runs), H, n)
    covs = ((chol @ np.swapaxes(chol, -1, -2))[rows] * np.outer(xs, xs)).reshape(len(runs), H, n, n)
    pick = np.arange(len(runs))
    sel = np.argmax(cum, axis=1)
    best = means[pick, sel]
    if mixture:
        with np.errstate(invalid="ignore"):
            w = np.exp(cum - cum[pick, sel][:, None])
            w /= w.sum(axis=1, keepdims=True)
        cov = mixture_mse(w, means, covs, best[:, None])
    else:
        cov = covs[pick, sel]
    cov = 0.5 * (cov + np.swapaxes(cov, -1, -2)) * excess[runs, None, None]
    with np.errstate(invalid="ignore"):
        live = cum > np.max(cum, axis=1, keepdims=True) - nats
        ranked = np.sort(np.where(np.isfinite(cum), cum, -np.inf), axis=1)
        gap = ranked[:, -1] - ranked[:, -2] if H > 1 else np.full(len(runs), np.inf)
    d = means[:, :, None, :2] - means[:, None, :, :2]
    far = np.einsum("rijk,rijk->rij", d, d) > far_m ** 2
    amb = np.any(far & live[:, :, None] & live[:, None, :], axis=(1, 2))
    return (best, cov, np.trace(covs[pick, sel, :2, :2], axis1=-2, axis2=-1), gap, amb,
            np.isfinite(cum).sum(axis=1), sel)


@pytest.mark.parametrize("far_m", [0.5, 40.0])
@pytest.mark.parametrize("mixture", [True, False])
def test_the_compiled_report_is_the_numpy_selection(mixture, far_m):
    rng = np.random.default_rng(4)
    P, H, n = 7, 5, 7
    mean = rng.normal(size=(P * H, n))
    chol = np.tril(rng.normal(size=(P * H, n, n)))
    xs = np.array([30.0, 30.0, 1.0, 1.0, 1e4, 1e4, 1e4])
    runs = np.array([0, 2, 3, 4, 5, 6])
    cum = rng.normal(scale=3.0, size=(len(runs), H))
    cum[1, 3:] = -np.inf                                     # padded hypotheses (no weight)
    cum[2, 1] = np.nan                                       # a failed hypothesis: argmax picks the NaN
    cum[3] = -np.inf                                         # nothing finite
    cum[4, 2] = cum[4, 0] = cum[4].max() + 1.0               # a tie: the first
    cum[5, :] = 0.0                                          # all live, all within 24 m of each other
    rows5 = runs[5] * H + np.arange(H)
    mean[rows5, 0], mean[rows5, 1] = 0.2 * np.arange(H), 1.0
    excess = rng.uniform(1.0, 3.0, P)
    outs = (np.full((P, n), -7.0), np.full((P, n, n), -7.0), np.full(P, -7.0), np.full(P, -7.0),
            np.zeros(P, bool), np.full(P, -7, np.int16), np.full(P, -7, np.int16))
    report(mean, chol, runs, H, xs, cum, mixture, 3.0, far_m, excess, *outs)
    with np.errstate(invalid="ignore"):
        expected = _numpy_report(mean, chol, runs, H, xs, cum, mixture, 3.0, far_m, excess)
    for got, want in zip(outs, expected):
        np.testing.assert_allclose(got[runs], want, rtol=1e-12, atol=0)
    assert (outs[0][1] == -7.0).all() and outs[5][1] == -7    # a passage not reported is left alone
    assert outs[6][runs[2]] == 1 and outs[6][runs[4]] == 0
    if far_m == 40.0:                                        # hypotheses both near and far apart (30 m units)
        assert outs[4][runs].any() and not outs[4][runs[5]]
