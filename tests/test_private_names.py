"""No module of the package uses another module's private names: no ``from shipsense.X import _name``, and no
``obj._name`` where ``_name`` is defined only in another module of the package (a name of a library's own, such
as numba's cache internals behind ``shipsense.numba_cache`` or a namedtuple's ``_replace``, is not the package's)."""

import ast
from pathlib import Path

import shipsense

PACKAGE = Path(shipsense.__file__).parent


def _private_definitions(tree):
    """Private names a module defines: top-level and class-level functions, classes and assignments, and the
    attributes its methods set on ``self``."""
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            for target in (node.targets if isinstance(node, ast.Assign) else [node.target]):
                for sub in ast.walk(target):
                    if isinstance(sub, ast.Name):
                        names.add(sub.id)
                    elif isinstance(sub, ast.Attribute):
                        names.add(sub.attr)
    return {n for n in names if n.startswith("_") and not n.startswith("__")}


def test_no_module_uses_another_modules_private_names():
    trees = {p.relative_to(PACKAGE).as_posix(): ast.parse(p.read_text()) for p in PACKAGE.rglob("*.py")}
    defined = {name: _private_definitions(tree) for name, tree in trees.items()}
    found = []
    for name, tree in trees.items():
        foreign = set().union(*(d for other, d in defined.items() if other != name)) - defined[name]
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("shipsense"):
                found += [(name, node.lineno, a.name) for a in node.names
                          if a.name.startswith("_") and not a.name.startswith("__")]
            elif isinstance(node, ast.Attribute) and node.attr in foreign:
                if not (isinstance(node.value, ast.Name) and node.value.id in ("self", "cls")):
                    found.append((name, node.lineno, ast.unparse(node)))
    assert not found, found
