"""shipsense.trackers.linalg: the eliminations agree with LAPACK and with each other."""

import numpy as np
from numba import njit

from shipsense.trackers.linalg import solve_in_place, solve_many_in_place


@njit(cache=False)
def _one_at_a_time(M, B):
    n, c = B.shape
    out = np.empty_like(B)
    for j in range(c):
        Mj, x = M.copy(), B[:, j].copy()
        solve_in_place(Mj, x, n)
        out[:, j] = x
    return out


@njit(cache=False)
def _together(M, B):
    Mc, X = M.copy(), B.copy()
    solve_many_in_place(Mc, X, B.shape[0], B.shape[1])
    return X


def test_one_elimination_for_many_right_hand_sides_gives_each_the_numbers_it_gets_alone():
    """Columns solved together equal, to the bit, each column solved alone (pivoting included: the matrices
    are not diagonally dominant), and LAPACK's solve to rounding."""
    rng = np.random.default_rng(0)
    for n, c in [(1, 1), (3, 2), (7, 7), (7, 2), (9, 4)]:
        for _ in range(20):
            M = rng.standard_normal((n, n)) * rng.uniform(1e-3, 1e3, n)[:, None]
            B = rng.standard_normal((n, c))
            together = _together(M, B)
            np.testing.assert_array_equal(together, _one_at_a_time(M, B))
            np.testing.assert_allclose(together, np.linalg.solve(M, B), rtol=1e-8, atol=1e-8 * np.abs(together).max())
