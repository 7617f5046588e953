"""Vectorised small-matrix kernels of the filter core agree with LAPACK / matmul and flag failures."""

import numpy as np
import pytest

from shipsense.models.field_model import LinearModel
from shipsense.physics.motion import cv_transition
from shipsense.trackers.filters.core import Belief, _cholesky_unrolled, _transition, predict, safe_cholesky


def spd(rng, batch, n):
    A = rng.standard_normal((batch, n, n + 2))
    return A @ np.swapaxes(A, -1, -2)


@pytest.mark.parametrize("n", [1, 3, 7, 9])
def test_unrolled_cholesky_equals_lapack(n):
    P = spd(np.random.default_rng(n), 700, n)
    np.testing.assert_allclose(_cholesky_unrolled(P), np.linalg.cholesky(P), rtol=1e-10, atol=1e-12)


def test_large_batch_cholesky_flags_only_the_bad_elements():
    rng = np.random.default_rng(1)
    P = spd(rng, 900, 7)
    P[5] = np.diag([1.0, 1.0, -1.0, 1.0, 1.0, 1.0, 1.0])   # indefinite
    P[17, 3, 2] = np.nan                                    # non-finite (lower triangle)
    L, ok = safe_cholesky(P)
    assert np.flatnonzero(~ok).tolist() == [5, 17]
    assert np.isfinite(L).all()
    good = np.ones(900, bool)
    good[[5, 17]] = False
    np.testing.assert_allclose(L[good], np.linalg.cholesky(P[good]), rtol=1e-10, atol=1e-12)


def test_a_bad_element_leaves_the_others_their_own_factors():
    """Below the unrolled form's batch, a batch with an indefinite, a non-finite and a very indefinite element
    (LAPACK fails on the whole stack) gives every other element LAPACK's factor to the bit -- what it gets alone
    --, and the bad ones what they get alone (flagged): the factors do not depend on the batch.  (Before, the
    whole batch was repaired through its eigendecomposition, moving every factor at rounding: an environment's
    run-ins side by side differed from one at a time.)"""
    rng = np.random.default_rng(4)
    P = spd(rng, 200, 7)
    P[17] = -np.eye(7)
    P[120, 0, 0] = np.nan
    P[121] -= 50.0 * np.eye(7)
    L, ok = safe_cholesky(P)
    assert np.flatnonzero(~ok).tolist() == [17, 120, 121]
    for i in range(200):
        alone, ok_alone = safe_cholesky(P[i:i + 1])
        np.testing.assert_array_equal(L[i], alone[0])
        assert ok[i] == ok_alone[0]
        if ok[i]:
            np.testing.assert_array_equal(L[i], np.linalg.cholesky(P[i]))
    L2, ok2 = safe_cholesky(P.reshape(20, 10, 7, 7))                 # leading batch axes kept
    np.testing.assert_array_equal(L2.reshape(L.shape), L)
    np.testing.assert_array_equal(ok2.ravel(), ok)


@pytest.mark.parametrize("A", [cv_transition(0.5, 3), np.eye(4) + np.triu(np.ones((4, 4)), 1)], ids=["cv", "dense"])
def test_transition_by_row_operations_equals_matmul(A):
    M = np.random.default_rng(2).standard_normal((5, A.shape[0], A.shape[0]))
    np.testing.assert_allclose(_transition(A, M), A @ M, rtol=1e-14, atol=1e-14)
    np.testing.assert_allclose(_transition(A, M, both_sides=True), A @ M @ A.T, rtol=1e-14, atol=1e-13)


def test_predict_from_a_cached_covariance_equals_predict_from_the_factor():
    rng = np.random.default_rng(3)
    A = cv_transition(0.5, 3)
    model = LinearModel(A, 0.1 * np.eye(7), np.eye(3, 7), np.ones(3))
    P = spd(rng, 600, 7)
    first = predict(Belief.from_cov(rng.standard_normal((600, 7)), P), model)   # carries its covariance
    assert getattr(first, "_cov", None) is not None
    plain = Belief(*first)                                                       # drops it
    assert getattr(plain, "_cov", None) is None
    a, b = predict(first, model), predict(plain, model)
    np.testing.assert_allclose(a.mean, b.mean, rtol=1e-14)
    np.testing.assert_allclose(a.cov, b.cov, rtol=1e-10, atol=1e-12)


def test_a_posterior_is_factorised_on_first_use_like_an_eager_one():
    """The update's covariance is factorised only when needed; every way of reading the belief sees the factor."""
    import pickle

    from shipsense.trackers.filters import ukf
    from shipsense.trackers.filters.core import _Posterior

    rng = np.random.default_rng(4)
    model = LinearModel(cv_transition(0.5, 3), 0.1 * np.eye(7), rng.standard_normal((3, 7)), np.ones(3))
    prior = predict(Belief.from_cov(rng.standard_normal((40, 7)), spd(rng, 40, 7)), model)
    post, _ = ukf.update(prior, rng.standard_normal((40, 3)), model)   # the numpy step (the compiled one factors)
    assert tuple.__getitem__(post, 1) is None                       # nothing factorised yet
    nxt = predict(post, model)                                      # the time update does not need the factor
    assert tuple.__getitem__(post, 1) is None
    L, ok = safe_cholesky(post.cov)
    np.testing.assert_array_equal(post.chol, L)
    assert post.ok.all() and ok.all()
    mean, chol, flag = post                                         # unpacking, indexing and pickling see it too
    assert chol is post.chol and post[1] is post.chol and flag is post.ok
    again = pickle.loads(pickle.dumps(post))
    np.testing.assert_array_equal(again.chol, L)
    np.testing.assert_array_equal(Belief(*again).mean, mean)
    np.testing.assert_allclose(predict(Belief(*post), model).cov, nxt.cov, rtol=1e-10, atol=1e-12)
    # an indefinite posterior covariance is flagged (and repaired) when the factor is read
    cov = post.cov.copy()
    cov[3] = -np.eye(7)
    bad = _Posterior.pending(post.mean, np.ones(40, bool), cov)
    assert np.flatnonzero(~bad.ok).tolist() == [3] and np.isfinite(bad.chol).all()
