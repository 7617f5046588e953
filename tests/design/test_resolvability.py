"""Two-ship resolvability: the joint Fisher information's limits and an independent finite-difference reference."""

import numpy as np
import pytest
from candidate_grids import s1p2_grid

from shipsense.design.fisher import passage_fim
from shipsense.design.resolvability import (
    SEPARATIONS_M,
    abreast,
    first_resolved,
    joint_fim,
    resolvable_separation,
    resolved,
    scenario_resolvability,
    separation_sd,
    share_statistic,
)
from shipsense.models.field_model import candidate_model, model_from_scenario, subset_model
from shipsense.models.transitions import powers
from shipsense.simulator import sample_passages


def _draws(name, passages=4, seed=0):
    model = model_from_scenario(name)
    truth = sample_passages(name, passages, seed=seed)
    return model, model.to_internal(model.state_from_truth(truth))


def test_joint_fim_matches_dense_finite_differences_of_the_summed_field():
    """A tiny case (two vector magnetometers, 6 samples): the joint information against central differences of
    the whitened superposed readings over the stacked state -- an independent Jacobian."""
    model = model_from_scenario("S2", sensors=["M1", "M2"])
    steps = 6
    th1 = model.to_internal(np.array([12.0, 9.0, -3.0, -2.0, 1e4, -5e3, 8e3]))
    th2 = model.to_internal(np.array([-7.0, 14.0, 2.0, -3.5, -6e3, 1.2e4, 4e3]))
    Ak = powers(model.A, steps)

    def readings(stacked):
        t1, t2 = stacked[:model.n], stacked[model.n:]
        y = model.h(np.einsum("kij,j->ki", Ak, t1)) + model.h(np.einsum("kij,j->ki", Ak, t2))
        return (y / np.sqrt(model.R)).ravel()

    x = np.concatenate([th1, th2])
    G = np.empty((steps * model.m, 2 * model.n))
    for i in range(2 * model.n):
        h = 1e-6 * max(1.0, abs(x[i]))
        e = np.zeros_like(x)
        e[i] = h
        G[:, i] = (readings(x + e) - readings(x - e)) / (2 * h)
    np.testing.assert_allclose(joint_fim(model, th1, th2, steps), G.T @ G, rtol=1e-5, atol=1e-6)


def test_diagonal_blocks_are_the_one_ship_fims_and_per_sensor_parts_add_up():
    model, thetas = _draws("S1-P2", 2)
    t1, t2 = abreast(model, thetas, [15.0])
    J = joint_fim(model, t1, t2, 101)
    n = model.n
    np.testing.assert_allclose(J[..., :n, :n], passage_fim(model, t1, 101), rtol=1e-10)
    np.testing.assert_allclose(J[..., n:, n:], passage_fim(model, t2, 101), rtol=1e-10)
    np.testing.assert_allclose(J, J.swapaxes(-1, -2), rtol=1e-12)
    per = joint_fim(model, t1, t2, 101, per_sensor=True)
    assert per.shape == (2, 1, 3, 2 * n, 2 * n)
    np.testing.assert_allclose(per.sum(axis=-3), J, rtol=1e-10)


def test_cross_terms_vanish_as_the_ships_fields_stop_overlapping():
    """Two magnetometers 2L apart, one ship passing over each: the normalised cross block
    ``D1^-1/2 J12 D2^-1/2`` shrinks towards 0 as L grows (the block-diagonal limit), while the one-ship
    blocks stay what they are."""
    steps, coupling = 41, []
    for L in (5.0, 50.0, 500.0, 5000.0):
        model = candidate_model("S2", [[-L, 0.0, -2.0], [L, 0.0, -2.0]])
        th1 = model.to_internal(np.array([-L, -40.0, 0.0, 2.0, 1e4, 1e4, 1e4]))
        th2 = model.to_internal(np.array([L, -40.0, 0.0, 2.0, 1e4, 1e4, 1e4]))
        J = joint_fim(model, th1, th2, steps)
        n = model.n
        d = np.sqrt(np.diag(J))
        coupling.append(np.abs(J[:n, n:] / np.outer(d[:n], d[n:])).max())
    assert all(b < a for a, b in zip(coupling, coupling[1:])), coupling
    assert coupling[-1] < 1e-6 < coupling[0]


def test_coincident_ships_make_the_joint_fim_singular_and_are_not_resolved():
    model, thetas = _draws("S2", 3)
    t1, t2 = abreast(model, thetas, [0.0])
    J = joint_fim(model, t1, t2, model.n * 10)
    w = np.linalg.eigvalsh(J)
    assert np.all(w[..., 0] <= 1e-9 * w[..., -1])                    # the ship-exchange direction is not seen
    assert np.all(np.isinf(separation_sd(model, J, t1, t2, model.n * 10)))
    ok = resolved(model, thetas, 80, np.array([0.0, 5.0, 20.0]))
    assert not ok[:, 0].any()
    assert np.all(first_resolved(ok, [0.0, 5.0, 20.0]) > 0)


def test_separation_sd_against_a_direct_inverse():
    """Where J is well conditioned, the bound is min_k g_k^T J^-1 g_k with the plain inverse."""
    model, thetas = _draws("S1-P2", 2, seed=3)
    steps = 101
    t1, t2 = abreast(model, thetas, [25.0])
    J = joint_fim(model, t1, t2, steps)
    Ak = powers(model.A, steps)
    ref = np.empty(2)
    for p in range(2):
        C = np.linalg.inv(J[p, 0])
        u = (t1[p, 0, :2] - t2[p, 0, :2]) / 25.0                     # parallel abreast ships: constant
        g = np.concatenate([u @ Ak[:, :2], -(u @ Ak[:, :2])], axis=-1)   # (K, 2n)
        ref[p] = np.sqrt(np.einsum("ki,ij,kj->k", g, C, g).min())
    np.testing.assert_allclose(separation_sd(model, J, t1, t2, steps)[:, 0], ref, rtol=1e-6)


@pytest.mark.parametrize("name, steps, subsets", [("S2-field-trial", 80, ([0, 1], [1, 2, 4], [0])),
                                                   ("S1-P2", 101, ([0, 1], [2]))])
def test_a_denser_array_never_resolves_worse_than_its_subset(name, steps, subsets):
    """More sensors add information at every separation (the joint FIM grows in the Loewner order), so each
    draw's resolvable separation, and the array's, is never larger than a subset's."""
    model, thetas = _draws(name, 4, seed=1)
    whole = resolvable_separation(model, thetas, steps, share=1.0)
    assert np.isfinite(whole.per_draw_m).any()
    for keep in subsets:
        part = subset_model(model, keep)
        assert part.n == model.n
        sub = resolvable_separation(part, thetas, steps, share=1.0)
        assert np.all(whole.per_draw_m <= sub.per_draw_m), (keep, whole.per_draw_m, sub.per_draw_m)
        assert whole.separation_m <= sub.separation_m
    # and strictly better somewhere: the figure depends on the layout
    assert np.any(whole.per_draw_m < resolvable_separation(subset_model(model, [0]), thetas, steps).per_draw_m)


def test_bearing_channels_do_not_enter_the_joint_information():
    """Seismic bearings do not superpose: S2's joint information is that of its two magnetometers alone."""
    model, thetas = _draws("S2", 2)
    mags = subset_model(model, [0, 1])
    assert model.axial.any() and not mags.axial.any()
    t1, t2 = abreast(model, thetas, [10.0])
    np.testing.assert_allclose(joint_fim(model, t1, t2, 80), joint_fim(mags, t1, t2, 80), rtol=1e-12)


def test_share_statistic_is_the_order_statistic():
    per = np.array([3.0, 1.0, np.inf, 2.0])
    assert share_statistic(per, 0.5) == 2.0
    assert share_statistic(per, 0.75) == 3.0
    assert share_statistic(per, 0.76) == np.inf
    assert share_statistic(per, 1e-9) == 1.0


def test_scenario_figure_is_reproducible_and_on_the_grid():
    a = scenario_resolvability("S2", passages=3, seed=2)
    b = scenario_resolvability("S2", passages=3, seed=2)
    np.testing.assert_array_equal(a.per_draw_m, b.per_draw_m)
    assert a.separation_m in SEPARATIONS_M and a.separation_m == a.per_draw_m.max()
    assert a.to_json()["separation_m"] == a.separation_m


# -- design -------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def grid():
    return s1p2_grid(30.0, 20.0)    # 4 x 4


def test_set_values_are_the_resolvability_of_the_set_and_grow_with_sensors(grid):
    from itertools import combinations

    from shipsense.design.resolvability import candidate_information, set_values

    sc, cands, model, thetas = grid
    d0 = 5.0
    info = candidate_information(model, thetas, sc.steps, d0)
    pairs = np.array(list(combinations(range(len(cands)), 2)))
    v2 = set_values(model, info, sc.steps, pairs, d0)
    # a set's value is the share statistic of the ratios its own model gives (the subset's joint information)
    for i in (0, 7, 50):
        part = subset_model(model, pairs[i])
        t1, t2 = abreast(part, thetas, [d0])
        sd = separation_sd(part, joint_fim(part, t1, t2, sc.steps, stride=2), t1, t2, sc.steps, stride=2)[:, 0]
        assert v2[i] == pytest.approx(-np.log(share_statistic(sd / d0)), rel=1e-6)
    # adding a third sensor to a pair never lowers the value
    third = np.array([[*p, j] for p in pairs[:40] for j in range(len(cands)) if j not in p])
    v3 = set_values(model, info, sc.steps, third, d0)
    base = dict(zip(map(tuple, pairs[:40]), v2[:40]))
    assert np.all(v3 >= np.array([base[tuple(t[:2])] for t in third]) - 1e-9)


def test_the_search_is_exhaustive_when_it_can_be_and_exchanges_otherwise(grid):
    from itertools import combinations

    from shipsense.design.resolvability import best_set, candidate_information, set_values

    sc, cands, model, thetas = grid
    info = candidate_information(model, thetas, sc.steps, 10.0)

    def values(sets):
        return set_values(model, info, sc.steps, sets, 10.0)

    every = np.array(list(combinations(range(len(cands)), 3)))
    top = values(every).max()
    chosen, value, complete, evaluated = best_set(values, len(cands), 3)
    assert complete and evaluated == len(every) and value == top and values(chosen[None])[0] == top
    chosen, value, complete, _ = best_set(values, len(cands), 3, exhaustive=0, starts=5, seed=1)
    assert not complete and len(set(chosen)) == 3 and value <= top
    starts = np.sort(np.argsort(np.random.default_rng(1).random((5, len(cands))), axis=1)[:, :3], axis=1)
    assert value >= values(starts).max()                           # the exchanges never lose the best start


def test_design_with_the_resolvability_criterion(grid, tmp_path):
    import json

    from shipsense.design.designer import design_array, summary_lines, write_design

    sc, cands, model, thetas = grid
    res = design_array(sc, 2, criterion="resolvability", candidates=cands, passages=4, seed=3, separation=10.0,
                       random_layouts=50)
    assert res.placement.status == "optimal" and res.placement.certified_gap == 0
    assert all(b["value"] is None or b["value"] <= res.placement.value + 1e-12 for b in res.baselines.values())
    write_design(res, tmp_path / "out")
    report = json.loads((tmp_path / "out" / "design.json").read_text(), parse_constant=lambda c: 1 / 0)
    assert report["criterion"] == "resolvability" and report["separation_m"] == 10.0
    assert report["resolvability"]["separation_m"] == res.resolvability.separation_m
    assert any("told apart" in line for line in summary_lines(res))
    for kwargs, field in (({"criterion": "D", "separation": 10.0}, "--separation"),
                          ({"criterion": "resolvability", "separation": -1.0}, "--separation"),
                          ({"criterion": "resolvability", "costs": np.ones(len(cands)), "budget": 5.0}, "--budget"),
                          ({"criterion": "F"}, "--criterion")):
        with pytest.raises(ValueError, match=field):
            design_array(sc, 2, candidates=cands, passages=2, **kwargs)
