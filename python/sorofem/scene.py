"""Scene files: a whole static simulation described in TOML.

Schema
------
::

    [mesh]                     # required: exactly one of `file` or `box`
    file = "beam.vtu"          # relative to the scene file; .tet or any format meshio reads
    # box = { size = [1.0, 0.1, 0.1], cells = [8, 2, 2] }   # optional origin = [x, y, z]
    scale = 1.0                # optional, > 0; coordinates are multiplied by this

    [material]                 # required; Neo-Hookean
    youngs_modulus = 66e3      # Pa; or shear_modulus + lame_lambda (Pa)
    poisson_ratio = 0.45       # 0 <= nu < 0.5 (nu = 0.5 is rejected: lambda must be finite)
    density = 1080             # kg/m^3, optional (default 0)

    [formulation]              # optional
    kind = "standard"          # or "mixed": displacement + nodal pressure, no locking as nu -> 0.5
    volumetric = "log"         # optional: c(J) = ln J ("log") or J - 1 ("linear")
    pressure_mass = "consistent"   # optional, mixed only: "consistent" or "lumped"

    [[fixed]]                  # required, at least one entry, each selecting >= 1 node
    box = { min = [-1e-9, -1, -1], max = [1e-9, 1, 1] }   # or nodes = [0, 1, 2]
    displacement = [0, 0, 0]   # optional prescribed displacement, m

    [loads]                    # optional
    gravity = [0, 0, -9.81]    # m/s^2
    forces = [{ nodes = [5, 6], force = [0, 0, -0.1] }]    # optional; N per node;
                               # `box = {min, max}` may select the nodes instead of `nodes`

    [solver]                   # optional
    tolerance = 1e-8           # relative residual
    max_iterations = 50
    load_steps = 1

    [[cable]]                  # optional, any number; a straight line ...
    start = [0, 0.01, 0.01]    # m
    direction = [1, 0, 0]      # any non-zero length
    length = 0.4               # m
    divisions = 10             # segments
    # points = [[0, 0.01, 0.01], [0.2, 0.01, 0.01], [0.4, 0.01, 0.01]]   # ... or explicit points
    stiffness = 1e5            # N/m per segment (required)
    actuation = 0.8            # alpha > 0: 1 = rest length, < 1 = pulled (default 1)
    transition = 1e-3          # slack-taut transition width / segment rest length, in (0, 1)
    anchor_first = false       # first point fixed in the world (the motor)
    snap_tolerance = 0.0       # m: points this far outside the mesh attach to the nearest tet
    outside = "error"          # or "free": points farther out become free nodes
    free_node_mass = 0.0       # kg per free node

    [dynamics]                 # optional: integrate in time instead of a static solve
    dt = 0.01                  # s
    steps = 200
    mass_damping = 0.0         # Rayleigh alpha_M, 1/s
    stiffness_damping = 0.0    # Rayleigh beta_K, s
    save_every = 1             # frames written every this many steps
    initial = "rest"           # or "static": start from the static equilibrium (loads, actuations)
    actuation = [[[0.0, 1.0], [0.5, 0.8]]]   # per cable: [time, alpha] keyframes, linear, held
                               # outside; default: every cable keeps its `actuation`

    [target]                   # optional (for `sorofem estimate` / `sorofem control`): exactly one of
    nodes = [17, 18, 19]       # ... mesh node indices, with their goal `positions` (m) ...
    positions = [[0.1, 0, -0.01], [0.1, 0.02, -0.01], [0.1, 0.02, 0.01]]
    # points = [[0.1, 0.01, 0.01]]   # ... or marker points at rest (m) + `positions` ...
    # surface = "goal.obj"     # ... or a goal surface, relative to the scene file, with
    # scale = 1.0              #     optional coordinate scale and the body's own
    # rest = "rest.obj"        #     rest surface (default: the mesh's boundary)

    [estimate]                 # optional: `sorofem estimate` fits these to [target]
    params = ["shear_modulus", "lame_lambda"]   # names of sorofem.inverse.PARAMETERS
    x0 = [20e3, 0.2e6]         # initial values, one per name
    bounds = [[1e3, 1e6], [1e3, 1e8]]           # optional, one [lo, hi] per name
    method = "least-squares"   # optional: "least-squares", "l-bfgs-b" or "nelder-mead"
    starts = 0                 # optional: number of extra random starts

    [control]                  # optional: `sorofem control` finds cable actuations for [target]
    cables = [0]               # indices of [[cable]] entries (default: all)
    bounds = [[0.3, 1.0]]      # optional, one alpha range per cable
    method = "l-bfgs-b"        # optional: or "nelder-mead"

Validation is strict: an unknown key, a wrong type, a missing mesh file, a ``[[fixed]]``
entry selecting no node or an out-of-range value raises :class:`~sorofem.SceneError`
with the file, the dotted key (e.g. ``fixed[0].box.min``) and, when it can be found, the
line.

Examples
--------
>>> import sorofem as sf
>>> scene = sf.Scene.load("cantilever.toml")      # doctest: +SKIP
>>> result = scene.solve()                        # doctest: +SKIP
"""

from __future__ import annotations

import math
import os
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .cables import OUTSIDE_MODES, Cable
from .dynamics import Keyframes, Trajectory, simulate
from .errors import InputError, ParameterError, SceneError
from .io import read_mesh
from .targets import Target
from .model import (
    FORMULATIONS,
    PRESSURE_MASSES,
    VOLUMETRIC_MEASURES,
    Body,
    Mesh,
    NeoHookean,
    StaticResult,
    solve_static,
)

__all__ = ["Scene"]

_TOP_KEYS = (
    "mesh", "material", "formulation", "fixed", "loads", "solver", "cable", "dynamics", "target", "estimate",
    "control",
)
_ESTIMATE_METHODS = ("least-squares", "l-bfgs-b", "nelder-mead")
_CONTROL_METHODS = ("l-bfgs-b", "nelder-mead")
_CABLE_KEYS = (
    "points", "start", "direction", "length", "divisions", "stiffness", "actuation", "transition",
    "anchor_first", "snap_tolerance", "outside", "free_node_mass",
)
_DYNAMICS_DEFAULTS: dict[str, Any] = {
    "mass_damping": 0.0, "stiffness_damping": 0.0, "save_every": 1, "initial": "rest", "actuation": None,
}
_MATERIAL_KEYS = ("youngs_modulus", "poisson_ratio", "shear_modulus", "lame_lambda", "density")
_SOLVER_DEFAULTS: dict[str, Any] = {"tolerance": 1e-8, "max_iterations": 50, "load_steps": 1}
_FORMULATION_DEFAULTS: dict[str, str] = {"kind": "standard", "volumetric": "log", "pressure_mass": "consistent"}

_HEADER = re.compile(r"^\s*(\[\[?)\s*([^\]]+?)\s*\]\]?\s*(#.*)?$")
_KEY_PART = re.compile(r"^([A-Za-z0-9_\-]+)(?:\[(\d+)\])?$")


def _type_name(value: Any) -> str:
    return {
        bool: "a boolean",
        int: "an integer",
        float: "a number",
        str: "a string",
        list: "an array",
        dict: "a table",
    }.get(type(value), type(value).__name__)


class _Checker:
    """Validates values of one scene file and builds errors that point into it."""

    def __init__(self, path: Path, text: str) -> None:
        self.path = path
        self.lines = text.splitlines()

    # -- locating keys ---------------------------------------------------------------

    def find_line(self, key: str) -> int | None:
        """Best-effort 1-based line of a dotted key such as ``fixed[1].box.min``."""
        parts = []
        for token in key.split("."):
            match = _KEY_PART.match(token)
            if not match:
                return None
            parts.append((match.group(1), None if match.group(2) is None else int(match.group(2))))
        names = [name for name, _ in parts]
        # The longest prefix that is a table header opens the section to search in.
        for depth in range(len(parts), 0, -1):
            header = ".".join(names[:depth])
            span = self._section(header, parts[depth - 1][1])
            if span is not None:
                return self._find_in(span, names[depth:])
        # Keys of the root table, or a table written inline at the root.
        first_header = next((i for i, line in enumerate(self.lines) if _HEADER.match(line)), len(self.lines))
        return self._find_in((0, first_header), names)

    def _section(self, header: str, index: int | None) -> tuple[int, int] | None:
        seen = -1
        for i, line in enumerate(self.lines):
            match = _HEADER.match(line)
            if match and re.sub(r"\s+", "", match.group(2)) == header:
                seen += 1
                if index is None or seen == index:
                    end = next(
                        (j for j in range(i + 1, len(self.lines)) if _HEADER.match(self.lines[j])),
                        len(self.lines),
                    )
                    return i, end
        return None

    def _find_in(self, span: tuple[int, int], names: list[str]) -> int | None:
        start, end = span
        found = start + 1 if start < len(self.lines) and _HEADER.match(self.lines[start]) else None
        if not names and found is not None:
            return found
        for depth, name in enumerate(names):
            pattern = re.compile(
                (r"^\s*" if depth == 0 else r"[{,\s]") + re.escape(name) + r"\s*="
            )
            hit = next((j for j in range(start, end) if pattern.search(self.lines[j])), None)
            if hit is None:
                break
            found, start = hit + 1, hit
        return found

    def error(self, key: str | None, message: str) -> SceneError:
        line = self.find_line(key) if key else None
        return SceneError(message, path=self.path, key=key, line=line)

    # -- typed getters ---------------------------------------------------------------

    def table(self, value: Any, key: str, hint: str = "") -> dict[str, Any]:
        if not isinstance(value, dict):
            raise self.error(key, f"expected a table{hint}, got {_type_name(value)}")
        return value

    def keys(self, table: dict[str, Any], allowed: tuple[str, ...], prefix: str) -> None:
        for name in table:
            if name not in allowed:
                key = f"{prefix}.{name}" if prefix else name
                raise self.error(key, f"unknown key '{name}' (allowed: {', '.join(allowed)})")

    def number(self, value: Any, key: str, *, minimum: float | None = None, strict: bool = True) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.error(key, f"expected a number, got {_type_name(value)} {value!r}")
        value = float(value)
        if not math.isfinite(value):
            raise self.error(key, f"expected a finite number, got {value}")
        if minimum is not None and (value <= minimum if strict else value < minimum):
            raise self.error(key, f"expected a number {'>' if strict else '>='} {minimum:g}, got {value:g}")
        return value

    def integer(self, value: Any, key: str, minimum: int) -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(key, f"expected an integer, got {_type_name(value)} {value!r}")
        if value < minimum:
            raise self.error(key, f"expected an integer >= {minimum}, got {value}")
        return value

    def vec3(self, value: Any, key: str) -> np.ndarray:
        if not isinstance(value, list) or len(value) != 3:
            shown = f"an array of length {len(value)}" if isinstance(value, list) else f"{_type_name(value)} {value!r}"
            raise self.error(key, f"expected an array of 3 numbers, got {shown}")
        return np.array([self.number(v, key) for v in value])

    def string(self, value: Any, key: str) -> str:
        if not isinstance(value, str):
            raise self.error(key, f"expected a string, got {_type_name(value)} {value!r}")
        return value


@dataclass
class Scene:
    """A static simulation read from a TOML scene file (schema in the module docstring).

    Attributes
    ----------
    path
        The scene file.
    mesh, material, body
        The model, with the ``[[fixed]]`` conditions and ``[loads].forces`` applied to ``body``.
    formulation
        ``[formulation].kind``.
    formulation_options
        ``[formulation]`` ``volumetric`` and ``pressure_mass`` (keyword arguments of
        :class:`sorofem.Body`), defaults filled in.
    gravity
        ``(3,)`` m/s^2.
    solver
        Keyword arguments of :func:`sorofem.solve_static`: ``tolerance``,
        ``max_iterations``, ``load_steps``.

    Examples
    --------
    >>> import sorofem as sf
    >>> scene = sf.Scene.load("cantilever.toml")  # doctest: +SKIP
    >>> result = scene.solve()                    # doctest: +SKIP
    """

    path: Path
    mesh: Mesh
    material: NeoHookean
    body: Body
    formulation: str
    gravity: np.ndarray
    solver: dict[str, Any] = field(default_factory=lambda: dict(_SOLVER_DEFAULTS))
    formulation_options: dict[str, str] = field(
        default_factory=lambda: {k: v for k, v in _FORMULATION_DEFAULTS.items() if k != "kind"}
    )
    #: The ``[[cable]]`` entries, added to ``body`` (see :class:`sorofem.Cable`).
    cables: list[Cable] = field(default_factory=list)
    #: ``[dynamics]`` with defaults filled in (``actuation``: a list of
    #: :class:`sorofem.dynamics.Keyframes` per cable, or None), or None for a static scene.
    dynamics: dict[str, Any] | None = None
    #: ``[target]`` as a :class:`sorofem.Target`, or None.
    target: Target | None = None
    #: ``[estimate]``: ``params``, ``x0``, ``bounds``, ``method``, ``starts`` (None when absent), or None.
    estimate: dict[str, Any] | None = None
    #: ``[control]``: ``cables`` (indices), ``bounds``, ``method``, or None.
    control: dict[str, Any] | None = None

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> "Scene":
        """Read, validate and build a scene.

        Raises
        ------
        SceneError
            Anything wrong in the file, with ``path``, ``key`` and ``line``.
        FileNotFoundError
            The scene file itself does not exist.
        """
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"scene file not found: {path}")
        try:
            text = path.read_text(encoding="utf-8")
        except UnicodeDecodeError as exc:
            raise SceneError(f"not a UTF-8 text file ({exc})", path=path) from None
        return cls.from_toml(text, path)

    @classmethod
    def from_toml(cls, text: str, path: str | os.PathLike[str]) -> "Scene":
        """Build a scene from TOML text; relative mesh paths are resolved against ``path``'s folder."""
        path = Path(path)
        check = _Checker(path, text)
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            match = re.search(r"line (\d+)", str(exc))
            raise SceneError(
                f"invalid TOML: {exc}", path=path, line=int(match.group(1)) if match else None
            ) from None
        check.keys(data, _TOP_KEYS, "")
        for required in ("mesh", "material", "fixed"):
            if required not in data:
                what = "[[fixed]] entry" if required == "fixed" else f"[{required}] table"
                raise check.error(required, f"missing: a scene needs a {what}")

        mesh = _build_mesh(check, data["mesh"], path.parent)
        material = _build_material(check, data["material"])
        formulation, options = _build_formulation(check, data.get("formulation", {}))
        try:
            body = Body(mesh, material, formulation=formulation, **options)
        except ParameterError as exc:
            raise check.error(f"material.{exc.parameter or 'youngs_modulus'}", str(exc)) from None
        _apply_fixed(check, data["fixed"], body)
        gravity = _apply_loads(check, data.get("loads", {}), body)
        solver = _build_solver(check, data.get("solver", {}))
        cables = _apply_cables(check, data.get("cable", []), body)
        dynamics = _build_dynamics(check, data["dynamics"], body) if "dynamics" in data else None
        target = _build_target(check, data["target"], body, path.parent) if "target" in data else None
        estimate = _build_estimate(check, data["estimate"]) if "estimate" in data else None
        control = _build_control(check, data["control"], body) if "control" in data else None
        return cls(
            path=path,
            mesh=mesh,
            material=material,
            body=body,
            formulation=formulation,
            gravity=gravity,
            solver=solver,
            formulation_options=options,
            cables=cables,
            dynamics=dynamics,
            target=target,
            estimate=estimate,
            control=control,
        )

    def solve(self) -> StaticResult:
        """Run :func:`sorofem.solve_static` with the scene's loads and solver options."""
        return solve_static(self.body, self.gravity, **self.solver)

    def simulate(self) -> Trajectory:
        """Run :func:`sorofem.simulate` with the scene's ``[dynamics]`` (from the rest shape,
        or from :meth:`solve`'s equilibrium with ``initial = "static"``).

        Raises
        ------
        InputError
            The scene has no ``[dynamics]`` table.
        """
        if self.dynamics is None:
            raise InputError(f"{self.path}: the scene has no [dynamics] table")
        d = self.dynamics
        initial = self.solve() if d["initial"] == "static" else None
        return simulate(
            self.body, d["dt"], d["steps"], actuation=d["actuation"], gravity=self.gravity,
            damping=(d["mass_damping"], d["stiffness_damping"]), initial=initial, save_every=d["save_every"],
            tolerance=self.solver["tolerance"], max_iterations=self.solver["max_iterations"],
        )

    def to_dict(self) -> dict[str, Any]:
        """Plain summary of the scene's settings."""
        return {
            "scene": str(self.path),
            "mesh": None if self.mesh.source is None else str(self.mesh.source),
            "formulation": self.formulation,
            "formulation_options": self.body.formulation_options,
            "material": self.material.to_dict(),
            "gravity": self.gravity.tolist(),
            "fixed_nodes": int(self.body.fixed_nodes.size),
            "solver": dict(self.solver),
            "cables": [c.to_dict() for c in self.cables],
            "dynamics": None if self.dynamics is None else {
                **self.dynamics,
                "actuation": None if self.dynamics["actuation"] is None else [
                    np.column_stack([k.times, k.values]).tolist() for k in self.dynamics["actuation"]
                ],
            },
        }


# ---------------------------------------------------------------------------
# Sections


def _build_mesh(check: _Checker, raw: Any, base: Path) -> Mesh:
    table = check.table(raw, "mesh")
    check.keys(table, ("file", "box", "scale"), "mesh")
    scale = check.number(table["scale"], "mesh.scale", minimum=0.0) if "scale" in table else 1.0
    if ("file" in table) == ("box" in table):
        raise check.error("mesh", "expected exactly one of 'file' or 'box'")
    if "file" in table:
        name = check.string(table["file"], "mesh.file")
        file = Path(name) if Path(name).is_absolute() else base / name
        if not file.is_file():
            raise check.error("mesh.file", f"mesh file not found: {file}")
        try:
            return read_mesh(file, scale=scale)
        except InputError as exc:
            raise check.error("mesh.file", f"could not read the mesh: {exc}") from None
    box = check.table(table["box"], "mesh.box", " like { size = [1, 0.1, 0.1], cells = [8, 2, 2] }")
    check.keys(box, ("size", "cells", "origin"), "mesh.box")
    for required in ("size", "cells"):
        if required not in box:
            raise check.error(f"mesh.box.{required}", "missing")
    size = check.vec3(box["size"], "mesh.box.size")
    if np.any(size <= 0):
        raise check.error("mesh.box.size", f"expected three positive lengths, got {size.tolist()}")
    cells = box["cells"]
    if not isinstance(cells, list) or len(cells) != 3:
        raise check.error("mesh.box.cells", f"expected an array of 3 integers, got {cells!r}")
    cells = [check.integer(c, "mesh.box.cells", 1) for c in cells]
    origin = check.vec3(box["origin"], "mesh.box.origin") if "origin" in box else np.zeros(3)
    return Mesh.box(size=size * scale, cells=cells, origin=origin * scale)


def _build_material(check: _Checker, raw: Any) -> NeoHookean:
    table = check.table(raw, "material")
    check.keys(table, _MATERIAL_KEYS, "material")
    values = {name: check.number(value, f"material.{name}") for name, value in table.items()}
    try:
        return NeoHookean(**values)
    except ParameterError as exc:
        name = exc.parameter if exc.parameter in _MATERIAL_KEYS else next(iter(values), "youngs_modulus")
        raise check.error(f"material.{name}", str(exc).removeprefix(f"{name}: ")) from None


def _build_formulation(check: _Checker, raw: Any) -> tuple[str, dict[str, str]]:
    """``kind`` and the keyword arguments ``volumetric``, ``pressure_mass`` of :class:`Body`."""
    table = check.table(raw, "formulation")
    check.keys(table, tuple(_FORMULATION_DEFAULTS), "formulation")
    values = {}
    for name, allowed in (
        ("kind", FORMULATIONS),
        ("volumetric", VOLUMETRIC_MEASURES),
        ("pressure_mass", PRESSURE_MASSES),
    ):
        value = check.string(table.get(name, _FORMULATION_DEFAULTS[name]), f"formulation.{name}")
        if value not in allowed:
            raise check.error(
                f"formulation.{name}", f"expected one of {', '.join(repr(a) for a in allowed)}, got {value!r}"
            )
        values[name] = value
    kind = values.pop("kind")
    return kind, values


def _select_nodes(check: _Checker, entry: dict[str, Any], prefix: str, mesh: Mesh) -> np.ndarray:
    """Nodes chosen by exactly one of `nodes = [...]` or `box = {min, max}`."""
    if ("nodes" in entry) == ("box" in entry):
        raise check.error(prefix, "expected exactly one of 'nodes' or 'box'")
    if "nodes" in entry:
        raw = entry["nodes"]
        if not isinstance(raw, list):
            raise check.error(f"{prefix}.nodes", f"expected an array of node indices, got {_type_name(raw)}")
        nodes = np.array([check.integer(n, f"{prefix}.nodes", 0) for n in raw], dtype=np.int64)
        if nodes.size and nodes.max() >= mesh.n_nodes:
            raise check.error(
                f"{prefix}.nodes",
                f"node index {int(nodes.max())} out of range: the mesh has {mesh.n_nodes} nodes (0..{mesh.n_nodes - 1})",
            )
        key = f"{prefix}.nodes"
    else:
        box = check.table(entry["box"], f"{prefix}.box", " like { min = [x, y, z], max = [x, y, z] }")
        check.keys(box, ("min", "max"), f"{prefix}.box")
        for required in ("min", "max"):
            if required not in box:
                raise check.error(f"{prefix}.box.{required}", "missing")
        lo = check.vec3(box["min"], f"{prefix}.box.min")
        hi = check.vec3(box["max"], f"{prefix}.box.max")
        if np.any(lo > hi):
            raise check.error(f"{prefix}.box", f"expected min <= max, got min {lo.tolist()}, max {hi.tolist()}")
        nodes = mesh.nodes_in_box(lo, hi)
        key = f"{prefix}.box"
    if nodes.size == 0:
        lo_b, hi_b = mesh.bounds()
        raise check.error(
            key,
            f"selects no nodes (the mesh spans {np.round(lo_b, 6).tolist()} .. {np.round(hi_b, 6).tolist()})",
        )
    return nodes


def _apply_fixed(check: _Checker, raw: Any, body: Body) -> None:
    if isinstance(raw, dict):
        raise check.error("fixed", "expected an array of tables: write [[fixed]], not [fixed]")
    if not isinstance(raw, list):
        raise check.error("fixed", f"expected an array of tables ([[fixed]]), got {_type_name(raw)}")
    if not raw:
        raise check.error("fixed", "at least one [[fixed]] entry is required: an unsupported body has no equilibrium")
    for i, entry in enumerate(raw):
        prefix = f"fixed[{i}]"
        entry = check.table(entry, prefix)
        check.keys(entry, ("nodes", "box", "displacement"), prefix)
        nodes = _select_nodes(check, entry, prefix, body.mesh)
        disp = check.vec3(entry["displacement"], f"{prefix}.displacement") if "displacement" in entry else None
        body.fix(nodes, disp)


def _apply_loads(check: _Checker, raw: Any, body: Body) -> np.ndarray:
    table = check.table(raw, "loads")
    check.keys(table, ("gravity", "forces"), "loads")
    gravity = check.vec3(table["gravity"], "loads.gravity") if "gravity" in table else np.zeros(3)
    forces = table.get("forces", [])
    if not isinstance(forces, list):
        raise check.error("loads.forces", f"expected an array of tables, got {_type_name(forces)}")
    for i, entry in enumerate(forces):
        prefix = f"loads.forces[{i}]"
        entry = check.table(entry, prefix, " like { nodes = [..], force = [fx, fy, fz] }")
        check.keys(entry, ("nodes", "box", "force"), prefix)
        if "force" not in entry:
            raise check.error(f"{prefix}.force", "missing")
        nodes = _select_nodes(check, entry, prefix, body.mesh)
        body.add_force(nodes, check.vec3(entry["force"], f"{prefix}.force"))
    return gravity


def _build_solver(check: _Checker, raw: Any) -> dict[str, Any]:
    table = check.table(raw, "solver")
    check.keys(table, tuple(_SOLVER_DEFAULTS), "solver")
    options = dict(_SOLVER_DEFAULTS)
    if "tolerance" in table:
        options["tolerance"] = check.number(table["tolerance"], "solver.tolerance", minimum=0.0)
    for name in ("max_iterations", "load_steps"):
        if name in table:
            options[name] = check.integer(table[name], f"solver.{name}", 1)
    return options


def _apply_cables(check: _Checker, raw: Any, body: Body) -> list[Cable]:
    """Build each ``[[cable]]`` entry, add it to ``body`` and locate its points in the mesh."""
    if isinstance(raw, dict):
        raise check.error("cable", "expected an array of tables: write [[cable]], not [cable]")
    if not isinstance(raw, list):
        raise check.error("cable", f"expected an array of tables ([[cable]]), got {_type_name(raw)}")
    cables = []
    for i, entry in enumerate(raw):
        prefix = f"cable[{i}]"
        entry = check.table(entry, prefix)
        check.keys(entry, _CABLE_KEYS, prefix)
        if "stiffness" not in entry:
            raise check.error(f"{prefix}.stiffness", "missing: the stiffness of each segment, N/m")
        line_keys = ("start", "direction", "length", "divisions")
        if ("points" in entry) == any(k in entry for k in line_keys):
            raise check.error(prefix, "expected exactly one of 'points' or 'start' + 'direction' + 'length' + 'divisions'")
        options: dict[str, Any] = {}
        for name in ("stiffness", "actuation", "transition", "snap_tolerance", "free_node_mass"):
            if name in entry:
                options[name] = check.number(entry[name], f"{prefix}.{name}")
        if "anchor_first" in entry:
            if not isinstance(entry["anchor_first"], bool):
                raise check.error(f"{prefix}.anchor_first", f"expected true or false, got {_type_name(entry['anchor_first'])}")
            options["anchor_first"] = entry["anchor_first"]
        if "outside" in entry:
            outside = check.string(entry["outside"], f"{prefix}.outside")
            if outside not in OUTSIDE_MODES:
                raise check.error(f"{prefix}.outside", f"expected one of {', '.join(repr(m) for m in OUTSIDE_MODES)}, got {outside!r}")
            options["outside"] = outside
        try:
            if "points" in entry:
                points = entry["points"]
                if not isinstance(points, list) or len(points) < 2:
                    raise check.error(f"{prefix}.points", "expected an array of at least 2 points [x, y, z]")
                cable = Cable([check.vec3(p, f"{prefix}.points") for p in points], **options)
            else:
                for name in line_keys:
                    if name not in entry:
                        raise check.error(f"{prefix}.{name}", "missing (a straight cable needs start, direction, length and divisions)")
                cable = Cable.line(
                    check.vec3(entry["start"], f"{prefix}.start"),
                    check.vec3(entry["direction"], f"{prefix}.direction"),
                    check.number(entry["length"], f"{prefix}.length", minimum=0.0),
                    check.integer(entry["divisions"], f"{prefix}.divisions", 1),
                    **options,
                )
        except ParameterError as exc:
            name = exc.parameter or "points"
            raise check.error(f"{prefix}.{name}", str(exc).removeprefix(f"{name}: ")) from None
        body.add_cable(cable)
        cables.append(cable)
    if cables:
        try:
            body.cable_placements()
        except ParameterError as exc:
            match = re.search(r"cables\[(\d+)\]\.(\w+)", str(exc))
            key = f"cable[{match.group(1)}].{match.group(2)}" if match else "cable"
            raise check.error(key, f"could not place the cable in the mesh: {exc}") from None
    return cables


def _build_dynamics(check: _Checker, raw: Any, body: Body) -> dict[str, Any]:
    table = check.table(raw, "dynamics")
    check.keys(table, ("dt", "steps", *_DYNAMICS_DEFAULTS), "dynamics")
    for required in ("dt", "steps"):
        if required not in table:
            raise check.error(f"dynamics.{required}", "missing")
    options = dict(_DYNAMICS_DEFAULTS)
    options["dt"] = check.number(table["dt"], "dynamics.dt", minimum=0.0)
    options["steps"] = check.integer(table["steps"], "dynamics.steps", 1)
    for name in ("mass_damping", "stiffness_damping"):
        if name in table:
            options[name] = check.number(table[name], f"dynamics.{name}", minimum=0.0, strict=False)
    if "save_every" in table:
        options["save_every"] = check.integer(table["save_every"], "dynamics.save_every", 1)
    if "initial" in table:
        initial = check.string(table["initial"], "dynamics.initial")
        if initial not in ("rest", "static"):
            raise check.error("dynamics.initial", f"expected 'rest' or 'static', got {initial!r}")
        options["initial"] = initial
    if "actuation" in table:
        raw_schedule = table["actuation"]
        n_cables = len(body.cables)
        if not isinstance(raw_schedule, list) or len(raw_schedule) != n_cables:
            shown = f"{len(raw_schedule)} entries" if isinstance(raw_schedule, list) else _type_name(raw_schedule)
            raise check.error(
                "dynamics.actuation",
                f"expected one list of [time, alpha] keyframes per [[cable]] ({n_cables}), got {shown}",
            )
        schedule = []
        for c, frames in enumerate(raw_schedule):
            key = f"dynamics.actuation[{c}]"
            if not isinstance(frames, list) or not frames or not all(isinstance(f, list) and len(f) == 2 for f in frames):
                raise check.error(key, "expected a non-empty array of [time, alpha] pairs")
            values = [[check.number(t, key), check.number(a, key, minimum=0.0)] for t, a in frames]
            try:
                schedule.append(Keyframes(values))
            except InputError as exc:
                raise check.error(key, str(exc)) from None
        options["actuation"] = schedule
    return options


def _points(check: _Checker, value: Any, key: str) -> np.ndarray:
    if not isinstance(value, list) or not value:
        raise check.error(key, f"expected a non-empty array of [x, y, z] points, got {_type_name(value)}")
    return np.array([check.vec3(p, key) for p in value])


def _build_target(check: _Checker, raw: Any, body: Body, base: Path) -> Target:
    table = check.table(raw, "target")
    check.keys(table, ("nodes", "points", "positions", "surface", "scale", "rest"), "target")
    given = [k for k in ("nodes", "points", "surface") if k in table]
    if len(given) != 1:
        raise check.error("target", "expected exactly one of 'nodes', 'points' or 'surface'")
    kind = given[0]
    if kind == "surface":
        for name in ("positions",):
            if name in table:
                raise check.error(f"target.{name}", "not allowed with 'surface' (the goal is the surface)")
        files = {}
        for name in ("surface", "rest"):
            if name in table:
                file = Path(check.string(table[name], f"target.{name}"))
                file = file if file.is_absolute() else base / file
                if not file.is_file():
                    raise check.error(f"target.{name}", f"surface file not found: {file}")
                files[name] = file
        scale = check.number(table["scale"], "target.scale", minimum=0.0) if "scale" in table else 1.0
        key = "target.surface"
        try:
            target = Target.surface(files["surface"], scale, rest=files.get("rest"))
        except InputError as exc:
            raise check.error(key, str(exc)) from None
    else:
        for name in ("scale", "rest"):
            if name in table:
                raise check.error(f"target.{name}", "only allowed with 'surface'")
        if "positions" not in table:
            raise check.error("target.positions", f"missing: the goal position of each of the target's {kind}")
        positions = _points(check, table["positions"], "target.positions")
        if kind == "nodes":
            raw_nodes = table["nodes"]
            if not isinstance(raw_nodes, list) or not raw_nodes:
                raise check.error("target.nodes", f"expected a non-empty array of node indices, got {_type_name(raw_nodes)}")
            nodes = np.array([check.integer(n, "target.nodes", 0) for n in raw_nodes], dtype=np.int64)
            if nodes.max() >= body.mesh.n_nodes:
                raise check.error(
                    "target.nodes",
                    f"node index {int(nodes.max())} out of range: the mesh has {body.mesh.n_nodes} nodes",
                )
            rest = nodes
        else:
            rest = _points(check, table["points"], "target.points")
        if len(positions) != len(rest):
            raise check.error("target.positions", f"expected {len(rest)} positions, one per entry of '{kind}', got {len(positions)}")
        key = f"target.{kind}"
        try:
            target = Target.nodes(rest, positions) if kind == "nodes" else Target.points(rest, positions)
        except InputError as exc:
            raise check.error(key, str(exc)) from None
    try:
        target.bind(body.mesh)
    except InputError as exc:
        raise check.error(key, str(exc)) from None
    return target


def _number_list(check: _Checker, value: Any, key: str) -> list[Any]:
    """An array of numbers (or of arrays of numbers, for field / cable parameters)."""
    if not isinstance(value, list) or not value:
        raise check.error(key, f"expected a non-empty array, got {_type_name(value)}")
    return [
        [check.number(x, key) for x in v] if isinstance(v, list) else check.number(v, key) for v in value
    ]


def _bounds(check: _Checker, value: Any, key: str, count: int, what: str) -> list[tuple[float, float]]:
    if not isinstance(value, list) or len(value) != count:
        shown = f"{len(value)} entries" if isinstance(value, list) else _type_name(value)
        raise check.error(key, f"expected one [lo, hi] per {what} ({count}), got {shown}")
    out = []
    for pair in value:
        if not isinstance(pair, list) or len(pair) != 2:
            raise check.error(key, f"expected [lo, hi] pairs, got {pair!r}")
        lo, hi = check.number(pair[0], key), check.number(pair[1], key)
        if lo >= hi:
            raise check.error(key, f"expected lo < hi, got [{lo:g}, {hi:g}]")
        out.append((lo, hi))
    return out


def _method(check: _Checker, table: dict[str, Any], key: str, allowed: tuple[str, ...]) -> str:
    method = check.string(table.get("method", allowed[0]), key)
    if method not in allowed:
        raise check.error(key, f"expected one of {', '.join(repr(m) for m in allowed)}, got {method!r}")
    return method


def _build_estimate(check: _Checker, raw: Any) -> dict[str, Any]:
    from .inverse import PARAMETERS

    table = check.table(raw, "estimate")
    check.keys(table, ("params", "x0", "bounds", "method", "starts"), "estimate")
    for required in ("params", "x0"):
        if required not in table:
            raise check.error(f"estimate.{required}", "missing")
    names = table["params"]
    if not isinstance(names, list) or not names:
        raise check.error("estimate.params", f"expected a non-empty array of parameter names, got {_type_name(names)}")
    names = [check.string(n, "estimate.params") for n in names]
    for n in names:
        if n.partition(":")[0] not in PARAMETERS or ":" in n:
            raise check.error("estimate.params", f"unknown parameter {n!r} (expected one of {', '.join(PARAMETERS)})")
    x0 = _number_list(check, table["x0"], "estimate.x0")
    if len(x0) != len(names):
        raise check.error("estimate.x0", f"expected {len(names)} value(s), one per parameter, got {len(x0)}")
    bounds = _bounds(check, table["bounds"], "estimate.bounds", len(names), "parameter") if "bounds" in table else None
    starts = check.integer(table["starts"], "estimate.starts", 0) if "starts" in table else None
    return {
        "params": names, "x0": x0, "bounds": bounds,
        "method": _method(check, table, "estimate.method", _ESTIMATE_METHODS), "starts": starts or None,
    }


def _build_control(check: _Checker, raw: Any, body: Body) -> dict[str, Any]:
    table = check.table(raw, "control")
    check.keys(table, ("cables", "bounds", "method"), "control")
    n = len(body.cables)
    if n == 0:
        raise check.error("control", "needs at least one [[cable]] entry")
    if "cables" in table:
        raw_cables = table["cables"]
        if not isinstance(raw_cables, list) or not raw_cables:
            raise check.error("control.cables", f"expected a non-empty array of cable indices, got {_type_name(raw_cables)}")
        cables = [check.integer(c, "control.cables", 0) for c in raw_cables]
        if max(cables) >= n:
            raise check.error("control.cables", f"cable index {max(cables)} out of range: the scene has {n} cable(s)")
        if len(set(cables)) != len(cables):
            raise check.error("control.cables", "a cable is listed twice")
    else:
        cables = list(range(n))
    bounds = _bounds(check, table["bounds"], "control.bounds", len(cables), "cable") if "bounds" in table else None
    if bounds is not None and any(lo <= 0 for lo, _ in bounds):
        raise check.error("control.bounds", "expected actuation bounds > 0")
    return {"cables": cables, "bounds": bounds, "method": _method(check, table, "control.method", _CONTROL_METHODS)}
