"""The type stub python/inkopt/_core.pyi against the compiled module: the same public names, and for every callable
the same parameters (names in order, positional or keyword-only, defaults), methods static or not, so the stub
cannot drift from the bindings in crates/py."""

import ast
import inspect

import pytest
from helpers import REPO

from inkopt import _core

STUB = REPO / "python" / "inkopt" / "_core.pyi"


def _stub() -> ast.Module:
    return ast.parse(STUB.read_text(encoding="utf-8"))


def _public(names) -> set[str]:
    return {n for n in names if not n.startswith("_") or n == "__version__"}


def _stub_params(fn: ast.FunctionDef, skip_first: bool) -> list[tuple[str, str, object]]:
    """(name, kind, default) of each parameter; kind is "pos" or "kw"; default is `inspect.Parameter.empty` or
    the literal value."""
    a = fn.args
    assert not (a.posonlyargs or a.vararg or a.kwarg), f"{fn.name}: only plain and keyword-only parameters"
    pos = a.args[1:] if skip_first else a.args
    defaults = [inspect.Parameter.empty] * (len(a.args) - len(a.defaults)) + [ast.literal_eval(d) for d in a.defaults]
    defaults = defaults[1:] if skip_first else defaults
    out = [(p.arg, "pos", d) for p, d in zip(pos, defaults)]
    kw_defaults = [inspect.Parameter.empty if d is None else ast.literal_eval(d) for d in a.kw_defaults]
    out += [(p.arg, "kw", d) for p, d in zip(a.kwonlyargs, kw_defaults)]
    return out


def _real_params(obj, skip_self: bool) -> list[tuple[str, str, object]]:
    params = list(inspect.signature(obj).parameters.values())
    if skip_self:
        assert params and params[0].name == "self", f"{obj!r}: expected self first"
        params = params[1:]
    kinds = {inspect.Parameter.POSITIONAL_OR_KEYWORD: "pos", inspect.Parameter.KEYWORD_ONLY: "kw"}
    return [(p.name, kinds.get(p.kind, str(p.kind)), p.default) for p in params]


def _same(stub, real) -> bool:
    """Parameter lists equal, defaults compared by type and value (True is not 1)."""
    key = lambda ps: [(n, k, type(d).__name__, d) for n, k, d in ps]  # noqa: E731
    return key(stub) == key(real)


def _docstring_ok(node) -> bool:
    doc = ast.get_docstring(node)
    return bool(doc) and "\n" not in doc.strip()


def test_stub_has_the_modules_public_names():
    stub = set()
    for node in _stub().body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            stub.add(node.name)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            stub.add(node.target.id)
    assert stub == _public(dir(_core))


def test_stub_functions_match_the_module():
    functions = [n for n in _stub().body if isinstance(n, ast.FunctionDef)]
    assert functions
    for fn in functions:
        assert _docstring_ok(fn), f"{fn.name}: one-line docstring"
        stub, real = _stub_params(fn, skip_first=False), _real_params(getattr(_core, fn.name), skip_self=False)
        assert _same(stub, real), f"{fn.name}: stub {stub} != module {real}"


def _decorated(fn: ast.FunctionDef, name: str) -> bool:
    return any(isinstance(d, ast.Name) and d.id == name for d in fn.decorator_list)


@pytest.mark.parametrize("cls", [n for n in _stub().body if isinstance(n, ast.ClassDef)], ids=lambda c: c.name)
def test_stub_classes_match_the_module(cls):
    real_cls = getattr(_core, cls.name)
    assert _docstring_ok(cls), f"{cls.name}: one-line docstring"
    members = {n.name: n for n in cls.body if isinstance(n, ast.FunctionDef)}
    assert _public(members) == _public(vars(real_cls)), f"{cls.name}: members differ"
    new = members.pop("__new__", None)
    if new is None:  # built by its static methods only
        with pytest.raises(TypeError, match="cannot create"):
            real_cls()
    else:
        assert _docstring_ok(new), f"{cls.name}.__new__: one-line docstring"
        stub, real = _stub_params(new, skip_first=True), _real_params(real_cls, skip_self=False)
        assert _same(stub, real), f"{cls.name}(): stub {stub} != module {real}"
    for name, fn in members.items():
        assert _docstring_ok(fn), f"{cls.name}.{name}: one-line docstring"
        attr = inspect.getattr_static(real_cls, name)
        is_property, is_static = _decorated(fn, "property"), _decorated(fn, "staticmethod")
        assert is_property == inspect.isgetsetdescriptor(attr), f"{cls.name}.{name}: property in one, not the other"
        assert is_static == isinstance(attr, staticmethod), f"{cls.name}.{name}: static in one, not the other"
        if is_property:
            continue
        stub = _stub_params(fn, skip_first=not is_static)
        real = _real_params(getattr(real_cls, name), skip_self=not is_static)
        assert _same(stub, real), f"{cls.name}.{name}: stub {stub} != module {real}"
