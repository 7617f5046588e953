"""Typed, validated scenario configuration (pydantic v2, loaded from TOML).

A scenario file describes an array of seabed sensors, the medium, a nominal ship passage, optionally a prior
over random passages, the noise model, the signal chains and the tracker.  Everything is checked once, here;
the physics kernels below trust their inputs.  A bad file raises :class:`ScenarioError` with one message that
names the field and the reason.

Units are SI throughout (m, s, T, V/m, A·m², A·m, S/m, rad) except where a field name ends in ``_deg`` or
``_hz``.

:mod:`~shipsense.config.fields` (the value types and their messages), :mod:`~shipsense.config.tracker` (the
``[tracker]`` table), :mod:`~shipsense.config.traffic` (the ``[traffic]`` table: several ships),
:mod:`~shipsense.config.scenario` (the scenario and its TOML form) and :mod:`~shipsense.config.load` (shipped
names and files).
"""

from shipsense.config.fields import ScenarioError, format_error
from shipsense.config.load import load_scenario, shipped_scenarios
from shipsense.config.manoeuvres import ManoeuvreConfig, RandomManoeuvreConfig, SpeedChangeConfig, TurnConfig
from shipsense.config.scenario import (
    MIN_SENSOR_SPACING,
    MIN_SOURCE_DISTANCE,
    EarthConfig,
    EnvelopeChainConfig,
    MediumConfig,
    NoiseConfig,
    PassageConfig,
    PriorConfig,
    Scenario,
    SeismicConfig,
    SensorConfig,
    to_toml,
    validate_scenario,
)
from shipsense.config.tracker import (
    FILTERS,
    BankConfig,
    MotionConfig,
    ProcessNoiseConfig,
    TrackerConfig,
    TrackerOptions,
)
from shipsense.config.traffic import MAX_SHIPS, TrafficConfig

__all__ = ["FILTERS", "MAX_SHIPS", "MIN_SENSOR_SPACING", "MIN_SOURCE_DISTANCE", "BankConfig", "EarthConfig",
           "EnvelopeChainConfig", "ManoeuvreConfig", "MediumConfig", "MotionConfig", "NoiseConfig", "PassageConfig",
           "PriorConfig", "ProcessNoiseConfig", "RandomManoeuvreConfig", "Scenario", "ScenarioError", "SeismicConfig",
           "SensorConfig", "SpeedChangeConfig", "TrackerConfig", "TrackerOptions", "TrafficConfig", "TurnConfig",
           "format_error", "load_scenario", "shipped_scenarios", "to_toml", "validate_scenario"]
