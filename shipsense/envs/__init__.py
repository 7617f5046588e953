"""Gymnasium environments of ship passages past a sensor array (shared/spec/design.md section 4).

* ``shipsense/Passage-v0`` (:class:`~shipsense.envs.passage.PassageEnv`, native vector version
  :class:`~shipsense.envs.passage.PassageVectorEnv`): schedule which sensors to read.
* ``shipsense/ArrayDesign-v0`` (:class:`~shipsense.envs.array_design.ArrayDesignEnv`): place k sensors.

Both are registered when ``shipsense`` is imported (idempotently), so
``gymnasium.make("shipsense:shipsense/Passage-v0")`` works in a fresh process.
"""

from __future__ import annotations

PASSAGE_ID = "shipsense/Passage-v0"
DESIGN_ID = "shipsense/ArrayDesign-v0"


def register_envs() -> None:
    """Register the environments with gymnasium (a no-op when they already are)."""
    import gymnasium as gym

    if PASSAGE_ID not in gym.registry:
        gym.register(id=PASSAGE_ID, entry_point="shipsense.envs.passage:PassageEnv",
                     vector_entry_point="shipsense.envs.passage:PassageVectorEnv",
                     kwargs={"scenario": "S2"})
    if DESIGN_ID not in gym.registry:
        gym.register(id=DESIGN_ID, entry_point="shipsense.envs.array_design:ArrayDesignEnv",
                     kwargs={"scenario": "S1-P2"})


__all__ = ["DESIGN_ID", "PASSAGE_ID", "register_envs"]
