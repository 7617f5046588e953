"""The bank: equivalence with the driver, selection, fusion, pruning, divergence, ambiguity."""

import numpy as np
import pytest

from shipsense import load_scenario, simulate
from shipsense.models.field_model import model_from_scenario
from shipsense.trackers.bank.bank import run_bank
from shipsense.trackers.bank.seeding import seed_hypotheses
from shipsense.trackers.filters.run import run_filter

MAG = [0, 1, 2, 3, 5, 6, 7]
ELEC = [0, 1, 2, 3, 4, 8]


@pytest.fixture(scope="module")
def s2_bank():
    sc = load_scenario("S2")
    model = model_from_scenario(sc, sensors=["M1", "M2"])
    sim = simulate(sc, runs=4, seed=2)
    y = sim.measurements[..., ~sim.array.axial]
    truth = sim.truth[..., MAG]
    seeds = np.repeat(truth[:, None, 0], 6, axis=1).copy()
    offsets = np.array([[3, -3], [60, 40], [-50, 10], [5, 5], [-80, -80], [0, 30]], dtype=float)
    seeds[..., :2] += offsets
    seeds[..., 4:] = 0.0
    P0 = np.diag([100.0, 100.0, 2.0, 2.0, 1e8, 1e8, 1e8])
    return sc, model, y, truth, seeds, P0


def test_bank_equals_the_driver_per_hypothesis(s2_bank):
    _, model, y, _, seeds, P0 = s2_bank
    bank = run_bank("ukf", model, y, seeds, P0)
    ref = run_filter("ukf", model, y[:, None], seeds, P0)
    np.testing.assert_allclose(bank.means, ref.means, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(bank.loglik, ref.loglik, rtol=1e-12)
    np.testing.assert_allclose(bank.cum_loglik, np.cumsum(ref.loglik, axis=-1), rtol=1e-12)


def test_selection_and_fusion(s2_bank):
    _, model, y, truth, seeds, P0 = s2_bank
    bank = run_bank("ukf", model, y, seeds, P0)
    np.testing.assert_array_equal(bank.selected, np.argmax(bank.cum_loglik, axis=1))
    w = bank.weights
    np.testing.assert_allclose(w.sum(axis=1), 1.0)
    np.testing.assert_allclose(bank.fused_means, np.einsum("rhk,rhkn->rkn", w, bank.means), atol=1e-9)
    # the hypotheses seeded near the truth win and track it
    err = np.hypot(*(bank.selected_means[:, -1, :2] - truth[:, -1, :2]).T)
    assert np.all(err < 2.0), err
    # the fused covariance is at least the selected hypothesis' weighted spread (PSD)
    assert np.all(np.linalg.eigvalsh(bank.fused_pos_cov[:, -1]) > 0)


def test_pruning_frees_hypotheses_without_changing_the_survivors(s2_bank):
    _, model, y, _, seeds, P0 = s2_bank
    full = run_bank("ukf", model, y, seeds, P0)
    pruned = run_bank("ukf", model, y, seeds, P0, prune_nats=50.0)
    assert (~pruned.active[:, :, -1]).sum() > 0
    alive = pruned.active
    # equal to rounding: the linear-algebra path is chosen by batch size, and pruning shrinks the batch
    np.testing.assert_allclose(pruned.means[alive], full.means[alive], rtol=1e-10, atol=1e-9)
    assert np.isnan(pruned.means[~alive]).all()
    np.testing.assert_array_equal(pruned.selected[:, -1], full.selected[:, -1])
    assert np.all(pruned.cum_loglik[~alive] == -np.inf)
    np.testing.assert_array_equal(pruned.final_loglik, pruned.cum_loglik[:, :, -1])      # -inf once pruned


@pytest.mark.parametrize("prune_nats", [None, 50.0])
def test_a_lean_record_keeps_positions_likelihoods_and_the_selected_track_of_the_full_one(s2_bank, prune_nats):
    """``store``: the selected track chosen as the bank runs equals the one chosen afterwards from the full record
    (also with pruning, where the batch shrinks under the record's indices)."""
    _, model, y, _, seeds, P0 = s2_bank
    full = run_bank("ukf", model, y, seeds, P0, prune_nats=prune_nats)
    lean = run_bank("ukf", model, y, seeds, P0, prune_nats=prune_nats, store=("positions", "loglik", "selected"))
    assert lean.means is None and lean.pos_cov is None and lean.nis is None
    np.testing.assert_array_equal(lean.positions, full.positions)
    np.testing.assert_array_equal(lean.cum_loglik, full.cum_loglik)
    np.testing.assert_array_equal(lean.selected_means, full.selected_means)
    only = run_bank("ukf", model, y, seeds, P0, prune_nats=prune_nats, store="selected")
    np.testing.assert_array_equal(only.selected_means, full.selected_means)
    np.testing.assert_array_equal(only.selected, full.selected)          # the selection made as the bank ran
    cov = run_bank("ukf", model, y, seeds, P0, prune_nats=prune_nats, store=("pos_cov", "selected"))
    np.testing.assert_array_equal(cov.selected_pos_cov, full.selected_pos_cov)    # one choice for mean and cov
    np.testing.assert_array_equal(cov.selected_means, full.selected_means)
    with pytest.raises(ValueError, match="store: unknown 'mean'; choose from means, pos_cov"):
        run_bank("ukf", model, y, seeds, P0, store=("mean",))
    with pytest.raises(ValueError, match="did not keep 'loglik': run_bank"):
        _ = only.cum_loglik


def test_divergence_flags_the_far_hypotheses(s2_bank):
    _, model, y, _, seeds, P0 = s2_bank
    bank = run_bank("ukf", model, y, seeds, P0)
    ever = bank.diverged(window=10).any(axis=-1)          # flagged at some step of the passage
    assert not ever[np.arange(4), bank.selected[:, -1]].any()
    assert ever[:, [1, 4]].all()                           # the seeds 72 m and 113 m off
    assert not ever[:, [0, 3]].any()                       # the seeds 4 m and 7 m off


@pytest.mark.parametrize("name, ambiguous", [("S1-P1", True), ("S1-P2", False)])
def test_collinear_array_reports_mirror_ambiguity_and_triangle_does_not(name, ambiguous):
    sc = load_scenario(name)
    model = model_from_scenario(sc)
    sim = simulate(sc, runs=4, seed=1)
    seeds, P0 = seed_hypotheses(model, sim.measurements[:, 0], sc.tracker.bank)
    bank = run_bank("ukf", model, sim.measurements, seeds, P0)
    amb = bank.ambiguities(nats=sc.tracker.bank.ambiguity_nats, distance=sc.tracker.bank.ambiguity_distance)
    assert all(bool(a) == ambiguous for a in amb), amb
    if ambiguous:   # the pair are mirror images across the sensor line x = 0
        i, j, _, _ = amb[0][0]
        a, b = bank.means[0, i, -1, :2], bank.means[0, j, -1, :2]
        assert abs(a[0] + b[0]) < 2.0 and abs(a[1] - b[1]) < 2.0
    else:
        truth = sim.truth[..., ELEC]
        err = np.hypot(*(bank.selected_means[:, -1, :2] - truth[:, -1, :2]).T)
        assert np.all(err < 5.0), err


def test_selected_mean_square_error_adds_the_weighted_spread_of_the_other_hypotheses():
    from shipsense.trackers.bank.bank import BankRun

    means = np.zeros((1, 3, 1, 4))
    means[0, 1, 0, :2] = [3.0, 4.0]
    means[0, 2, 0, :2] = [100.0, 0.0]
    pos_cov = np.broadcast_to(np.eye(2), (1, 3, 1, 2, 2)).copy()
    ll = np.log([[0.75, 0.25, 1.0]])                                     # hypothesis 2 starts at -inf below
    init = np.array([[0.0, 0.0, -np.inf]])
    run = BankRun(means[:, :, 0], means, pos_cov, ll[..., None], np.zeros((1, 3, 1)), np.ones((1, 3, 1), int),
                  np.ones((1, 3, 1), bool), np.ones((1, 3, 1), bool), ("x", "y", "vx", "vy"), init)
    assert run.selected[0, 0] == 0
    spread = 0.25 * np.outer([3.0, 4.0], [3.0, 4.0])
    np.testing.assert_allclose(run.selected_pos_mse[0, 0], np.eye(2) + spread, rtol=1e-12)
    # one hypothesis with all the weight: its own covariance
    one = BankRun(means[:, :1, 0], means[:, :1], pos_cov[:, :1], ll[:, :1, None], np.zeros((1, 1, 1)),
                  np.ones((1, 1, 1), int), np.ones((1, 1, 1), bool), np.ones((1, 1, 1), bool), ("x", "y", "vx", "vy"))
    np.testing.assert_array_equal(one.selected_pos_mse, one.selected_pos_cov)


def test_the_kept_selection_is_the_maximum_of_cum_loglik_at_near_ties_of_the_prior_likelihoods():
    """Two identical hypotheses whose prior log-likelihoods differ by one ulp: the bank's running sums and
    ``cum_loglik`` sum in the same order, so the selection kept as the bank ran is ``cum_loglik``'s maximum
    at every step (summed as ``cumsum + initial`` instead, they disagreed at about 1 % of the steps)."""
    sc = load_scenario("S0")
    model = model_from_scenario(sc)
    sim = simulate(sc, runs=1, seed=4)
    seeds, P0 = seed_hypotheses(model, sim.measurements[:, 0], sc.tracker.bank)
    R = 120
    y = np.repeat(sim.measurements[:, :40], R, axis=0)
    twins = np.repeat(np.repeat(seeds[:, :1], 2, axis=1), R, axis=0)
    a = np.random.default_rng(0).uniform(-50.0, 50.0, R)
    init = np.stack([a, np.nextafter(a, np.inf)], axis=1)
    b = run_bank("ukf", model, y, twins, P0, initial_loglik=init, store=("loglik", "selected"))
    np.testing.assert_array_equal(b.selected, np.argmax(b.cum_loglik, axis=1))
    np.testing.assert_array_equal(b.cum_loglik[:, :, 0], init + b.loglik[:, :, 0])
    np.testing.assert_array_equal(b.final_loglik, b.cum_loglik[:, :, -1])
