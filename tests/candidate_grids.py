"""Square candidate grids around S1-P2's array with passages from its prior: the small design problems the design
tests share."""

from shipsense import load_scenario
from shipsense.design import placement as pl
from shipsense.models.field_model import candidate_model
from shipsense.simulator import sample_passages


def s1p2_grid(half, spacing, passages=4, seed=3):
    """S1-P2's scenario, candidates on a grid of ``spacing`` m over the square of half-side ``half`` m at
    z = -15 m, their candidate model and ``passages`` prior passages in its internal units."""
    sc = load_scenario("S1-P2")
    cands = pl.grid_candidates([(-half, -half), (half, -half), (half, half), (-half, half)], spacing, -15.0)
    model = candidate_model(sc, cands)
    thetas = model.to_internal(model.state_from_truth(sample_passages(sc, passages, seed=seed)))
    return sc, cands, model, thetas
