r"""Motion modes of a manoeuvring ship over the tracker's state, for an interacting multiple model filter.

Every mode acts on the same state as the constant-velocity model (:mod:`shipsense.physics.motion`:
``(x, y, v_x, v_y)`` then the source parameters), so the modes' estimates mix and combine component by
component (:mod:`shipsense.trackers.filters.imm`).  The modes:

``cv``
    nearly constant velocity, the model's own transition ``A`` and process noise ``Q`` (the filter of a
    straight passage; the turn rate is held at zero);
``turn_left`` / ``turn_right``
    coordinated turns at the fixed rates :math:`\pm\omega` (Li & Jilkov 2003, section V.A; Bar-Shalom, Li &
    Kirubarajan 2001, section 11.7): with :math:`s = \sin\omega\tau`, :math:`c = \cos\omega\tau`,

    .. math::
        \begin{bmatrix} p' \\ v' \end{bmatrix} =
        \begin{bmatrix} I & \omega^{-1}\begin{bmatrix} s & c - 1 \\ 1 - c & s \end{bmatrix} \\
                        0 & \begin{bmatrix} c & -s \\ s & c \end{bmatrix} \end{bmatrix}
        \begin{bmatrix} p \\ v \end{bmatrix},

    the exact motion at that rate; a white acceleration of standard deviation ``turn_accel`` (m/s²) covers
    rates between the grid's, and a share ``body_fixed`` of the horizontal magnetic moment turns with the
    hull (its permanent part) while the rest stays with the earth's field (the induced part), with a random
    walk of the horizontal moment of standard deviation ``(1/2) |\omega \tau| |m_h|`` per step for a share
    that is not known;
``speed``
    a change of speed: a white acceleration along the course of standard deviation ``speed_accel`` (m/s²)
    (across it, the ``cv`` mode's).

Switching is a Markov chain with mean sojourn times (``sojourn_cv``, ``sojourn_manoeuvre``, s): the
probability of staying in mode ``i`` over a step ``tau`` is ``exp(-tau / sojourn_i)``, the rest shared equally
by the other modes.  Internal units of the model (m, m/s, moment units) throughout.

References: X. R. Li and V. P. Jilkov, "Survey of maneuvering target tracking, Part I: dynamic models",
IEEE T-AES 39(4), 2003; Y. Bar-Shalom, X. R. Li and T. Kirubarajan, *Estimation with Applications to
Tracking and Navigation*, Wiley 2001, ch. 11.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from shipsense.models.transitions import transitions
from shipsense.physics.motion import cv_transition

MODES = ("cv", "turn_left", "turn_right", "speed")
"""The motion modes, in the order of the IMM's mode axis."""


@dataclass(frozen=True)
class MotionModes:
    """The IMM's motion modes for one state-space model (see the module).

    Parameters
    ----------
    n : int
        State dimension.
    period : float
        Sampling period T, s.
    Q : ndarray, shape (n, n)
        The constant-velocity process noise per period (internal units).
    moment : int or None
        Index of the magnetic moment's ``m_x`` in the state (None: no moment).
    turn_rate : float
        The turn modes' rate, rad/s.
    turn_accel, speed_accel : float
        White acceleration standard deviations of the turn and speed modes, m/s².
    body_fixed : float
        Share of the horizontal moment that turns with the hull, in [0, 1].
    sojourn_cv, sojourn_manoeuvre : float
        Mean sojourn times, s.
    initial : tuple of float
        Mode probabilities at a (re)start, one per mode of :data:`MODES`.
    """

    n: int
    period: float
    Q: np.ndarray
    moment: int | None = None
    turn_rate: float = math.radians(2.0)
    turn_accel: float = 0.05
    speed_accel: float = 0.1
    body_fixed: float = 0.5
    sojourn_cv: float = 600.0
    sojourn_manoeuvre: float = 15.0
    initial: tuple = (0.97, 0.01, 0.01, 0.01)

    names = MODES

    @property
    def M(self) -> int:
        """Number of modes."""
        return len(MODES)

    @property
    def A(self) -> np.ndarray:
        """The constant-velocity transition over one period (n, n) (:func:`shipsense.physics.motion.cv_transition`),
        which :func:`shipsense.models.transitions.transitions` scales to any step."""
        return cv_transition(self.period, self.n - 4)

    @property
    def prior(self) -> np.ndarray:
        """Mode probabilities at a (re)start (M,)."""
        p = np.asarray(self.initial, dtype=float)
        return p / p.sum()

    def switching(self, tau):
        """Mode transition matrices ``Pi[..., i, j] = P(mode j after tau | mode i)`` (..., M, M) for steps
        ``tau`` (...) s."""
        tau = np.asarray(tau, dtype=float)
        sojourn = np.array([self.sojourn_cv] + [self.sojourn_manoeuvre] * (self.M - 1))
        stay = np.exp(-np.abs(tau)[..., None] / sojourn)                  # (..., M)
        out = np.broadcast_to(((1.0 - stay) / (self.M - 1))[..., :, None], tau.shape + (self.M, self.M)).copy()
        idx = np.arange(self.M)
        out[..., idx, idx] = stay
        return out

    def transitions(self, mean, tau):
        """Every mode's transition ``A`` and process noise ``Q`` for states ``mean`` (..., M, n) (the mixed
        means each mode starts from: the speed mode's noise follows their course, the turn modes' moment
        noise their moment) over steps ``tau`` (...) s: (..., M, n, n) each."""
        mean = np.asarray(mean, dtype=float)
        tau = np.asarray(tau, dtype=float)
        batch = np.broadcast_shapes(mean.shape[:-2], tau.shape)
        n, M = self.n, self.M
        r = tau / self.period
        A = np.broadcast_to(transitions(self, np.broadcast_to(tau, batch))[..., None, :, :],
                            batch + (M, n, n)).copy()    # every mode from the constant-velocity transition
        Q = np.broadcast_to(self.Q, batch + (M, n, n)) * r[..., None, None, None]
        Q = Q.copy()
        for j, sign in ((1, 1.0), (2, -1.0)):
            w = sign * self.turn_rate
            s, c = np.sin(w * tau), np.cos(w * tau)
            A[..., j, 0, 2], A[..., j, 0, 3] = s / w, (c - 1.0) / w
            A[..., j, 1, 2], A[..., j, 1, 3] = (1.0 - c) / w, s / w
            A[..., j, 2, 2], A[..., j, 2, 3], A[..., j, 3, 2], A[..., j, 3, 3] = c, -s, s, c
            Q[..., j, :4, :4] += _white_acceleration(tau, self.turn_accel, self.turn_accel, None)
            if self.moment is not None:
                k = self.moment
                a = self.body_fixed * w * tau
                ca, sa = np.cos(a), np.sin(a)
                A[..., j, k, k], A[..., j, k, k + 1], A[..., j, k + 1, k], A[..., j, k + 1, k + 1] = ca, -sa, sa, ca
                mh2 = mean[..., j, k] ** 2 + mean[..., j, k + 1] ** 2
                var = (0.5 * w * tau) ** 2 * mh2
                Q[..., j, k, k] += var
                Q[..., j, k + 1, k + 1] += var
        v = mean[..., 3, 2:4]
        speed = np.sqrt(np.sum(v * v, axis=-1))
        course = np.where(speed[..., None] > 0, v / np.where(speed > 0, speed, 1.0)[..., None], [1.0, 0.0])
        Q[..., 3, :4, :4] += _white_acceleration(tau, self.speed_accel, 0.0, course)
        return A, Q


def _white_acceleration(tau, along, across, course):
    """Discrete white-noise acceleration (Bar-Shalom et al. 2001, section 6.3.2) on ``(x, y, v_x, v_y)``:
    ``G Sigma G^T`` with ``G = [tau^2/2 I; tau I]`` and ``Sigma`` of standard deviations ``along`` the unit
    vectors ``course`` (..., 2) and ``across`` them (isotropic when ``course`` is None); (..., 4, 4)."""
    tau = np.asarray(tau, dtype=float)
    if course is None:
        S = np.broadcast_to(np.eye(2) * along ** 2, tau.shape + (2, 2))
    else:
        u = np.asarray(course, dtype=float)
        uu = u[..., :, None] * u[..., None, :]
        S = along ** 2 * uu + across ** 2 * (np.eye(2) - uu)
    g = np.stack([0.5 * tau * tau, tau], axis=-1)                          # (..., 2)
    gg = g[..., :, None] * g[..., None, :]                                  # (..., 2, 2)
    out = np.empty(np.broadcast_shapes(gg.shape[:-2], S.shape[:-2]) + (4, 4))
    for a in range(2):
        for b in range(2):
            out[..., a * 2:(a + 1) * 2, b * 2:(b + 1) * 2] = gg[..., a, b, None, None] * S
    return out


def motion_modes(model, **options) -> MotionModes:
    """The motion modes of a state-space ``model`` (its ``n``, ``period``, ``Q`` and, for a field model, the
    moment's place in the state), with ``options`` of :class:`MotionModes`."""
    labels = tuple(getattr(model, "labels", ()))
    return MotionModes(n=model.n, period=float(getattr(model, "period", 1.0)), Q=np.asarray(model.Q, dtype=float),
                       moment=labels.index("mx") if "mx" in labels else None, **options)
