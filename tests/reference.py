"""Independent references for the tests (on the path through ``pythonpath = ["tests"]``)."""

import numpy as np


def kalman_reference(A, Q, C, R, y, x0, P0):
    """Textbook Kalman filter with explicit inverses, one batch element at a time: the independent reference
    the filters (numpy and compiled) are checked against."""
    x, P = x0.copy(), P0.copy()
    xs, Ps, ll = [], [], []
    for k in range(y.shape[0]):
        if k:
            x, P = A @ x, A @ P @ A.T + Q
        S = C @ P @ C.T + R
        K = P @ C.T @ np.linalg.inv(S)
        e = y[k] - C @ x
        ll.append(-0.5 * (len(e) * np.log(2 * np.pi) + np.log(np.linalg.det(S)) + e @ np.linalg.inv(S) @ e))
        x, P = x + K @ e, (np.eye(len(x)) - K @ C) @ P
        xs.append(x)
        Ps.append(P)
    return np.array(xs), np.array(Ps), np.array(ll)
