"""The scripts in bench/ and experiments/ are not run by the suite (they take minutes to hours), but every name they
import from the package must exist: a renamed or moved function otherwise breaks a study only when someone reruns
it. Checked statically (the scripts' ``from inkopt... import ...`` statements, at any depth), without running them."""

import ast
import importlib

import pytest
from helpers import REPO

SCRIPTS = sorted([*(REPO / "bench").glob("*.py"), *(REPO / "experiments").glob("*.py")])


def _guarded(tree) -> set:
    """ids of the nodes inside the ImportError handlers of a ``try``: fallbacks kept on purpose (a script that
    also runs on the package's earlier layouts, e.g. bench/determinism_snapshot.py); the ``try`` body is checked."""
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Try) and any(
            h.type is not None and "ImportError" in ast.unparse(h.type) for h in node.handlers
        ):
            out |= {id(n) for h in node.handlers for n in ast.walk(h)}
    return out


def _package_imports(path):
    """(module, name, line) of every ``from inkopt[.x] import name`` in the file, outside ImportError fallbacks."""
    tree = ast.parse(path.read_text(), str(path))
    guarded = _guarded(tree)
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.ImportFrom)
            and node.level == 0
            and (node.module or "").split(".")[0] == "inkopt"
            and id(node) not in guarded
        ):
            for alias in node.names:
                yield node.module, alias.name, node.lineno


def test_scripts_are_found():
    assert len(SCRIPTS) > 10


@pytest.mark.parametrize("path", SCRIPTS, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_script_imports_exist(path):
    missing = []
    for module, name, line in _package_imports(path):
        mod = importlib.import_module(module)
        if not hasattr(mod, name):
            try:  # a submodule imported by name: ``from inkopt import render``
                importlib.import_module(f"{module}.{name}")
            except ModuleNotFoundError:
                missing.append(f"{path.name}:{line}: {module} has no {name}")
    assert not missing, "; ".join(missing)
