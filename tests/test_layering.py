"""The package is layered: a module imports only from layers below it, never from its own layer
or above, at module level or inside a function; no module reaches into another module's private
attributes; no module is over 800 lines. The import graph is read from the source (AST), so an
import inside a function or under ``if TYPE_CHECKING:`` counts like any other.

The layers are listed in docs/architecture.md ("Python package"); a new module must be placed in
:data:`LAYERS` (the test fails until it is).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "python" / "sorofem"

#: The layers, lowest first. A module may import modules of lower layers only.
LAYERS: list[tuple[str, ...]] = [
    ("errors",),
    ("_extension", "_validate", "_version", "_deprecated", "_text", "progress", "_chunks"),
    ("_files",),
    ("_formats",),
    ("mesh",),
    ("io",),
    ("convert", "mesh_info", "meshing", "materials._declarations", "solver"),
    ("materials.neo_hookean", "materials.decoupled", "fitting.models", "material_library"),
    ("materials",),
    ("fitting.curves",),
    ("fitting.data", "fitting.plotting"),
    ("fitting.fit",),
    ("fitting.cli",),
    ("fitting",),
    ("cables", "obstacles"),
    ("body",),
    ("static", "_pvd"),
    ("dynamics",),
    ("plot", "targets"),
    ("inverse._parameters", "inverse.results"),
    ("inverse._problem",),
    ("inverse._optimizers",),
    ("inverse._analysis",),
    ("inverse._trajectory",),
    ("inverse._estimate_dynamics", "inverse._control_dynamics"),
    ("inverse._gradient", "inverse._estimate", "inverse._control"),
    ("inverse",),
    ("scene._spec",),
    ("scene._keys",),
    ("scene._build", "scene.generate"),
    ("scene._motion",),
    ("scene._scene",),
    ("scene",),
    ("viewer.style", "viewer.serving", "viewer.colours", "viewer.frames"),
    ("viewer.commands",),
    ("viewer.contact",),
    ("viewer.playback",),
    ("viewer.static_view",),
    ("viewer",),
    ("sweeps._cases",),
    ("sweeps._store",),
    ("sweeps._solve",),
    ("sweeps._run",),
    ("sweeps.cli",),
    ("sweeps",),
    ("cli",),
    # The facade (re-exports the public names) and the deprecated module, above everything.
    ("",),
    ("model",),
]
RANK = {("sorofem." + name).rstrip("."): rank for rank, layer in enumerate(LAYERS) for name in layer}
#: The compiled extension (crates/sorofem-py): below every Python module.
EXTENSION = "sorofem._core"
RANK[EXTENSION] = -1
MAX_LINES = 800


def _modules() -> dict[str, Path]:
    out = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = ("sorofem", *path.relative_to(PACKAGE).with_suffix("").parts)
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        out[name] = path
    return out


def _exists(name: str) -> bool:
    return name in MODULES or name == EXTENSION


MODULES = _modules()


def _imports(name: str, path: Path) -> list[tuple[str, int, bool]]:
    """``(imported sorofem module, line, inside a function)`` of every import in the file."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    in_function: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            in_function.update(id(sub) for sub in ast.walk(node) if sub is not node)
    found = []
    for node in ast.walk(tree):
        targets: list[str] = []
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = ".".join(package.split(".")[: len(package.split(".")) - node.level + 1] + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            targets = [f"{base}.{alias.name}" if _exists(f"{base}.{alias.name}") else base for alias in node.names]
        elif isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        for target in dict.fromkeys(targets):
            # `import sorofem.x.y` imports the deepest module that exists.
            while target and not _exists(target):
                target = target.rpartition(".")[0]
            if target and target != name:
                found.append((target, node.lineno, id(node) in in_function))
    return found


GRAPH = {name: _imports(name, path) for name, path in MODULES.items()}


def test_every_module_has_a_layer():
    missing = sorted(set(MODULES) - set(RANK))
    assert not missing, f"place these modules in tests/test_layering.py LAYERS (and docs/architecture.md): {missing}"
    stale = sorted(set(RANK) - set(MODULES) - {EXTENSION})
    assert not stale, f"LAYERS names modules that do not exist: {stale}"


@pytest.mark.parametrize("name", sorted(MODULES))
def test_imports_go_down_the_layers(name):
    upward = [
        f"line {line}: {target} (layer {RANK[target]}, this module is in layer {RANK[name]})"
        for target, line, _ in GRAPH[name]
        if RANK[target] >= RANK[name]
    ]
    assert not upward, f"{name} imports its own layer or a higher one: " + "; ".join(upward)


@pytest.mark.parametrize("name", sorted(MODULES))
def test_no_function_level_import_of_sorofem(name):
    """A function-level import of a sorofem module would hide a cycle; only optional or heavy
    third-party packages (viser, trimesh, pytetwild, matplotlib, meshio, scipy.optimize) are
    imported inside functions."""
    inside = [f"line {line}: {target}" for target, line, in_function in GRAPH[name] if in_function]
    assert not inside, f"{name} imports sorofem modules inside functions: {inside}"


def test_no_import_cycle():
    seen: dict[str, int] = {}  # 1: on the current path, 2: done

    def visit(node: str, path: list[str]) -> None:
        seen[node] = 1
        for target, _, _ in GRAPH.get(node, []):
            if seen.get(target) == 1:
                cycle = path[path.index(target):] + [target]
                pytest.fail("import cycle: " + " -> ".join(cycle))
            if target not in seen:
                visit(target, [*path, target])
        seen[node] = 2

    for module in sorted(MODULES):
        if module not in seen:
            visit(module, [module])


def _private_definitions(tree: ast.AST) -> set[str]:
    """The private names a module defines: functions, classes, assigned attributes and names."""
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store):
            names.add(node.attr)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            names.add(node.id)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
    return {n for n in names if n.startswith("_")}


@pytest.mark.parametrize("name", sorted(MODULES))
def test_no_reaching_into_private_attributes(name):
    """``other._attr`` is allowed only for private names the module defines itself (its own
    classes' attributes); another module's internals go through a documented interface."""
    tree = ast.parse(MODULES[name].read_text(encoding="utf-8"))
    own = _private_definitions(tree)
    foreign = sorted({
        f"line {node.lineno}: .{node.attr}"
        for node in ast.walk(tree)
        if isinstance(node, ast.Attribute)
        and node.attr.startswith("_")
        and not (node.attr.startswith("__") and node.attr.endswith("__"))
        and node.attr not in own
        and not (isinstance(node.value, ast.Name) and node.value.id in ("self", "cls"))
    })
    assert not foreign, f"{name} uses private attributes it does not define: {foreign}"


@pytest.mark.parametrize("name", sorted(MODULES))
def test_module_size(name):
    lines = len(MODULES[name].read_text(encoding="utf-8").splitlines())
    assert lines <= MAX_LINES, f"{MODULES[name]} has {lines} lines (at most {MAX_LINES}): split it by concern"
