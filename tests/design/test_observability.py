"""Observability and ambiguity verdicts follow the measurement model."""

import numpy as np
import pytest

from shipsense import load_scenario
from shipsense.design.observability import (
    MIRROR_REFINE,
    ambiguity_search,
    check_scenario,
    discrepancy,
    mirror,
    mirror_lines,
)
from shipsense.models.field_model import model_from_scenario


def test_collinear_envelope_array_is_ambiguous_with_mirror_pairs():
    v = check_scenario("S1-P1", passages=2)
    assert v.verdict == "ambiguous" and v.min_chi2 < 1e-6 and v.fim_rank == 6   # full rank, yet ambiguous
    for p in v.pairs:   # the alternative is the mirror image across the sensor line x = 0
        assert p.alternative[0] == pytest.approx(-p.passage[0], abs=1e-6)
        assert p.alternative[1] == pytest.approx(p.passage[1], abs=1e-6)


def test_triangle_envelope_array_is_observable():
    v = check_scenario("S1-P2", passages=2)
    assert v.verdict == "observable" and v.min_chi2 > 25 and not v.pairs


@pytest.mark.parametrize("kind, verdict", [("vector", "observable"), ("magnitude", "ambiguous")])
def test_magnetometers_on_a_line_depend_on_the_measurement_kind(kind, verdict):
    sc = load_scenario("S2-field-trial")
    mags = [s.model_copy(update={"kind": kind}) for s in sc.sensors if s.type == "magnetometer"]
    assert len(mags) == 3 and len({s.position[1] for s in mags}) == 1   # three on the line y = 0
    v = check_scenario(sc.model_copy(update={"sensors": mags}), passages=2)
    assert v.verdict == verdict, (v.verdict, v.min_chi2)


@pytest.mark.parametrize("kind, verdict", [("vector", "observable"), ("magnitude", "ambiguous")])
def test_electrodes_on_a_line_depend_on_the_measurement_kind(kind, verdict):
    """|E| is unchanged by the mirror across the sensor line (x = 0), the signed field is not (E_x flips)."""
    sc = load_scenario("S1-P1")
    assert {s.position[0] for s in sc.sensors} == {0.0}
    sensors = [s.model_copy(update={"kind": kind}) for s in sc.sensors]
    v = check_scenario(sc.model_copy(update={"sensors": sensors}), passages=2)
    assert v.verdict == verdict, (v.verdict, v.min_chi2)
    if kind == "magnitude":
        assert v.min_chi2 < 1e-6 and v.fim_rank == 6
        for p in v.pairs:
            assert p.alternative[0] == pytest.approx(-p.passage[0], abs=1e-6)
    else:
        assert v.min_chi2 > 25 and not v.pairs


def test_mirror_transform_is_exact_for_envelopes_and_axial_for_moments():
    model = model_from_scenario("S1-P1")
    theta = model.to_internal(np.array([-150.0, -80.0, 8.0, 4.0, -6.8, 100.0]))
    alt = mirror(model, theta, [0.0, 0.0], [0.0, 1.0])
    assert discrepancy(model, theta, alt, 101) < 1e-12 * discrepancy(model, theta, theta * 1.01, 101)
    mag = model_from_scenario("S0")
    th = np.array([-140.0, -70.0, 6.0, 6.0, 80.0, 20.0, 40.0])
    m = mirror(mag, th, [0.0, 0.0], [1.0, 0.0])       # across y = 0: (x, -y), m -> (-mx, my, -mz)
    np.testing.assert_allclose(m[:4], [-140.0, 70.0, 6.0, -6.0])
    np.testing.assert_allclose(m[4:], [-80.0, 20.0, -40.0])


def test_mirror_lines_are_each_line_once():
    """S1-P1's three sensors share the line x = 0: as the pair line of each pair and as each sensor's 90 degree
    line it is one line; each sensor's other five angles are lines of their own (16 in all)."""
    model = model_from_scenario("S1-P1")
    lines = mirror_lines(model)
    assert len(lines) == 16
    theta = model.to_internal(np.array([-150.0, -80.0, 8.0, 4.0, -6.8, 100.0]))
    kept = np.stack([mirror(model, theta, c, d) for c, d in lines])
    pos = model.array.positions[:, :2]
    every = [(pos[i], pos[j] - pos[i]) for i in range(3) for j in range(i + 1, 3)]
    every += [(p, [np.cos(a), np.sin(a)]) for p in pos for a in np.arange(6) * np.pi / 6]
    for c, d in every:   # the candidate of every line, duplicates included, is among the kept ones
        m = mirror(model, theta, c, d)
        assert np.min(np.abs(kept - m).max(axis=-1)) < 1e-9


def test_a_large_line_array_keeps_its_exact_mirror_among_the_refined_candidates():
    """Eight magnitude electrodes on x = 0 have more mirror lines than are refined; the line they share is the
    closest mirror as it stands (discrepancy 0), so the search still returns it."""
    sc = load_scenario("S1-P1")
    template = sc.sensors[0].model_copy(update={"kind": "magnitude"})
    sensors = [template.model_copy(update={"id": f"E{i}", "position": (0.0, 10.0 * i - 35.0, -15.0)})
               for i in range(8)]
    model = model_from_scenario(sc.model_copy(update={"sensors": sensors}))
    assert len(mirror_lines(model)) > MIRROR_REFINE
    theta = model.to_internal(np.array([-150.0, -80.0, 8.0, 4.0, -6.8, 100.0]))
    found = ambiguity_search(model, theta, sc.steps, starts=0)
    alt, chi2, _, source = found[0]
    assert source == "mirror" and chi2 < 1e-9
    assert alt[0] == pytest.approx(150.0, abs=1e-6) and alt[1] == pytest.approx(-80.0, abs=1e-6)
