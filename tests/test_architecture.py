"""The package's shape, checked mechanically (docs/architecture.md): every Python module imports only from its own
layer or the layers above it, so data flows one way and nothing outside cli/ reaches into the command line; no
import circles, in Python or in the Rust crates; files stay focused; source comments say what the code does, not
when or under which issue it was written, and cite nothing outside the repository."""

import ast
import io
import re
import tokenize

from helpers import REPO

PKG = REPO / "python" / "inkopt"
CRATES = REPO / "crates"
# top to bottom; a module may import from its own layer and any layer before it
LAYERS = [
    {"units", "color", "errors", "io", "threads", "heap", "images", "pictures", "charts", "lighting"}
    | {"_core", "__init__"},
    {"model"},
    {"rundir"},
    {"render", "distributed", "shardwire"},
    {"neighbourhood", "loss", "spectral"},
    {"scenes"},
    {"optim"},
    {"printing"},
    {"evaluation"},
    {"calibration"},
    {"proof"},
    {"run", "runfigures", "estimate", "footprint", "coarse"},
    {"inksets"},
    {"cli", "__main__"},
]
MAX_PY_LINES = 450  # a few hundred lines; a longer file is a sign that it holds two things
MAX_RS_LINES = 450  # the same for Rust, the bindings included


def _layer(top: str) -> int:
    for i, names in enumerate(LAYERS):
        if top in names:
            return i
    raise AssertionError(f"python/inkopt/{top} is in no layer of docs/architecture.md; add it to LAYERS")


def _module_name(path) -> str:
    rel = path.relative_to(PKG.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _top(module: str) -> str:
    """The top-level part of inkopt a module belongs to (``inkopt.scenes.slab`` -> ``scenes``)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def _is_package(path) -> bool:
    return path.name == "__init__.py"


def _imported_modules(path):
    """Full names of the inkopt modules a file imports, at its top or inside functions (``from .x import y``
    yields ``inkopt...x`` and, where ``y`` is itself a module, ``inkopt...x.y``)."""
    me = _module_name(path)
    package = me.split(".") if _is_package(path) else me.split(".")[:-1]
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - node.level + 1]
                mod = ".".join(base + (node.module.split(".") if node.module else []))
            else:
                mod = node.module or ""
            if mod.split(".")[0] != "inkopt":
                continue
            if mod != "inkopt":
                yield mod
            for a in node.names:
                yield f"{mod}.{a.name}"  # kept only if it names a module (filtered by the caller)
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] == "inkopt":
                    yield a.name


def _python_graph() -> dict:
    files = {_module_name(p): p for p in PKG.rglob("*.py")}
    known = set(files) | {"inkopt._core"}
    graph = {}
    for name, path in files.items():
        deps = set()
        for mod in _imported_modules(path):
            # the deepest known module that the imported name is, or lies in
            parts = mod.split(".")
            while parts and ".".join(parts) not in known:
                parts.pop()
            dep = ".".join(parts)
            if dep and dep != name and not name.startswith(dep + "."):  # a module's own package is not a dependency
                deps.add(dep)
        graph[name] = deps
    return graph


def _cycle(graph: dict) -> list | None:
    """One cycle of a directed graph (as a list of nodes, first repeated at the end), or None."""
    state, stack = {}, []

    def visit(n):
        state[n] = 1
        stack.append(n)
        for m in sorted(graph.get(n, ())):
            if state.get(m) == 1:
                return stack[stack.index(m) :] + [m]
            if m not in state and (c := visit(m)):
                return c
        stack.pop()
        state[n] = 2
        return None

    for n in sorted(graph):
        if n not in state and (c := visit(n)):
            return c
    return None


def test_modules_import_only_from_layers_above():
    bad = []
    for name, deps in _python_graph().items():
        mine = _layer(_top(name))
        bad += [f"{name} imports {d}" for d in sorted(deps) if _layer(_top(d)) > mine]
    assert not bad, bad


def test_no_python_import_circle():
    """Module by module, imports inside functions included (they must not hide a circle)."""
    cycle = _cycle(_python_graph())
    assert cycle is None, " -> ".join(cycle)


def _rust_modules(src) -> dict:
    """Module path (``a::b``) of each file of a crate's ``src`` (``lib.rs`` is the crate root, ``x/mod.rs`` is
    ``x``)."""
    mods = {}
    for p in src.rglob("*.rs"):
        parts = list(p.relative_to(src).with_suffix("").parts)
        if parts[-1] in ("lib", "mod", "main"):
            parts.pop()
        mods["::".join(parts)] = p
    return mods


def _rust_code(text: str) -> str:
    """Rust source without comments and string literals (so that paths in prose are not counted)."""
    text = re.sub(r"//[^\n]*", "", text)
    text = re.sub(r"/\*.*?\*/", "", text, flags=re.S)
    return re.sub(r'"(\\.|[^"\\])*"', '""', text)


def _rust_graph(src) -> dict:
    mods = _rust_modules(src)
    graph = {}
    for name, path in mods.items():
        here = name.split("::") if name else []
        code = _rust_code(path.read_text())
        deps = set()
        # crate::a::b, super::x, self::x paths, in `use` trees and in expressions; `mod x;` is containment
        refs = [m.group(0) for m in re.finditer(r"\b(crate|super|self)(::(\{[^}]*\}|\w+))+", code)]
        # `use crate::{a::x, b}` groups: each item of the group is a path of its own
        for ref in refs:
            head, *rest = ref.split("::", 1)
            tail = rest[0] if rest else ""
            base = [] if head == "crate" else here[:-1] if head == "super" else list(here)
            for item in tail[1:-1].split(",") if tail.startswith("{") else [tail]:
                parts = base + [s for s in item.strip().split("::") if s and s != "{"]
                parts = [s.strip("{} ") for s in parts]
                while parts and "::".join(parts) not in mods:
                    parts.pop()
                dep = "::".join(parts)
                if dep in mods and dep != name and not name.startswith(dep + "::" if dep else "\0"):
                    deps.add(dep)
        graph[name or "<crate root>"] = {d or "<crate root>" for d in deps}
    return graph


def test_no_rust_module_circle():
    """In each crate, the modules' references (``crate::``, ``super::``, ``self::`` paths) form no circle; a
    module's own ancestors are not counted (a parent declaring its children is containment)."""
    for src in sorted(CRATES.glob("*/src")):
        cycle = _cycle(_rust_graph(src))
        assert cycle is None, f"{src.relative_to(REPO)}: " + " -> ".join(cycle)


def test_no_source_file_is_huge():
    """Files stay focused (a few hundred lines); a long one is a sign that it holds two things."""
    long = [
        f"{p.relative_to(REPO)}: {n}"
        for p in PKG.rglob("*.py")
        if (n := len(p.read_text().splitlines())) > MAX_PY_LINES
    ]
    long += [
        f"{p.relative_to(REPO)}: {n}"
        for p in CRATES.rglob("*.rs")
        if (n := len(p.read_text().splitlines())) > MAX_RS_LINES
    ]
    assert not long, long


DATE = re.compile(r"\b20\d\d-[01]\d(-[0-3]\d)?\b")
ISSUE = re.compile(r"\b[Ii]ssues? *#?\d+|(?:^|\s|\()#\d+\b")
# the method is cited as docs/method.md; ../shared/data (test meshes beside the checkout) is data, not a citation
OUTSIDE = re.compile(r"shared/(?!data\b)\w|(?<!docs/)\bmethod\.md|/work/")


def _python_comments(path):
    """(line, text) of every comment and docstring of a Python file."""
    text = path.read_text()
    for tok in tokenize.generate_tokens(io.StringIO(text).readline):
        if tok.type == tokenize.COMMENT:
            yield tok.start[0], tok.string
    for node in ast.walk(ast.parse(text)):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            doc = ast.get_docstring(node, clean=False)
            if doc:
                yield node.body[0].lineno, doc


def _rust_comments(path):
    for i, line in enumerate(path.read_text().splitlines(), 1):
        if (k := line.find("//")) >= 0:
            yield i, line[k:]


def test_comments_carry_no_dates_issue_numbers_or_outside_references():
    """Comments say what the code does and why, in the present tense: the history is git's. A measured constant
    names the results file in the repository that measured it, not a day or an issue."""
    files = [*PKG.rglob("*.py"), *(REPO / "tests").rglob("*.py"), *(REPO / "bench").rglob("*.py")]
    bad = []
    for path in files:
        for line, text in _python_comments(path):
            for pat in (DATE, ISSUE, OUTSIDE):
                if m := pat.search(text):
                    bad.append(f"{path.relative_to(REPO)}:{line}: {m.group(0)!r}")
    for path in CRATES.rglob("*.rs"):
        for line, text in _rust_comments(path):
            for pat in (DATE, ISSUE, OUTSIDE):
                if m := pat.search(text):
                    bad.append(f"{path.relative_to(REPO)}:{line}: {m.group(0)!r}")
    assert not bad, bad


def test_checks_find_what_they_look_for(tmp_path):
    """The graph and comment checks are not vacuous: a planted circle and a planted date are found."""
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b"}, "b": set()}) is None
    src = tmp_path / "src"
    (src / "p").mkdir(parents=True)
    (src / "lib.rs").write_text("mod x;\nmod p;\n")
    (src / "x.rs").write_text("use crate::p::Y;\n// crate::q is prose\n")
    (src / "p" / "mod.rs").write_text("mod r;\npub use self::r::Y;\n")
    (src / "p" / "r.rs").write_text("use crate::{x::Z, p};\n")
    g = _rust_graph(src)
    assert g["x"] == {"p"} and g["p"] == {"p::r"} and g["p::r"] == {"x"}
    assert _cycle(g) is not None
    assert DATE.search("# 300 since 2026-11-25") and ISSUE.search("see issue 13") and ISSUE.search("(#12)")
    assert not ISSUE.search("a[#0]") and not DATE.search("spp 2026")
    assert OUTSIDE.search("see ../shared/method.md") and OUTSIDE.search("(method.md section 4)")
    assert not OUTSIDE.search("docs/method.md section 4") and not OUTSIDE.search("../shared/data/spot")


MAX_FUNCTION_LINES = 80  # a longer function is a sign that it does several steps: name them
MAX_PARAMETERS = 9  # more, and the arguments travel as a typed bundle (a frozen dataclass) instead
#: functions allowed past those limits, each with the reason it stays whole ("module.py:function": reason)
LONG_FUNCTIONS: dict[str, str] = {}


def _functions(path):
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            a = node.args
            params = [*a.posonlyargs, *a.args, *a.kwonlyargs, *filter(None, (a.vararg, a.kwarg))]
            params = [p for p in params if p.arg not in ("self", "cls")]
            yield node.name, node.end_lineno - node.lineno + 1, len(params)


def test_functions_are_short_and_take_few_parameters():
    """No function of python/inkopt is longer than ``MAX_FUNCTION_LINES`` or takes more than ``MAX_PARAMETERS``
    parameters unless ``LONG_FUNCTIONS`` says why; the allow-list names only functions that need it."""
    seen, bad = set(), []
    for path in sorted(PKG.rglob("*.py")):
        for name, lines, params in _functions(path):
            key = f"{path.relative_to(PKG)}:{name}"
            if lines > MAX_FUNCTION_LINES or params > MAX_PARAMETERS:
                seen.add(key)
                if key not in LONG_FUNCTIONS:
                    bad.append(f"{key}: {lines} lines, {params} parameters")
    assert not bad, bad
    assert not set(LONG_FUNCTIONS) - seen, f"no longer needed: {sorted(set(LONG_FUNCTIONS) - seen)}"
