"""The package's layering (docs/architecture.md): every module imports only from its own layer or the layers
above it, so data flows one way and nothing outside cli/ reaches into the command line."""
import ast

from helpers import REPO

PKG = REPO / "python" / "inkopt"
# top to bottom; a module may import from its own layer and any layer before it
LAYERS = [
    {"units", "color", "io", "pictures", "charts", "lighting", "_core", "__init__"},
    {"model"},
    {"rundir"},
    {"render", "distributed"},
    {"loss"},
    {"scenes"},
    {"optim"},
    {"printing"},
    {"evaluation"},
    {"run"},
    {"inksets"},
    {"cli", "__main__"},
]


def _layer(top: str) -> int:
    for i, names in enumerate(LAYERS):
        if top in names:
            return i
    raise AssertionError(f"python/inkopt/{top} is in no layer of docs/architecture.md; add it to LAYERS")


def _imports(path):
    """Top-level inkopt names imported by a module (absolute ``inkopt.x`` or relative ``..x``)."""
    rel = path.relative_to(PKG).with_suffix("")
    package = list(rel.parts[:-1])
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[:len(package) - node.level + 1]
                parts = base + (node.module.split(".") if node.module else [])
                if not parts:  # "from .. import x" at the top: x are top-level modules
                    yield from (a.name for a in node.names)
                    continue
                yield parts[0]
            elif node.module and node.module.split(".")[0] == "inkopt":
                parts = node.module.split(".")
                yield parts[1] if len(parts) > 1 else node.names[0].name
        elif isinstance(node, ast.Import):
            for a in node.names:
                parts = a.name.split(".")
                if parts[0] == "inkopt" and len(parts) > 1:
                    yield parts[1]


def test_modules_import_only_from_layers_above():
    bad = []
    for path in sorted(PKG.rglob("*.py")):
        top = path.relative_to(PKG).parts[0].removesuffix(".py")
        mine = _layer(top)
        for name in _imports(path):
            if name in ("__version__",):
                continue
            if _layer(name) > mine:
                bad.append(f"{path.relative_to(REPO)} imports {name}")
    assert not bad, bad


def test_no_source_file_is_huge():
    """Files stay focused (a few hundred lines); a long one is a sign that it holds two things."""
    long = [f"{p.relative_to(REPO)}: {n}" for p in PKG.rglob("*.py")
            if (n := len(p.read_text().splitlines())) > 450]
    assert not long, long
