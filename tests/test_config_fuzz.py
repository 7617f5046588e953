"""Fuzzing the scenario schema: every mutation of a shipped scenario's values either loads or fails with one
ScenarioError naming the file and the field -- never another exception, never a silent coercion."""

import math
import tomllib

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from shipsense.config import ScenarioError, validate_scenario
from shipsense.config.load import _shipped_dir

BASES = {name: tomllib.loads((_shipped_dir() / f"{name}.toml").read_text()) for name in ("S2", "S1-P2", "demo")}


def _leaves(node, path=()):
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _leaves(v, (*path, k))
    elif isinstance(node, list) and node and isinstance(node[0], dict):
        for i, v in enumerate(node):
            yield from _leaves(v, (*path, i))
    else:
        yield path


LEAVES = [(name, path) for name, data in BASES.items() for path in _leaves(data)]
BAD = st.one_of(
    st.sampled_from(["0.5", "", "nan", "1e3", True, False, [], {}, [1.0], [[1.0, 2.0]], {"x": 1}]),
    st.sampled_from([math.nan, math.inf, -math.inf, 1e308, -1e308, 1e-308, 0, -1, 2**63, -(2**63), 0.0, -0.0]),
    st.integers(min_value=-(2**70), max_value=2**70), st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=30))


def _set(data, path, value):
    import copy

    data = copy.deepcopy(data)
    node = data
    for k in path[:-1]:
        node = node[k]
    node[path[-1]] = value
    return data


@settings(derandomize=True, max_examples=1000, deadline=2000, suppress_health_check=[HealthCheck.too_slow])
@given(leaf=st.sampled_from(LEAVES), value=BAD)
def test_a_mutated_scenario_loads_or_names_the_field(leaf, value):
    name, path = leaf
    try:
        validate_scenario(_set(BASES[name], path, value), "fuzz.toml", strict=True)
    except ScenarioError as err:
        msg = str(err)
        assert msg.startswith("fuzz.toml: ") and "\n" not in msg
        assert "function-after" not in msg and "Input should" not in msg, msg   # the project's words
        # the message names the mutated field, or the table it belongs to (a cross-field check)
        keys = [p for p in path if isinstance(p, str)]
        assert any(k in msg for k in keys), (path, msg)


@pytest.mark.parametrize("path,value,words", [
    (("period",), "0.5", "expected a number, got str"), (("steps",), 80.0, "expected a whole number"),
    (("steps",), True, "expected a whole number, got bool"), (("period",), 1e308, "at most 3600 s"),
    (("runs",), 10**9, "runs"), (("passage", "velocity"), [1e5, 0.0], "at most 100 m/s"),
    (("medium", "sigma_water"), -4.0, "sigma_water"), (("passage", "p"), math.nan, "passage.p"),
])
def test_the_messages_name_the_field_and_the_range(path, value, words):
    with pytest.raises(ScenarioError, match=words):
        validate_scenario(_set(BASES["S1-P2"], path, value), "bad.toml", strict=True)
