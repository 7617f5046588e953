r"""Shaft-rate envelope signal chain.

A channel of an electrode sensor records, at a high rate,

.. math::  x_i(t) = A_i(t) \cos(2\pi f_s t + \varphi) + n(t),

where :math:`A_i(t)` is the quasi-static HED field of the channel (signed) and
:math:`f_s` the shaft rate.  The envelope :math:`|A_i(t)|` is recovered by
(1) the magnitude of the analytic signal (Hilbert transform), (2) a zero-phase
low-pass filter (default 0.5 Hz) and (3) decimation to the tracker period.  A ``magnitude`` electrode reports the
envelope of :math:`|E(t)|`, which is :math:`|A(t)|`: the root sum of squares
of its three channels' analytic-signal magnitudes, then the same low-pass.
All functions work along the time axis ``-2`` of (..., samples, channels)
arrays.
"""

from __future__ import annotations

import numpy as np


def raw_channels(amplitude, times, shaft_hz, phase=0.0, noise_std=0.0, rng=None):
    """Simulate raw shaft-rate channels.

    Parameters
    ----------
    amplitude : ndarray, shape (..., n_samples, n_channels)
        Signed field amplitude ``A_i(t)`` of each channel at ``times``, V/m.
    times : ndarray, shape (n_samples,)
        Sample times, s.
    shaft_hz : float
        Shaft rotation frequency, Hz.
    phase : float or ndarray broadcastable to (..., 1, 1)
        Carrier phase, rad.
    noise_std : float or ndarray broadcastable to (..., n_channels)
        Standard deviation of white Gaussian noise per raw sample, V/m.
    rng : numpy.random.Generator, optional
        Required when ``noise_std`` is non-zero.

    Returns
    -------
    x : ndarray, same shape as ``amplitude``
    """
    amplitude = np.asarray(amplitude, dtype=float)
    carrier = np.cos(2.0 * np.pi * shaft_hz * np.asarray(times)[:, None] + phase)
    x = amplitude * carrier
    if np.any(np.asarray(noise_std) > 0):
        if rng is None:
            raise ValueError("rng is required when noise_std > 0")
        x = x + np.asarray(noise_std) * rng.standard_normal(x.shape)
    return x


def extract_envelope(raw, rate_hz, lowpass_hz=0.5, order=4):
    """Envelope of raw channels at the raw rate: ``lowpass(|hilbert(x)|)``.

    Parameters
    ----------
    raw : ndarray, shape (..., n_samples, n_channels)
    rate_hz : float
        Sample rate of ``raw``, Hz.
    lowpass_hz : float
        Corner of the zero-phase Butterworth low-pass, Hz.
    order : int
        Butterworth order (applied forwards and backwards).

    Returns
    -------
    env : ndarray, same shape as ``raw``
    """
    from scipy import signal  # (lazily: scipy.signal is a slow import; benchmarks/import_time.py)

    return _lowpass(np.abs(signal.hilbert(raw, axis=-2)), rate_hz, lowpass_hz, order)


def extract_magnitude_envelope(raw, rate_hz, lowpass_hz=0.5, order=4):
    r"""Envelope of the magnitude of three-axis raw channels, ``lowpass(sqrt(sum_i |hilbert(x_i)|^2))``.

    For channels sharing one carrier, :math:`x_i = A_i \cos(2\pi f_s t + \varphi)`, the analytic
    signals are :math:`A_i e^{i(2\pi f_s t + \varphi)}` and the root sum of their squared magnitudes is
    :math:`|A|`: the envelope of :math:`|E(t)|` (an electrode ``magnitude`` reading).

    Parameters
    ----------
    raw : ndarray, shape (..., n_samples, n_sensors, 3)
    rate_hz, lowpass_hz, order : as :func:`extract_envelope`

    Returns
    -------
    env : ndarray, shape (..., n_samples, n_sensors)
    """
    from scipy import signal

    analytic = np.abs(signal.hilbert(raw, axis=-3))
    return _lowpass(np.sqrt(np.sum(analytic * analytic, axis=-1)), rate_hz, lowpass_hz, order)


def _lowpass(x, rate_hz, lowpass_hz, order):
    """Zero-phase Butterworth low-pass along axis -2."""
    if not 0 < lowpass_hz < rate_hz / 2:
        raise ValueError(f"lowpass_hz must be in (0, rate_hz/2) = (0, {rate_hz / 2:g}), got {lowpass_hz!r}")
    from scipy import signal

    sos = signal.butter(order, lowpass_hz, btype="low", fs=rate_hz, output="sos")
    return signal.sosfiltfilt(sos, x, axis=-2)


def decimate_to(env, raw_times, out_times):
    """Samples of ``env`` (..., n_raw, c) at ``out_times`` (nearest raw sample)."""
    raw_times = np.asarray(raw_times)
    idx = np.clip(np.searchsorted(raw_times, np.asarray(out_times) - 0.5 * (raw_times[1] - raw_times[0])),
                  0, raw_times.size - 1)
    return np.take(env, idx, axis=-2)


def envelope_chain(raw, raw_times, out_times, rate_hz, lowpass_hz=0.5):
    """Full chain: analytic-signal magnitude, low-pass, decimation to ``out_times``."""
    return decimate_to(extract_envelope(raw, rate_hz, lowpass_hz), raw_times, out_times)


def magnitude_envelope_chain(raw, raw_times, out_times, rate_hz, lowpass_hz=0.5):
    """Full chain of magnitude sensors: raw (..., n_raw, S, 3) -> envelopes of ``|E|`` (..., len(out_times), S)."""
    return decimate_to(extract_magnitude_envelope(raw, rate_hz, lowpass_hz), raw_times, out_times)
