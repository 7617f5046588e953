"""Loading scenarios: a shipped name or a TOML path, validated once, a bad value one line naming the field."""

from __future__ import annotations

import tomllib
from importlib import resources
from pathlib import Path

from shipsense.config.fields import ScenarioError
from shipsense.config.scenario import Scenario, validate_scenario


def _shipped_dir():
    return resources.files("shipsense") / "scenarios"


def shipped_scenarios() -> dict[str, str]:
    """Names of the scenarios shipped with the package and their one-line descriptions."""
    out = {}
    for entry in sorted(_shipped_dir().iterdir(), key=lambda e: e.name):
        if entry.name.endswith(".toml"):
            desc = tomllib.loads(entry.read_text()).get("description", "").strip()
            out[entry.name[:-5]] = desc.splitlines()[0] if desc else ""
    return out


def load_scenario(name_or_path: str | Path) -> Scenario:
    """Load and validate a scenario: a shipped name (``S0``, ``S1-P2``, ...) or a TOML path.

    Raises
    ------
    ScenarioError
        With one message naming the file, the field and the reason.
    """
    if isinstance(name_or_path, Scenario):
        return name_or_path
    text = None
    path = Path(name_or_path)
    lookup = {n.lower(): n for n in shipped_scenarios()}
    if str(name_or_path).lower() in lookup and not path.is_file():
        name = lookup[str(name_or_path).lower()]
        text = (_shipped_dir() / f"{name}.toml").read_text()
        source = f"shipped scenario {name!r}"
    elif path.is_file():
        try:
            text = path.read_text()
        except (OSError, UnicodeDecodeError) as err:
            raise ScenarioError(f"{path}: cannot read the file ({err})") from None
        source = str(path)
    else:
        raise ScenarioError(f"{name_or_path}: no such file, and not a shipped scenario "
                            f"(shipped: {', '.join(shipped_scenarios())})")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ScenarioError(f"{source}: not valid TOML ({err})") from None
    return validate_scenario(data, source, strict=True)
