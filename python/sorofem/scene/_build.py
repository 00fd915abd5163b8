"""Building a scene's objects from its checked tables: what the schema cannot check (the mesh,
other files, counts, indices in range), with errors that name the key."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .._files import check_path
from .._validate import MAX_MAGNITUDE
from ..body import Body
from ..cables import Cable
from ..dynamics import Keyframes
from ..errors import InputError, ParameterError
from ..io import read_mesh, read_points
from ..materials import Material, material_class
from ..mesh import Mesh
from ..meshing import INSTALL_HINT, MESHER, mesher_available, tetrahedralize
from ..obstacles import Box, Obstacle, Plane, Sphere
from ..plot import COLOR_FIELDS
from ..targets import Target
from ._keys import CABLE_OPTIONS, MATERIAL_KEYS
from ._spec import Checker, quoted

__all__ = ["build_mesh", "build_material", "apply_fixed", "apply_loads", "apply_cables", "apply_obstacles",
           "set_cable_command", "build_dynamics",
           "build_output", "build_target", "observed_rest", "build_estimate", "build_control", "existing_file"]


def existing_file(check: Checker, key: str, name: str, base: Path, what: str) -> Path:
    """``name`` resolved against the scene file's folder (checked as a path first); it must exist."""
    file = _path(check, name, key, base)
    if not file.is_file():
        raise check.error(key, f"{what} not found: {file}")
    return file


def build_mesh(check: Checker, table: dict[str, Any], base: Path) -> Mesh:
    scale = table["scale"]
    if "file" in table:
        file = existing_file(check, "mesh.file", table["file"], base, "mesh file")
        try:
            mesh = read_mesh(file, scale=scale)
        except InputError as exc:
            raise check.error("mesh.file", f"could not read the mesh: {exc}") from None
    elif "surface" in table:
        file = existing_file(check, "mesh.surface", table["surface"], base, "surface file")
        if not mesher_available():
            raise check.error("mesh.surface", f"filling a surface with tetrahedra needs the optional mesher "
                              f"{MESHER}: {INSTALL_HINT}")
        try:
            mesh = tetrahedralize(file, table.get("edge_length"), scale=scale)
        except ParameterError as exc:
            key = "mesh.edge_length" if exc.parameter == "edge_length" else "mesh.surface"
            raise check.error(key, str(exc).removeprefix("edge_length: ")) from None
        except InputError as exc:
            raise check.error("mesh.surface", f"could not fill the surface with tetrahedra: {exc}") from None
    else:
        box = table["box"]
        mesh = Mesh.box(size=np.array(box["size"]) * scale, cells=box["cells"], origin=np.array(box["origin"]) * scale)
    axes = table["axes"]
    if [a.lstrip("+") for a in axes] != ["x", "y", "z"]:
        try:
            mesh = mesh.transformed(axes)
        except ParameterError as exc:
            raise check.error("mesh.axes", str(exc).removeprefix("axes: ")) from None
    return mesh


def _path(check: Checker, name: str, key: str, base: Path, expand: bool = False) -> Path:
    """A file named in the scene, relative to the scene's folder (``expand``: ``~`` is the home
    folder); checked as a path first."""
    try:
        file = check_path(name, key)
    except InputError as exc:
        raise check.error(key, str(exc).removeprefix(f"{key}: ")) from None
    file = file.expanduser() if expand else file
    file = file if file.is_absolute() else base / file
    try:
        return check_path(file, key)
    except InputError as exc:
        raise check.error(key, str(exc).removeprefix(f"{key}: ")) from None


def _box_bounds(check: Checker, box: dict[str, Any], key: str) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = np.array(box["min"]), np.array(box["max"])
    if np.any(lo > hi):
        raise check.error(key, f"expected min <= max, got min {lo.tolist()}, max {hi.tolist()}")
    return lo, hi


def _span(mesh: Mesh) -> str:
    lo, hi = mesh.bounds
    return f"the mesh spans {np.round(lo, 6).tolist()} .. {np.round(hi, 6).tolist()}"


def _keyword_arguments(values: dict[str, Any]) -> dict[str, Any]:
    """Material values by parameter name as the class's keywords: Ogden's ``"mu:0"``,
    ``"mu:1"`` -> ``mu=[...]`` in term order."""
    out: dict[str, Any] = {}
    terms: dict[str, dict[int, Any]] = {}
    for name, value in values.items():
        base, vector, index = name.partition(":")
        if vector:
            terms.setdefault(base, {})[int(index)] = value
        else:
            out[name] = value
    return out | {base: [by_index[i] for i in sorted(by_index)] for base, by_index in terms.items()}


def _new_material(check: Checker, cls: type[Material], values: dict[str, Any], key: str) -> Material:
    try:
        return cls(**_keyword_arguments(values))
    except ParameterError as exc:
        name = exc.parameter if exc.parameter in values else next(iter(values), "youngs_modulus")
        raise check.error(f"{key}.{name}", str(exc).removeprefix(f"{name}: ")) from None


def _given(table: dict[str, Any]) -> dict[str, Any]:
    return {k: table[k] for k in MATERIAL_KEYS if k in table}


def build_material(
    check: Checker, table: dict[str, Any], mesh: Mesh, formulation: str
) -> tuple[Material, dict[str, np.ndarray], np.ndarray | None]:
    """The material (per-element with regions), the named regions' elements and each element's
    entry (-1: ``[material]`` itself)."""
    cls = material_class(table["model"])
    base = _new_material(check, cls, _given(table), "material")
    entries = table["region"]
    if not entries:
        return base, {}, None
    m = mesh.n_tets
    centroids = mesh.points[mesh.tets].mean(axis=1)
    owner = np.full(m, -1, dtype=np.int64)
    materials: list[Material] = []
    names: dict[str, int] = {}
    for i, entry in enumerate(entries):
        prefix = f"material.region[{i}]"
        given = _given(entry)
        if not given and "name" not in entry:
            raise check.error(
                prefix, f"gives no material value and no name: expected any of {', '.join(quoted(MATERIAL_KEYS))} "
                "(the others are inherited from [material]), or a name for [estimate]",
            )
        if "name" in entry:
            if entry["name"] in names:
                raise check.error(
                    f"{prefix}.name", f"{entry['name']!r} is already the name of material.region[{names[entry['name']]}]"
                )
            names[entry["name"]] = i
        # Values not given are the base material's, in the form the entry uses.
        form = next((f for f in base.model.forms if set(given) & set(f.names)), base.form)
        values = {**{n: base.value(n) for n in form.names}, "density": base.density, **given}
        materials.append(_new_material(check, cls, values, prefix))
        if "cells" in entry:
            cells = np.array(entry["cells"], dtype=np.int64)
            if cells.max() >= m:
                raise check.error(
                    f"{prefix}.cells",
                    f"element index {int(cells.max())} out of range: the mesh has {m} tets (0..{m - 1})",
                )
            owner[cells] = i
        else:
            lo, hi = _box_bounds(check, entry["box"], f"{prefix}.box")
            inside = np.all((centroids >= lo) & (centroids <= hi), axis=1)
            if not inside.any():
                raise check.error(
                    f"{prefix}.box", f"selects no elements: no element centroid is inside ({_span(mesh)})"
                )
            owner[inside] = i
    for i in range(len(entries)):
        if not np.any(owner == i):
            raise check.error(
                f"material.region[{i}]",
                "has no element left: every element it selects is overridden by later [[material.region]] entries",
            )
    every = [base, *materials]  # every[owner + 1] is an element's material
    for i, mat in enumerate(every):
        if i == 0 and not np.any(owner == -1):
            continue
        try:
            mat.check_formulation(formulation, 1)
        except ParameterError as exc:
            entry, prefix = (table, "material") if i == 0 else (entries[i - 1], f"material.region[{i - 1}]")
            key = f"{prefix}.{exc.parameter}" if exc.parameter in entry else prefix
            raise check.error(key, str(exc).removeprefix(f"{exc.parameter}: ")) from None
    # One form for every entry: theirs if they agree, else the core's.
    forms = {mat.form.names for mat in every}
    names_out = forms.pop() if len(forms) == 1 else base.model.core_form.names
    arrays = {a: np.array([mat.value(a) for mat in every])[owner + 1] for a in (*names_out, "density")}
    material = cls(**_keyword_arguments(arrays))
    regions = {name: np.flatnonzero(owner == i).astype(np.int64) for name, i in names.items()}
    return material, regions, owner


def _select_nodes(check: Checker, entry: dict[str, Any], prefix: str, mesh: Mesh) -> np.ndarray:
    """Nodes chosen by `nodes = [...]` or `box = {min, max}` (the schema makes it exactly one)."""
    if "nodes" in entry:
        nodes = np.array(entry["nodes"], dtype=np.int64)
        if nodes.max() >= mesh.n_nodes:
            raise check.error(
                f"{prefix}.nodes",
                f"node index {int(nodes.max())} out of range: "
                f"the mesh has {mesh.n_nodes} nodes (0..{mesh.n_nodes - 1})",
            )
        key = f"{prefix}.nodes"
    else:
        lo, hi = _box_bounds(check, entry["box"], f"{prefix}.box")
        nodes = mesh.nodes_in_box(lo, hi)
        key = f"{prefix}.box"
    if nodes.size == 0:
        raise check.error(key, f"selects no nodes ({_span(mesh)})")
    return nodes


def apply_fixed(check: Checker, entries: list[dict[str, Any]], body: Body) -> None:
    for i, entry in enumerate(entries):
        body.fix(_select_nodes(check, entry, f"fixed[{i}]", body.mesh), entry["displacement"])


def apply_loads(check: Checker, table: dict[str, Any], body: Body) -> np.ndarray:
    for i, entry in enumerate(table["forces"]):
        body.add_force(_select_nodes(check, entry, f"loads.forces[{i}]", body.mesh), entry["force"])
    return np.array(table["gravity"])


def apply_obstacles(
    check: Checker, entries: list[dict[str, Any]], contact: dict[str, Any], body: Body, base: Path
) -> list[Path]:
    """Build each ``[[obstacle]]`` entry and add it to ``body`` with the ``[contact]`` settings;
    returns the surface files read."""
    files = []
    try:
        body.set_contact(**contact)
    except ParameterError as exc:
        raise check.error(f"contact.{exc.parameter or 'dhat'}", str(exc)) from None
    names: dict[str, int] = {}
    for i, entry in enumerate(entries):
        prefix = f"obstacle[{i}]"
        if "name" in entry:
            if entry["name"] in names:
                raise check.error(f"{prefix}.name", f"{entry['name']!r} already names obstacle[{names[entry['name']]}]; "
                                  "expected a unique name")
            names[entry["name"]] = i
        obstacle: Obstacle
        if "plane" in entry:
            key = f"{prefix}.plane"
            make = lambda: Plane(entry["plane"]["point"], entry["plane"]["normal"])  # noqa: E731
        elif "sphere" in entry:
            key = f"{prefix}.sphere"
            make = lambda: Sphere(entry["sphere"]["center"], entry["sphere"]["radius"])  # noqa: E731
        elif "box" in entry:
            key = f"{prefix}.box"
            make = lambda: Box(entry["box"]["min"], entry["box"]["max"])  # noqa: E731
        else:
            key = f"{prefix}.mesh.file"
            table = entry["mesh"]
            file = existing_file(check, key, table["file"], base, "surface file")
            files.append(file)
            make = lambda: Obstacle.mesh(file, table["scale"], one_sided=table["one_sided"])  # noqa: E731
        try:
            obstacle = make()
        except InputError as exc:
            raise check.error(key, str(exc)) from None
        try:
            body.add_obstacle(obstacle, entry["friction"], path=entry["path"])
        except InputError as exc:
            raise check.error(prefix, str(exc)) from None
    return files


def _contact_force_target(check: Checker, table: dict[str, Any], body: Body,
                          obstacles: Sequence[dict[str, Any]]) -> Target:
    """``[target] contact_force``: the obstacle by name or index, bound to the body."""
    key = "target.contact_force.obstacle"
    which = table["obstacle"]
    names = [entry.get("name") for entry in obstacles]
    if isinstance(which, str):
        if which not in names:
            given = [n for n in names if n is not None]
            raise check.error(key, f"no [[obstacle]] is named {which!r}; "
                              + (f"expected one of {given}" if given else "give the [[obstacle]] a name = ...")
                              + " or its index")
        index = names.index(which)
    else:
        index = which
        if index >= len(obstacles):
            raise check.error(key, f"obstacle index {index} out of range: the scene has {len(obstacles)} [[obstacle]] "
                              "entries")
    try:
        target = Target.contact_force(index, table["force"])
        target.bind(body.mesh, body=body)
    except InputError as exc:
        raise check.error("target.contact_force", str(exc)) from None
    return target


def apply_cables(check: Checker, entries: list[dict[str, Any]], body: Body) -> list[Cable]:
    """Build each ``[[cable]]`` entry, add it to ``body`` and locate its points in the mesh."""
    cables = []
    for i, entry in enumerate(entries):
        prefix = f"cable[{i}]"
        options = {name: entry[name] for name in CABLE_OPTIONS}
        if entry["model"] == "tendon" and (entry["pull"] is None) == (entry["tension"] is None):
            raise check.error(f"{prefix}.pull", "a tendon needs exactly one of pull (m) and tension (N)")
        try:
            if "points" in entry:
                cable = Cable(entry["points"], **options)
            else:
                cable = Cable.line(entry["start"], entry["direction"], entry["length"], entry["divisions"], **options)
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


def set_cable_command(check: Checker, prefix: str, entry: dict[str, Any], body: Body, cable: int) -> None:
    """Give ``body``'s cable ``cable``, already built, the per-solve values of its ``[[cable]]``
    entry: a spring chain's actuation and stiffness, a tendon's pull or tension (exactly one).
    What a scene built ``like`` another does instead of building its cables."""
    if entry["model"] != "tendon":
        body.set_actuation(cable, entry["actuation"])
        body.set_cable_stiffness(cable, entry["stiffness"])
        return
    if (entry["pull"] is None) == (entry["tension"] is None):
        raise check.error(f"{prefix}.pull", "a tendon needs exactly one of pull (m) and tension (N)")
    name = "pull" if entry["pull"] is not None else "tension"
    try:
        if name == "pull":
            body.pull(cable, displacement=entry["pull"])
        else:
            body.pull(cable, tension=entry["tension"])
    except ParameterError as exc:
        raise check.error(f"{prefix}.{name}", str(exc).removeprefix(f"{exc.parameter}: ")) from None


def build_dynamics(check: Checker, table: dict[str, Any], body: Body) -> dict[str, Any]:
    options = dict(table)
    if not table["dt"] * table["steps"] <= MAX_MAGNITUDE:
        raise check.error("dynamics.dt", f"the simulated time dt * steps is {table['dt'] * table['steps']:g} s, above "
                          f"the documented limit {MAX_MAGNITUDE:g} s")
    schedule = table["actuation"]
    if schedule is not None:
        n_cables = len(body.cables)
        if len(schedule) != n_cables:
            raise check.error(
                "dynamics.actuation",
                f"expected one list of [time, value] keyframes per [[cable]] ({n_cables}), got {len(schedule)} entries",
            )
        options["actuation"] = []
        for c, frames in enumerate(schedule):
            try:
                options["actuation"].append(Keyframes(frames))
            except InputError as exc:
                raise check.error(f"dynamics.actuation[{c}]", str(exc)) from None
            values = [value for _, value in frames]
            kind = body.commands[c][0]
            if kind == "actuation" and min(values) <= 0:
                raise check.error(f"dynamics.actuation[{c}]", f"alphas must be > 0, got {min(values):g}")
            if kind == "tension" and min(values) < 0:
                raise check.error(f"dynamics.actuation[{c}]", f"tensions must be >= 0 N, got {min(values):g}")
            if kind == "pull" and max(values) >= body.cables[c].length:
                raise check.error(f"dynamics.actuation[{c}]", f"pulls must stay below the tendon's rest length "
                                  f"{body.cables[c].length:.6g} m, got {max(values):g} m")
    return options


def build_output(check: Checker, table: dict[str, Any], formulation: str, base: Path) -> dict[str, Any]:
    out = dict(table)
    if "directory" in out:
        if not out["directory"].strip():
            raise check.error("output.directory", "expected a folder name, got an empty string")
        out["directory"] = _path(check, out["directory"], "output.directory", base, expand=True)
    else:
        out["directory"] = None
    if out["color_by"] == "pressure" and formulation != "mixed":
        raise check.error(
            "output.color_by",
            f"'pressure' needs [formulation] kind = \"mixed\": the {formulation} formulation has no pressure field "
            f"(choose one of {', '.join(repr(f) for f in COLOR_FIELDS if f != 'pressure')})",
        )
    return out


def build_target(
    check: Checker, table: dict[str, Any], body: Body, base: Path, obstacles: Sequence[dict[str, Any]] = ()
) -> tuple[Target, list[Path]]:
    """The target, and the surface files it was read from (``obstacles``: the ``[[obstacle]]``
    entries a contact force may name)."""
    files: dict[str, Path] = {}
    if "contact_force" in table:
        return _contact_force_target(check, table["contact_force"], body, obstacles), []
    if "surface" in table:
        for name in ("surface", "rest"):
            if name in table:
                file = _path(check, table[name], f"target.{name}", base)
                if not file.is_file():
                    raise check.error(f"target.{name}", f"surface file not found: {file}")
                files[name] = file
        key = "target.surface"
        try:
            target = Target.surface(files["surface"], table["scale"], rest=files.get("rest"))
        except InputError as exc:
            raise check.error(key, str(exc)) from None
    else:
        kind = "nodes" if "nodes" in table else "points"
        if "positions_file" in table:
            files["positions_file"] = existing_file(check, "target.positions_file", table["positions_file"], base,
                                                    "points file")
            try:
                positions = read_points(files["positions_file"])
            except InputError as exc:
                raise check.error("target.positions_file", str(exc)) from None
        elif "positions" in table:
            positions = np.array(table["positions"])
        else:
            raise check.error("target.positions", f"missing: expected the goal of each of '{kind}' as positions = "
                              "[[x, y, z], ...] or positions_file = \"markers.csv\" (or, with [dynamics], a recorded "
                              "motion as tracks or tracks_file)")
        rest = observed_rest(check, table, body)
        if len(positions) != len(rest):
            where = "target.positions_file" if "positions_file" in table else "target.positions"
            raise check.error(
                where, f"expected {len(rest)} positions, one per entry of '{kind}', got {len(positions)}"
            )
        key = f"target.{kind}"
        try:
            target = Target.nodes(rest, positions) if kind == "nodes" else Target.points(rest, positions)
        except InputError as exc:
            raise check.error(key, str(exc)) from None
    try:
        target.bind(body.mesh)
    except InputError as exc:
        raise check.error(key, str(exc)) from None
    return target, list(files.values())


def observed_rest(check: Checker, table: dict[str, Any], body: Body) -> np.ndarray:
    """The ``[target]`` nodes ``(k,)`` int64, checked to be in the mesh, or points ``(k, 3)`` (m)."""
    if "nodes" not in table:
        return np.array(table["points"], dtype=np.float64)
    nodes = np.array(table["nodes"], dtype=np.int64)
    if nodes.max() >= body.mesh.n_nodes:
        raise check.error("target.nodes",
                          f"node index {int(nodes.max())} out of range: the mesh has {body.mesh.n_nodes} nodes")
    return nodes


def _bounds(
    check: Checker, value: list[list[float]] | None, key: str, count: int, what: str
) -> list[tuple[float, float]] | None:
    if value is None:
        return None
    if len(value) != count:
        raise check.error(key, f"expected one [lo, hi] per {what} ({count}), got {len(value)} entries")
    for lo, hi in value:
        if lo >= hi:
            raise check.error(key, f"expected lo < hi, got [{lo:g}, {hi:g}]")
    return [(lo, hi) for lo, hi in value]


def build_estimate(check: Checker, table: dict[str, Any], regions: dict[str, np.ndarray]) -> dict[str, Any]:
    names = table["params"]
    for n in names:
        kind, _, region = n.partition(":")
        if region and region not in regions:
            named = ", ".join(repr(r) for r in regions) or "none"
            raise check.error(
                "estimate.params",
                f"{n!r} names region {region!r}, which is not the name of a [[material.region]] entry (named: {named})",
            )
    if len(set(names)) != len(names):
        raise check.error("estimate.params", "a parameter is listed twice")
    x0 = table["x0"]
    if len(x0) != len(names):
        raise check.error("estimate.x0", f"expected {len(names)} value(s), one per parameter, got {len(x0)}")
    return {
        "params": names,
        "x0": x0,
        "bounds": _bounds(check, table["bounds"], "estimate.bounds", len(names), "parameter"),
        "method": table["method"],
        "starts": table["starts"] or None,
    }


def build_control(check: Checker, table: dict[str, Any], body: Body) -> dict[str, Any]:
    n = len(body.cables)
    if n == 0:
        raise check.error("control", "needs at least one [[cable]] entry")
    cables = table["cables"]
    if cables is not None:
        if max(cables) >= n:
            raise check.error("control.cables", f"cable index {max(cables)} out of range: the scene has {n} cable(s)")
        if len(set(cables)) != len(cables):
            raise check.error("control.cables", "a cable is listed twice")
    else:
        cables = list(range(n))
    bounds = _bounds(check, table["bounds"], "control.bounds", len(cables), "cable")
    kinds = [body.commands[c][0] for c in cables]
    for c, kind, pair in zip(cables, kinds, bounds or [None] * len(cables)):
        if pair is None:
            if kind == "tension":
                raise check.error("control.bounds", f"cable {c} is a tendon driven by its tension: give its [lo, hi] in N")
            continue
        lo, hi = pair
        if kind == "actuation" and lo <= 0:
            raise check.error("control.bounds", f"cable {c}: an alpha range needs lo > 0, got [{lo:g}, {hi:g}]")
        if kind == "tension" and lo < 0:
            raise check.error("control.bounds", f"cable {c}: a tension range needs lo >= 0 N, got [{lo:g}, {hi:g}]")
        if kind == "pull" and hi >= body.cables[c].length:
            raise check.error("control.bounds", f"cable {c}: a pull range must stay below the tendon's rest length "
                                                f"{body.cables[c].length:.6g} m, got hi = {hi:g} m")
    return {
        "cables": cables,
        "bounds": bounds,
        "method": table["method"],
    }
