"""The environments (and the modules split off them) use no other module's private names: no ``from X import
_name``, no ``obj._name`` of another object.  The exceptions wait for public names in ``shipsense.trackers``."""

import ast
from pathlib import Path

import shipsense

PACKAGE = Path(shipsense.__file__).parent
MODULES = sorted(PACKAGE.glob("envs/*.py")) + [PACKAGE / "design/information_gain.py"]
WAITING = set()


def _private_uses(path):
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            yield from (alias.name for alias in node.names if alias.name.startswith("_"))
        elif isinstance(node, ast.Attribute) and node.attr.startswith("_") and not node.attr.startswith("__"):
            if not (isinstance(node.value, ast.Name) and node.value.id in ("self", "cls")):
                yield node.attr


def test_no_private_names_of_other_modules():
    found = {(path.relative_to(PACKAGE).as_posix(), name) for path in MODULES for name in _private_uses(path)}
    assert found <= WAITING, sorted(found - WAITING)
