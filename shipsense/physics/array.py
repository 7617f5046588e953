"""A sensor array as a measurement function: source state -> stacked channels.

This is the one place where the field kernels are turned into what a set of
sensors reports.  The simulator, the trackers' measurement models and the
design tools all call :meth:`SensorArray.measure`, vectorised over any leading
batch axes and over sensors (no Python loop over sensors).

Channel layout: sensors in order, each contributing its measurement kind's
components (see :data:`CHANNELS`).  Units are SI: tesla, V/m, radians.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from shipsense.physics.electric import Medium, fast_hed, hed_field, magnitude_jacobian, magnitude_reading
from shipsense.physics.magnetic import dipole_field_at, dipole_field_jacobian
from shipsense.physics.seismic import bearing, bearing_jacobian

CHANNELS: dict[tuple[str, str], tuple[str, ...]] = {
    ("magnetometer", "vector"): ("bx", "by", "bz"),
    ("magnetometer", "magnitude"): ("b",),
    ("magnetometer", "tmi"): ("tmi",),
    ("electrode", "vector"): ("ex", "ey", "ez"),
    ("electrode", "envelope"): ("ex", "ey", "ez"),
    ("electrode", "magnitude"): ("e",),
    ("accelerometer", "bearing"): ("bearing",),
}
"""Channel names of each (sensor type, measurement kind)."""

UNITS = {"magnetometer": "T", "electrode": "V/m", "accelerometer": "rad"}
KINDS = {t: tuple(k for (tt, k) in CHANNELS if tt == t) for t in UNITS}
"""Measurement kinds allowed for each sensor type."""

_SCALAR_KIND_CODE = {"magnitude": 1, "tmi": 2}


def as_slice(idx):
    """Consecutive indices as a slice (basic indexing: views, no gather), other indices unchanged; None if empty."""
    idx = np.asarray(idx, dtype=int)
    if idx.size == 0:
        return None
    if np.array_equal(idx, np.arange(idx[0], idx[0] + idx.size)):
        return slice(int(idx[0]), int(idx[0]) + idx.size)
    return idx


def _block(a, batch):
    """Per-sensor readings (..., S, w) as one flat block (*batch, S * w), broadcast to the batch if needed."""
    shape = batch + (a.shape[-2] * a.shape[-1],)
    if a.shape[:-2] != batch:
        return np.broadcast_to(a, batch + a.shape[-2:]).reshape(shape)
    return a.reshape(shape)


@dataclass(frozen=True, eq=False)
class SensorArray:
    """Positions, types and measurement kinds of an array of seabed sensors.

    Parameters
    ----------
    ids : sequence of str
    types : sequence of {"magnetometer", "electrode", "accelerometer"}
    kinds : sequence of str
        Measurement kind of each sensor (``KINDS[type]``).
    positions : array_like, shape (S, 3)
        World coordinates, m.
    orientations : array_like, shape (S, 3, 3), optional
        Columns are the sensor axes in world coordinates (identity if omitted);
        applies to vector and envelope readings (magnitudes do not depend on it).
    medium : Medium, optional
        Required when the array has electrodes.
    earth_direction : array_like, shape (3,), optional
        Unit Earth-field vector for ``tmi`` readings.
    electric_method : {"fast", "series"}
        Which HED path :meth:`measure` uses.
    """

    ids: tuple
    types: tuple
    kinds: tuple
    positions: np.ndarray
    orientations: np.ndarray | None = None
    medium: Medium | None = None
    earth_direction: np.ndarray | None = None
    electric_method: str = "fast"
    _index: dict = field(init=False, repr=False)

    def __post_init__(self):
        S = len(self.ids)
        pos = np.asarray(self.positions, dtype=float).reshape(S, 3)
        R = np.broadcast_to(np.eye(3), (S, 3, 3)) if self.orientations is None else np.asarray(self.orientations, float)
        object.__setattr__(self, "positions", pos)
        object.__setattr__(self, "orientations", np.array(R))
        object.__setattr__(self, "ids", tuple(self.ids))
        object.__setattr__(self, "types", tuple(self.types))
        object.__setattr__(self, "kinds", tuple(self.kinds))
        gather, channels = [], []
        for s, (sid, t, k) in enumerate(zip(self.ids, self.types, self.kinds)):
            if (t, k) not in CHANNELS:
                raise ValueError(f"sensor {sid!r}: unknown measurement kind {k!r} for a {t}")
            for c, name in enumerate(CHANNELS[(t, k)]):
                gather.append(3 * s + c)
                channels.append((sid, name))
        groups = {t: np.array([i for i, tt in enumerate(self.types) if tt == t], dtype=int) for t in UNITS}
        if groups["electrode"].size and self.medium is None:
            raise ValueError("an array with electrode sensors needs a medium")
        if self.earth_direction is None and "tmi" in self.kinds:
            raise ValueError("an array with tmi magnetometers needs earth_direction")
        mag_code = np.array([_SCALAR_KIND_CODE.get(self.kinds[i], 0) for i in groups["magnetometer"]], dtype=int)
        env = np.array([self.kinds[i] == "envelope" for i in groups["electrode"]], dtype=bool)
        emag = np.array([self.kinds[i] == "magnitude" for i in groups["electrode"]], dtype=bool)
        identity = np.allclose(self.orientations, np.eye(3), rtol=0, atol=0)
        # measure() stacks the sensor types' blocks (magnetometers and electrodes 3 slots per sensor, bearings 1)
        block = {"magnetometer": 0, "electrode": 3 * groups["magnetometer"].size,
                 "accelerometer": 3 * (groups["magnetometer"].size + groups["electrode"].size)}
        width = {"magnetometer": 3, "electrode": 3, "accelerometer": 1}
        group_gather = [block[self.types[g // 3]] + width[self.types[g // 3]] * int(np.flatnonzero(
            groups[self.types[g // 3]] == g // 3)[0]) + g % 3 for g in gather]
        object.__setattr__(self, "_index", {
            "gather": np.array(gather, dtype=int),
            "channels": tuple(channels), "groups": groups,
            "mag_code": mag_code, "envelope": env, "electric_magnitude": emag, "identity": identity,
            "positions": {t: pos[g] for t, g in groups.items()},
            "mag_vector_only": bool(mag_code.size) and not mag_code.any(),
            "group_gather": None if group_gather == list(range(block["accelerometer"] + groups["accelerometer"].size))
            else as_slice(np.array(group_gather, dtype=int)),
        })

    @property
    def channels(self) -> tuple[tuple[str, str], ...]:
        """(sensor id, channel name) of every stacked measurement component."""
        return self._index["channels"]

    @property
    def n_channels(self) -> int:
        return len(self.channels)

    @property
    def channel_sensor(self) -> np.ndarray:
        """Index of the sensor of each channel, shape (m,)."""
        return self._index["gather"] // 3

    @property
    def channel_units(self) -> tuple[str, ...]:
        return tuple(UNITS[self.types[s]] for s in self.channel_sensor)

    @property
    def axial(self) -> np.ndarray:
        """Boolean (m,): channels that are axial angles (residuals wrap modulo pi)."""
        return np.array([self.kinds[s] == "bearing" for s in self.channel_sensor], dtype=bool)

    def group(self, sensor_type: str) -> np.ndarray:
        """Indices of the sensors of one type."""
        return self._index["groups"][sensor_type]

    def electric_field(self, sources, dipoles):
        """Oriented electric field ``R^T E`` at the electrodes, shape (..., S_e, 3), V/m."""
        idx = self.group("electrode")
        E = hed_field(self.positions[idx], np.asarray(sources, float)[..., None, :],
                      np.asarray(dipoles, float)[..., None, :], self.medium, method=self.electric_method)
        return E if self._index["identity"] else np.einsum("sji,...sj->...si", self.orientations[idx], E)

    def measure(self, sources, moments=None, dipoles=None):
        """Noise-free measurements of every channel.

        Parameters
        ----------
        sources : array_like, shape (..., 3)
            Source position (world, m).
        moments : array_like, shape (..., 3), optional
            Magnetic moment, A·m² (needed if the array has magnetometers).
        dipoles : array_like, shape (..., 3), optional
            Horizontal electric dipole moment, A·m (needed for electrodes).

        Returns
        -------
        y : ndarray, shape (..., m)
            Stacked channels in :attr:`channels` order, SI units.
        """
        # complex inputs pass through the magnetic and bearing paths (complex-step derivatives)
        sources = np.asarray(sources)
        moments = None if moments is None else np.asarray(moments)
        dtype = np.result_type(sources, float) if moments is None else np.result_type(sources, moments, float)
        sources = sources.astype(dtype, copy=False)
        groups = self._index["groups"]
        batch = np.broadcast_shapes(sources.shape[:-1],
                                    *(np.shape(a)[:-1] for a in (moments, dipoles) if a is not None))
        parts = []   # per sensor type, (..., channels of that type's block) in group order
        idx = groups["magnetometer"]
        if idx.size:
            if moments is None:
                raise ValueError("this array has magnetometers: moments are required")
            B = dipole_field_at(self._index["positions"]["magnetometer"], sources, moments)
            vec = B if self._index["identity"] else np.einsum("sji,...sj->...si", self.orientations[idx], B)
            if not self._index["mag_vector_only"]:
                code = self._index["mag_code"]
                scalar = np.sqrt(np.sum(B * B, axis=-1))
                if np.any(code == 2):
                    scalar = np.where(code == 2, B @ self.earth_direction, scalar)
                vec = np.where((code == 0)[:, None], vec, np.stack([scalar, 0 * scalar, 0 * scalar], axis=-1))
            parts.append(_block(vec, batch))
        idx = groups["electrode"]
        if idx.size:
            if dipoles is None:
                raise ValueError("this array has electrodes: dipoles are required")
            E = self.electric_field(sources, dipoles)
            out = np.where(self._index["envelope"][:, None], np.abs(E), E)
            emag = self._index["electric_magnitude"]
            if emag.any():   # one channel, |E|, in the sensor's first slot
                e = magnitude_reading(E)
                out = np.where(emag[:, None], np.stack([e, 0 * e, 0 * e], axis=-1), out)
            parts.append(_block(out, batch))
        idx = groups["accelerometer"]
        if idx.size:
            parts.append(_block(bearing(self._index["positions"]["accelerometer"], sources[..., None, :])[..., None],
                                batch))
        if not parts:
            return np.zeros(batch + (0,), dtype=dtype)
        flat = parts[0] if len(parts) == 1 else np.concatenate(parts, axis=-1)
        g = self._index["group_gather"]
        return flat if g is None else flat[..., g]

    def _scalar_jacobian_rows(self, idx, R, B, dBq, dBm, val, dq, dm):
        """Readings and derivatives of magnetometers ``idx`` when some are scalar (magnitude, tmi), written
        into :meth:`measure_jacobian`'s blocks ``val``, ``dq``, ``dm``."""
        code = self._index["mag_code"]
        vec = np.einsum("sji,...sj->...si", R, B)
        # row vector of the scalar reading: b-hat for magnitude, b_E for tmi
        norm = np.sqrt(np.sum(B * B, axis=-1, keepdims=True))
        w = B / np.where(norm > 0, norm, 1.0)
        if np.any(code == 2):
            w = np.where((code == 2)[:, None], self.earth_direction, w)
        scalar = np.sum(w * B, axis=-1)
        is_vec = (code == 0)[:, None]
        val[..., idx, :] = np.where(is_vec, vec, np.stack([scalar, 0 * scalar, 0 * scalar], axis=-1))
        for target, dB in ((dq, dBq), (dm, dBm)):
            rows = np.einsum("sji,...sjk->...sik", R, dB)
            srow = np.einsum("...sj,...sjk->...sk", w, dB)
            first = np.concatenate([srow[..., None, :], np.zeros_like(rows[..., 1:, :])], axis=-2)
            target[..., idx, :, :] = np.where(is_vec[..., None], rows, first)

    def measure_jacobian(self, sources, moments=None, dipoles=None):
        """Measurements and their derivatives with respect to the source's position and moments.

        Same arguments as :meth:`measure`.  Returns ``(y, dy_dq, dy_dm, dy_dp)``
        with shapes (..., m), (..., m, 3) (source position), (..., m, 3)
        (magnetic moment) and (..., m, 2) (horizontal electric dipole).  The
        electric derivatives come from the fast HED path
        (:meth:`~shipsense.physics.electric.FastHED.field_jacobian`).  An
        envelope channel's derivative is ``sign(E)`` times the field's (it has
        a kink where the field changes sign); an electric magnitude's is
        ``E^T dE / |E|``, zero where the field vanishes
        (:func:`~shipsense.physics.electric.magnitude_jacobian`).
        """
        sources = np.asarray(sources, dtype=float)
        groups = self._index["groups"]
        batch = np.broadcast_shapes(sources.shape[:-1],
                                    *(np.shape(a)[:-1] for a in (moments, dipoles) if a is not None))
        S = len(self.ids)
        val = np.zeros(batch + (S, 3))
        dq = np.zeros(batch + (S, 3, 3))
        dm = np.zeros(batch + (S, 3, 3))
        dp = np.zeros(batch + (S, 3, 2))
        idx = groups["magnetometer"]
        if idx.size:
            if moments is None:
                raise ValueError("this array has magnetometers: moments are required")
            B, dBq, dBm = dipole_field_jacobian(self.positions[idx], sources[..., None, :],
                                                np.asarray(moments, float)[..., None, :])
            R = self.orientations[idx]
            if self._index["mag_vector_only"]:   # three-axis readings only: no scalar rows to form
                if self._index["identity"]:
                    val[..., idx, :], dq[..., idx, :, :], dm[..., idx, :, :] = B, dBq, dBm
                else:
                    val[..., idx, :] = np.einsum("sji,...sj->...si", R, B)
                    for target, dB in ((dq, dBq), (dm, dBm)):
                        target[..., idx, :, :] = np.einsum("sji,...sjk->...sik", R, dB)
            else:
                self._scalar_jacobian_rows(idx, R, B, dBq, dBm, val, dq, dm)
        idx = groups["electrode"]
        if idx.size:
            if dipoles is None:
                raise ValueError("this array has electrodes: dipoles are required")
            E, dEq, G = fast_hed(self.medium).field_jacobian(
                self.positions[idx], sources[..., None, :], np.asarray(dipoles, float)[..., None, :])
            if not self._index["identity"]:   # sensor axes other than the world's
                R = self.orientations[idx]
                E = np.einsum("sji,...sj->...si", R, E)
                dEq = np.einsum("sji,...sjk->...sik", R, dEq)
                G = np.einsum("sji,...sjk->...sik", R, G)
            env = self._index["envelope"][:, None]
            sign = np.where(env, np.sign(E), 1.0)
            val[..., idx, :] = np.where(env, np.abs(E), E)
            dq[..., idx, :, :] = sign[..., None] * dEq
            dp[..., idx, :, :] = sign[..., None] * G
            emag = self._index["electric_magnitude"]
            if emag.any():   # magnitude sensors: |E| and its row in the first slot, zeros in the others
                sel = idx[emag]
                e, de_q = magnitude_jacobian(E[..., emag, :], dEq[..., emag, :, :])
                _, de_p = magnitude_jacobian(E[..., emag, :], G[..., emag, :, :])
                val[..., sel, :] = np.stack([e, 0 * e, 0 * e], axis=-1)
                dq[..., sel, :, :] = np.concatenate([de_q[..., None, :], np.zeros_like(dEq[..., emag, 1:, :])], -2)
                dp[..., sel, :, :] = np.concatenate([de_p[..., None, :], np.zeros_like(G[..., emag, 1:, :])], -2)
        idx = groups["accelerometer"]
        if idx.size:
            val[..., idx, 0] = bearing(self.positions[idx], sources[..., None, :])
            dq[..., idx, 0, :] = bearing_jacobian(self.positions[idx], sources[..., None, :])
        g = self._index["gather"]
        flat = batch + (3 * S,)
        return (val.reshape(flat)[..., g], dq.reshape(flat + (3,))[..., g, :],
                dm.reshape(flat + (3,))[..., g, :], dp.reshape(flat + (2,))[..., g, :])
