"""Envelope chain: the analytic-signal envelope recovers the amplitude."""

import numpy as np

from shipsense.physics.envelope import envelope_chain, magnitude_envelope_chain, raw_channels


def test_recovers_constant_amplitude_within_2_percent_at_20_db():
    rng = np.random.default_rng(0)
    rate = 100.0
    t = np.arange(0, 120, 1 / rate)
    A = np.array([3e-6, -1e-6, 5e-7])
    amp = np.broadcast_to(A, (8, t.size, 3))  # 8 runs
    noise = np.abs(A) / np.sqrt(2) / 10  # signal power A^2/2 over noise power: 100 (20 dB)
    raw = raw_channels(amp, t, shaft_hz=3.0, phase=rng.uniform(0, 6, (8, 1, 1)), noise_std=noise, rng=rng)
    out_t = np.arange(10, 110, 0.4)
    env = envelope_chain(raw, t, out_t, rate, lowpass_hz=0.5)
    rel = (env - np.abs(A)) / np.abs(A)
    # RMS error within 2 % and bias within 0.5 % (single samples reach ~3 %: the residual
    # noise of a 0.5 Hz band at 20 dB is about 1 % rms per sample)
    assert np.sqrt(np.mean(rel**2)) < 0.02, np.sqrt(np.mean(rel**2))
    assert abs(rel.mean()) < 0.005, rel.mean()


def test_tracks_a_slow_amplitude_and_loses_a_fast_one():
    rate = 100.0
    t = np.arange(0, 200, 1 / rate)
    slow = (2 + np.sin(2 * np.pi * 0.02 * t))[:, None]   # 0.02 Hz: inside the 0.5 Hz pass band
    fast = (2 + np.sin(2 * np.pi * 2.0 * t))[:, None]    # 2 Hz: removed by the low-pass
    out_t = np.arange(20, 180, 0.5)
    env_slow = envelope_chain(raw_channels(slow, t, 5.0), t, out_t, rate)
    env_fast = envelope_chain(raw_channels(fast, t, 5.0), t, out_t, rate)
    truth = 2 + np.sin(2 * np.pi * 0.02 * out_t)
    assert np.abs(env_slow[:, 0] - truth).max() < 0.01
    assert np.abs(env_fast[:, 0] - 2.0).max() < 0.05


def test_magnitude_chain_recovers_the_length_of_the_amplitude_vector():
    """Three channels sharing a carrier: the envelope of |E(t)| is |A|, a slowly turning amplitude included
    (its components change sign; |A| does not)."""
    rate = 100.0
    t = np.arange(0, 200, 1 / rate)
    ang = 2 * np.pi * 0.01 * t
    A = np.stack([3 * np.cos(ang), 3 * np.sin(ang), np.full_like(t, 4.0)], -1)    # |A| = 5 throughout
    raw = raw_channels(A, t, 5.0, phase=0.7).reshape(t.size, 1, 3)
    out_t = np.arange(20, 180, 0.5)
    env = magnitude_envelope_chain(raw, t, out_t, rate)
    assert env.shape == (out_t.size, 1)
    assert np.abs(env[:, 0] - 5.0).max() < 0.01
    per_channel = envelope_chain(raw[:, 0], t, out_t, rate)
    np.testing.assert_allclose(env[:, 0], np.linalg.norm(per_channel, axis=-1), rtol=0.02)
