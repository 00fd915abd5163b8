"""Every key of a scene file, written once, as data: its type, range, default, meaning, units and
the value the annotated example shows.

The validator (:meth:`sorofem.Scene.from_toml`), :func:`json_schema` (``docs/scene.schema.json``,
``sorofem schema``), the annotated schema in :mod:`sorofem.scene`'s docstring and README.md's key
table (:mod:`sorofem.scene.generate`) all read :data:`SCENE`. Where the values are declared
elsewhere they are read from there: material parameters from :mod:`sorofem.materials`, solver
options from :class:`sorofem.solver.SolveOptions`, cable options from :class:`sorofem.Cable`,
formulations from :mod:`sorofem.body`, estimable parameters from :mod:`sorofem.inverse`.
"""

from __future__ import annotations

import inspect
import json
from dataclasses import fields
from pathlib import Path
from typing import Any

from .._validate import MAX_CABLE_DIVISIONS, MAX_STARTS, MAX_TIME_STEPS, Range
from ..body import FORMULATIONS, PRESSURE_MASSES, VOLUMETRIC_MEASURES, Body
from ..cables import CABLE_MODELS, OUTSIDE_MODES, Cable
from ..inverse import MOTION_PARAMETERS, parameter_names
from ..materials import DENSITY, MODELS, NEO_HOOKEAN, MaterialModel, Parameter
from ..mesh import Mesh
from ..plot import COLOR_FIELDS
from ..solver import SolveOptions
from ._spec import (
    NO_DEFAULT,
    Array,
    Boolean,
    Checker,
    Choice,
    Either,
    Field,
    Group,
    Integer,
    Number,
    String,
    Table,
    Tables,
    Tuple,
)

__all__ = ["SCENE", "TOP_KEYS", "MATERIAL_KEYS", "CABLE_OPTIONS", "json_schema", "schema_text", "defaults"]

_VEC3 = Array(Number(), 3, 3)
_POINTS = Array(_VEC3, 1, noun="[x, y, z] points")
_NODES = Array(Integer(ge=0), 1)
#: Names of regions and of ``"shear_modulus:NAME"`` parameters.
_NAME = r"[A-Za-z_][A-Za-z0-9_\-]*"
_BOX_HINT = " like { min = [x, y, z], max = [x, y, z] }"


def _box(what: str) -> Table:
    return Table(
        {
            "min": Field(_VEC3, "lowest corner", "m", required=True),
            "max": Field(_VEC3, "highest corner (>= min)", "m", required=True),
        },
        hint=_BOX_HINT,
        doc=f"Closed axis-aligned box: {what} inside it (boundary included).",
    )


_NODE_BOX = _box("the nodes")
_SELECT_NODES = Choice((Group(("nodes",)), Group(("box",))))

# -- [material]: from the model declarations ---------------------------------------------------


def _parameter_doc(model: MaterialModel, p: Parameter) -> str:
    """``Young's modulus E (with poisson_ratio)``, plus any stricter range of a formulation."""
    partners = next((f.names for f in model.forms if p.name in f.names), (p.name,))
    others = [n for n in partners if n != p.name]
    text = f"{p.doc} {p.symbol}"
    for formulation, strict in p.formulation_ranges:
        text += f", {strict.describe()} for kind = \"{formulation}\""
    return text + (f" (with {', '.join(others)})" if others else "")


def _material_values(live: dict[str, Any], commented: dict[str, Any] | None = None) -> dict[str, Field]:
    """A Field per parameter of every model, the forms' order reversed (Young's modulus first),
    shown in the annotated example live (``live``), commented out (``commented``) or not at all."""
    commented = commented or {}
    out: dict[str, Field] = {}
    for model in MODELS.values():
        for form in model.forms[::-1]:
            for name in form.names:
                p = model.parameter(name)
                example = live.get(name, commented.get(name, NO_DEFAULT))
                out.setdefault(name, Field(
                    Number(p.range), _parameter_doc(model, p), p.units, example=example, commented=name not in live,
                ))
    return out


def _optional(model: MaterialModel, name: str) -> bool:
    """A key a table may leave out: a parameter with a default (Yeoh's d2, d3: no such term) or
    an Ogden term after the first (a model of fewer terms)."""
    base, vector, index = name.partition(":")
    return model.parameter(name).default is not None or (bool(vector) and index != "0")


#: Every way to give a material, over all models: exactly one per table.
_MATERIAL_FORMS = tuple(
    Group(tuple(n for n in form.names if not _optional(model, n)), tuple(n for n in form.names if _optional(model, n)))
    for model in MODELS.values()
    for form in model.forms[::-1]
)
#: The material values a table may hold (every model's parameters, and density).
MATERIAL_KEYS = tuple(_material_values({})) + (DENSITY.name,)

_REGION = Table(
    {
        "name": Field(
            String(pattern=_NAME, pattern_doc="a name of letters, digits, '_' and '-'"),
            "name of the region, unique; [estimate] params may then name it, e.g. \"shear_modulus:NAME\"",
            example="tip",
        ),
        "box": Field(_box("the elements whose centroid lies"), "select the elements whose centroid is in this box",
                     "m", example={"min": [0.3, -1, -1], "max": [0.4, 1, 1]}),
        "cells": Field(Array(Integer(ge=0), 1), "select these elements (tetrahedron indices, 0-based)",
                       example=[0, 1, 2], commented=True),
        **_material_values({"youngs_modulus": 132e3}),
        "density": Field(Number(DENSITY.range), "density rho of these elements", DENSITY.units),
    },
    choices=(
        Choice((Group(("box",)), Group(("cells",)))),
        Choice(_MATERIAL_FORMS, required=False, partial=True),
    ),
    doc="Other material values for some elements; values not given are the [material] table's, and a later "
    "entry overrides an earlier one where they overlap.",
)

_MATERIAL = Table(
    {
        "model": Field(String(tuple(MODELS)), "the material model (sorofem.materials.MODELS)",
                       default=NEO_HOOKEAN.name),
        **_material_values({"youngs_modulus": 66e3, "poisson_ratio": 0.45},
                           {"shear_modulus": 22.76e3, "lame_lambda": 0.2048e6}),
        "density": Field(
            Number(DENSITY.range), "density rho (only matters under gravity and in dynamics)", DENSITY.units,
            default=0.0, example=1080,
        ),
        "region": Field(
            Tables(_REGION, "material.region"),
            "[[material.region]] entries: per-element materials (see the entry's description)",
            default=[], see=("Materials per region", "#materials-per-region"),
        ),
    },
    choices=(Choice(_MATERIAL_FORMS),),
    doc="The material: " + "; ".join(
        f"{m.title}, exactly one of " + " or ".join(" + ".join(f.names) for f in m.forms[::-1])
        for m in MODELS.values()
    ) + ".",
)

# -- the other sections ------------------------------------------------------------------------

_MESH = Table(
    {
        "file": Field(String(), "mesh file, relative to the scene file: .tet or any volume format meshio reads",
                      example="beam.vtu"),
        "box": Field(
            Table(
                {
                    "size": Field(Array(Number(Range(gt=0)), 3, 3), "edge lengths [x, y, z]", "m", required=True,
                                  example=[1.0, 0.1, 0.1]),
                    "cells": Field(Array(Integer(ge=1), 3, 3), "hexahedral cells along x, y, z (6 tets each)",
                                   required=True, example=[8, 2, 2]),
                    "origin": Field(_VEC3, "lowest corner", "m", default=[0.0, 0.0, 0.0]),
                },
                hint=" like { size = [1, 0.1, 0.1], cells = [8, 2, 2] }",
                doc="A box meshed with nx * ny * nz hexahedra of 6 tetrahedra each.",
            ),
            "a box mesh instead of a file", example={"size": [1.0, 0.1, 0.1], "cells": [8, 2, 2]}, commented=True,
        ),
        "surface": Field(
            String(), "closed triangle surface (.stl, .obj, .ply, .off), relative to the scene file, filled with "
            "tetrahedra by sf.tetrahedralize (fTetWild: the optional extra 'mesh')", example="robot.stl", commented=True,
            see=("From a surface to a simulation", "#from-a-surface-to-a-simulation"),
        ),
        "edge_length": Field(
            Number(Range(gt=0)), "target edge length of the tetrahedra filling surface, after scale (default: 1/20 of "
            "the bounding-box diagonal)", "m", example=0.004, commented=True,
        ),
        "scale": Field(Number(Range(gt=0)), "multiplies all coordinates (for box: size and origin)", default=1.0),
        "axes": Field(
            Array(String(Mesh.AXIS_NAMES), 3, 3),
            "after scale, new axis i is old axis axes[i], with its sign: a signed permutation of x, y, z; "
            "[\"x\", \"-z\", \"y\"] turns a y-up mesh into a z-up one",
            default=["x", "y", "z"], see=("Axes", "#axes"),
        ),
    },
    choices=(Choice((Group(("file",)), Group(("box",)), Group(("surface",), ("edge_length",)))),),
    doc="The tetrahedral mesh: exactly one of file, box or surface.",
)

#: Defaults of the formulation options: sorofem.Body's own.
_BODY_DEFAULTS = {
    name: p.default for name, p in inspect.signature(Body.__init__).parameters.items() if p.default is not p.empty
}

_FORMULATION = Table(
    {
        "kind": Field(String(FORMULATIONS), "displacement only (\"standard\") or displacement + nodal pressure "
                      "(\"mixed\", no locking as nu -> 0.5)", default=_BODY_DEFAULTS["formulation"],
                      see=("Formulations", "#formulations")),
        "volumetric": Field(
            String(VOLUMETRIC_MEASURES), "volumetric measure c(J): ln J (\"log\") or J - 1 (\"linear\")",
            default=_BODY_DEFAULTS["volumetric"],
        ),
        "pressure_mass": Field(String(PRESSURE_MASSES), "pressure mass matrix of the mixed formulation",
                               default=_BODY_DEFAULTS["pressure_mass"]),
    },
    doc="Finite element formulation.",
)

_FIXED = Table(
    {
        "nodes": Field(_NODES, "node indices, 0-based", example=[0, 1, 2], commented=True),
        "box": Field(_NODE_BOX, "the nodes inside this closed box", "m",
                     example={"min": [-1e-9, -1, -1], "max": [1e-9, 1, 1]}),
        "displacement": Field(_VEC3, "prescribed displacement of the selected nodes", "m", default=[0.0, 0.0, 0.0]),
    },
    choices=(_SELECT_NODES,),
    doc="Supports: exactly one of nodes or box; each entry must select at least one node.",
)
# Listed before box so that the annotated example shows nodes = [...] live.
_FORCE = Table(
    {
        "nodes": Field(_NODES, "node indices, 0-based", example=[5, 6]),
        "box": Field(_NODE_BOX, "the nodes inside this closed box", "m"),
        "force": Field(_VEC3, "force added to each selected node", "N", required=True, example=[0, 0, -0.1]),
    },
    choices=(_SELECT_NODES,),
    hint=" like { nodes = [..], force = [fx, fy, fz] }",
    doc="A nodal force: exactly one of nodes or box, and force.",
)

_LOADS = Table(
    {
        "gravity": Field(_VEC3, "acceleration of gravity", "m/s^2", default=[0.0, 0.0, 0.0], example=[0, 0, -9.81]),
        "forces": Field(Tables(_FORCE, "loads.forces", sections=False), "nodal forces, N per node", default=[]),
    },
    doc="External loads.",
)

#: [solver]: the fields of sorofem.solver.SolveOptions.
_SOLVER = Table(
    {
        f.name: Field(
            Integer(ge=int(f.metadata["range"].ge), le=f.metadata["maximum"]) if f.metadata["integer"]
            else Number(f.metadata["range"]),
            f.metadata["doc"], default=f.default,
        )
        for f in fields(SolveOptions)
    },
    doc="Newton solver options (sorofem.solver.SolveOptions).",
)

#: Defaults of the cable options: sorofem.Cable's own.
_CABLE_DEFAULTS = {
    name: p.default for name, p in inspect.signature(Cable.__init__).parameters.items() if p.default is not p.empty
}
#: The [[cable]] keys that are keyword arguments of sorofem.Cable (the others place the points).
CABLE_OPTIONS = ("model", "stiffness", "actuation", "pull", "tension", "transition", "anchor_first", "snap_tolerance",
                 "outside", "free_node_mass", "damping")

_CABLE = Table(
    {
        "points": Field(Array(_VEC3, 2, noun="[x, y, z] points"), "the cable's points at rest", "m",
                        example=[[0, 0.01, 0.01], [0.2, 0.01, 0.01], [0.4, 0.01, 0.01]], commented=True),
        "start": Field(_VEC3, "first point of a straight cable", "m", example=[0, 0.01, 0.01]),
        "direction": Field(_VEC3, "direction of a straight cable (any non-zero length)", example=[1, 0, 0]),
        "length": Field(Number(Range(gt=0)), "length of a straight cable", "m", example=0.4),
        "divisions": Field(Integer(ge=1, le=MAX_CABLE_DIVISIONS), "equal segments of a straight cable", example=10),
        "model": Field(String(CABLE_MODELS), "a chain of unilateral springs bonded to the body, or an inextensible "
                       "tendon sliding through its points (the last one tied) with one tension",
                       default=_CABLE_DEFAULTS["model"]),
        "stiffness": Field(Number(Range(gt=0)), "stiffness of each segment spring (springs: required)", "N/m",
                           default=None, example=1e5),
        "actuation": Field(Number(Range(gt=0)), "springs: alpha, segment rest lengths are scaled by it (1 rest, < 1 "
                           "pulled)", default=_CABLE_DEFAULTS["actuation"], example=0.8),
        "pull": Field(Number(), "tendon: pulled length, the tendon is held at L <= L0 - pull (exactly one of pull "
                      "and tension)", "m", default=None, example=0.01, commented=True),
        "tension": Field(Number(Range(ge=0)), "tendon: tension (exactly one of pull and tension)", "N", default=None,
                         example=2.0, commented=True),
        "transition": Field(Number(Range(gt=0, lt=1)), "width of the smooth slack-taut transition, fraction of a "
                            "segment's rest length", default=_CABLE_DEFAULTS["transition"]),
        "anchor_first": Field(Boolean(), "the first point is fixed in the world (a motor)",
                              default=_CABLE_DEFAULTS["anchor_first"]),
        "snap_tolerance": Field(Number(Range(ge=0)), "points this far outside the mesh attach to the nearest tet",
                                "m", default=_CABLE_DEFAULTS["snap_tolerance"]),
        "outside": Field(String(OUTSIDE_MODES), "points farther outside are an error, or free nodes with their "
                         "own mass", default=_CABLE_DEFAULTS["outside"]),
        "free_node_mass": Field(Number(Range(ge=0)), "mass of each free node", "kg",
                                default=_CABLE_DEFAULTS["free_node_mass"]),
        "damping": Field(Number(Range(ge=0)), "dashpot of each segment: a force damping * dL/dt in time "
                         "integration (static solves are unaffected)", "N s/m", default=_CABLE_DEFAULTS["damping"]),
    },
    choices=(Choice((Group(("points",)), Group(("start", "direction", "length", "divisions")))),),
    doc="A cable embedded in the mesh (sorofem.Cable): a chain of unilateral springs (model = \"springs\": "
    "stiffness, actuation) or a sliding tendon (model = \"tendon\": pull or tension); points, or start + direction "
    "+ length + divisions.",
)

_OBSTACLE = Table(
    {
        "name": Field(
            String(pattern=_NAME, pattern_doc="a name of letters, digits, '_' and '-'"),
            "name of the obstacle, unique; [target] contact_force may then name it", example="table", commented=True,
        ),
        "plane": Field(
            Table(
                {
                    "point": Field(_VEC3, "a point of the plane", "m", required=True),
                    "normal": Field(_VEC3, "normal (any length > 0), pointing towards the body", required=True),
                },
                hint=" like { point = [x, y, z], normal = [nx, ny, nz] }",
                doc="A half-space: the body stays on the side the normal points to (sorofem.Plane).",
            ),
            "a half-space (a floor, a wall)", "m", example={"point": [0, 0, -0.06], "normal": [0, 0, 1]},
        ),
        "sphere": Field(
            Table(
                {
                    "center": Field(_VEC3, "centre", "m", required=True),
                    "radius": Field(Number(Range(gt=0)), "radius", "m", required=True),
                },
                hint=" like { center = [x, y, z], radius = r }",
                doc="A solid ball (sorofem.Sphere).",
            ),
            "a solid ball", "m", example={"center": [0.3, 0.05, -0.1], "radius": 0.03}, commented=True,
        ),
        "box": Field(_box("the solid"), "a solid axis-aligned box (sorofem.Box)", "m",
                     example={"min": [0.3, 0.0, -0.2], "max": [0.4, 0.1, -0.1]}, commented=True),
        "mesh": Field(
            Table(
                {
                    "file": Field(String(), "triangle surface file (STL, OBJ, PLY, ...), relative to the scene file",
                                  required=True),
                    "scale": Field(Number(Range(gt=0)), "multiplies its coordinates", default=1.0),
                    "one_sided": Field(Boolean(), "accept an open surface as a sheet the body cannot cross",
                                       default=False),
                },
                hint=" like { file = \"cup.stl\", scale = 0.001 }",
                doc="A rigid triangle surface (sorofem.Obstacle.mesh): closed, or open with one_sided = true.",
            ),
            "a triangle surface from a file", example={"file": "cup.stl", "scale": 0.001}, commented=True,
        ),
        "friction": Field(Number(Range(ge=0)), "Coulomb friction coefficient between this obstacle and the body",
                          default=0.0, example=0.5),
        "path": Field(
            Array(Tuple((Number(), Number(), Number(), Number()), "[t, dx, dy, dz]"), 1,
                  noun="[t, dx, dy, dz] keyframes"),
            "keyframes of a prescribed translation, linearly interpolated and held outside their range, followed "
            "with [dynamics] (static solves use t = 0)", "s, m", default=None,
            example=[[0.0, 0, 0, 0], [0.5, 0, 0, 0.02]], commented=True,
        ),
    },
    choices=(Choice((Group(("plane",)), Group(("sphere",)), Group(("box",)), Group(("mesh",)))),),
    doc="A rigid obstacle the body cannot pass through (contact by Incremental Potential Contact, optional "
    "Coulomb friction): exactly one of plane, sphere, box or mesh.",
)

_CONTACT = Table(
    {
        "dhat": Field(Number(Range(gt=0)), "activation distance of the contact barrier: the body rests a fraction "
                      "of it away from an obstacle (default: 1 % of the mean boundary edge length)", "m",
                      default=None, example=1e-4, commented=True),
        "stiffness": Field(Number(Range(gt=0)), "reference barrier stiffness (default: from the material at the "
                           "first solve)", "J/m^4", default=None),
        "friction_slip": Field(Number(Range(gt=0)), "static solves: slip over a load step below which friction "
                               "sticks (default dhat / 10)", "m", default=None),
        "friction_velocity": Field(Number(Range(gt=0)), "dynamics: sliding speed below which friction sticks",
                                   "m/s", default=None),
        "self_contact": Field(Boolean(), "the body's boundary surface may touch itself (frictionless; its forces "
                              "are part of the contact forces and sum to zero)", default=False, example=True,
                              commented=True),
        "adaptive_stiffness": Field(Boolean(), "the barrier stiffness adapts as in IPC (balanced at each time "
                                    "step's start, within [stiffness, 100 stiffness]); false keeps it at stiffness "
                                    "(trajectory gradients through contact are exact with both)", default=True),
    },
    doc="Contact settings: the [[obstacle]] entries' and the body's contact with itself (sorofem.Body.set_contact).",
)

_DYNAMICS = Table(
    {
        "dt": Field(Number(Range(gt=0)), "time step", "s", required=True, example=0.01),
        "steps": Field(Integer(ge=1, le=MAX_TIME_STEPS), "number of time steps", required=True, example=200),
        "mass_damping": Field(Number(Range(ge=0)), "Rayleigh alpha_M", "1/s", default=0.0),
        "stiffness_damping": Field(Number(Range(ge=0)), "Rayleigh beta_K", "s", default=0.0),
        "save_every": Field(Integer(ge=1, le=MAX_TIME_STEPS), "write a frame every this many steps (plus the first and last)",
                            default=1),
        "initial": Field(String(("rest", "static")), "start at rest from the rest shape, or from the static "
                         "equilibrium (loads, actuations)", default="rest"),
        "actuation": Field(
            Array(Array(Tuple((Number(), Number()), "[time, value]"), 1, noun="[time, value] pairs"),
                  indexed=True),
            "one array of [time, value] keyframes per [[cable]], linearly interpolated and held outside their "
            "range: alpha (springs, > 0), pull in m or tension in N (tendons, as commanded) (default: each cable "
            "keeps its command)",
            "s, -", default=None, example=[[[0.0, 1.0], [0.5, 0.8]]],
        ),
    },
    doc="Integrate in time (implicit Euler, lumped mass; density > 0) instead of a static solve.",
)

#: What [target] nodes or points may come with: a goal, or a recorded motion.
_OBSERVED = ("positions", "positions_file", "tracks", "tracks_file")

_TARGET = Table(
    {
        "nodes": Field(_NODES, "observed mesh nodes (with positions)", example=[17, 18, 19]),
        "points": Field(_POINTS, "observed marker points at rest, inside the mesh (with positions)", "m",
                        example=[[0.1, 0.01, 0.01]], commented=True),
        "positions": Field(_POINTS, "goal position of each node or point", "m",
                           example=[[0.1, 0, -0.01], [0.1, 0.02, -0.01], [0.1, 0.02, 0.01]]),
        "positions_file": Field(
            String(), "the goal positions from a file instead, relative to the scene file: .npy (k, 3) or a .csv / "
            ".txt table with columns x, y, z (sorofem.io.read_points)", example="markers.csv", commented=True,
        ),
        "tracks": Field(
            Array(Tuple((Number(Range(ge=0)), Integer(ge=0), Number(), Number(), Number()), "[time, marker, x, y, z]"),
                  1, noun="[time, marker, x, y, z] rows"),
            "a recorded motion instead (with [dynamics]): where marker number `marker` (0-based, an entry of nodes or "
            "points) was at `time`, a frame k dt of [dynamics]; a marker may miss frames", "s, -, m",
            example=[[0.02, 0, 0.4, 0.05, 0.0986]], commented=True,
            see=("Estimate and control in time", "#estimate-and-control-in-time"),
        ),
        "tracks_file": Field(
            String(), "the recorded motion from a file instead, relative to the scene file: a .csv / .txt table, a "
            "header line time, marker, x, y, z (any order), then a row per marker seen in a frame",
            example="tracks.csv", commented=True,
        ),
        "surface": Field(String(), "goal surface file, relative to the scene file", example="goal.obj",
                         commented=True),
        "scale": Field(Number(Range(gt=0)), "coordinate scale of the surface files", default=1.0, commented=True),
        "rest": Field(String(), "the body's own rest surface (default: the mesh boundary)", example="rest.obj",
                      commented=True),
        "contact_force": Field(
            Table(
                {
                    "obstacle": Field(
                        Either((String(pattern=_NAME, pattern_doc="a name of letters, digits, '_' and '-'"),
                                Integer(ge=0))),
                        "the [[obstacle]]: its name, or its index (0-based, in file order)", required=True,
                    ),
                    "force": Field(Either((Number(Range(ge=0)), _VEC3)),
                                   "the goal: a force [fx, fy, fz], or a magnitude >= 0 (whatever its direction)",
                                   "N", required=True),
                },
                hint=' like { obstacle = "table", force = 0.05 }',
                doc="The total force an obstacle exerts on the body (sorofem.Target.contact_force).",
            ),
            "the total force an [[obstacle]] should exert on the body, instead of positions", "N",
            example={"obstacle": "table", "force": 0.05}, commented=True,
        ),
    },
    choices=(
        Choice((
            Group(("nodes",), _OBSERVED), Group(("points",), _OBSERVED),
            Group(("surface",), ("scale", "rest")), Group(("contact_force",)),
        )),
        Choice(tuple(Group((name,)) for name in _OBSERVED), required=False),
    ),
    doc="What sorofem estimate / control should meet (sorofem.Target): where parts of the body should be, or the "
    "force an obstacle exerts on it; exactly one of nodes, points, surface or contact_force; nodes and points with "
    "one of positions or positions_file (a goal), or tracks or tracks_file (a recorded motion, with [dynamics]).",
)

#: Parameter names [estimate] accepts (sorofem.inverse's for every model), material ones optionally ":REGION".
_PARAMETERS = tuple(dict.fromkeys(n for model in MODELS.values() for n in parameter_names(model))) + MOTION_PARAMETERS
_MATERIAL_PARAMETERS = tuple(dict.fromkeys(n for model in MODELS.values() for n in model.estimable()))
_ESTIMATE = Table(
    {
        "params": Field(
            Array(String(_PARAMETERS, pattern=f"(?:{'|'.join(_MATERIAL_PARAMETERS)}):{_NAME}",
                         pattern_doc="a material one followed by ':REGION' (a named [[material.region]])"), 1),
            "names of the parameters to fit (sorofem.inverse.PARAMETERS); a material one may name a region, "
            "\"shear_modulus:tip\"; with [dynamics] also the Rayleigh coefficients mass_damping (1/s) and "
            "stiffness_damping (s) and the dashpot cable_damping (N s/m) of the one spring cable, scalars only",
            required=True, example=["shear_modulus", "lame_lambda"],
        ),
        "x0": Field(Array(Either((Number(), Array(Number(), 1))), 1),
                    "initial values, one per parameter (an array for a field; > 0 for a damping coefficient)",
                    required=True, example=[20e3, 0.2e6]),
        "bounds": Field(Array(Tuple((Number(), Number()), "[lo, hi]"), 1), "one [lo, hi] per parameter",
                        default=None, example=[[1e3, 1e6], [1e3, 1e8]]),
        "method": Field(String(("least-squares", "l-bfgs-b", "nelder-mead")), "optimiser", default="least-squares"),
        "starts": Field(Integer(ge=0, le=MAX_STARTS), "number of extra random starts (not with [dynamics])",
                        default=0),
    },
    doc="sorofem estimate (sorofem.estimate): fit these parameters so that the equilibrium meets [target]; with "
    "[dynamics], so that the motion of [dynamics] meets the recorded [target] tracks.",
)

_CONTROL = Table(
    {
        "cables": Field(Array(Integer(ge=0), 1), "indices of the [[cable]] entries to actuate (default: all)",
                        default=None, example=[0]),
        "bounds": Field(Array(Tuple((Number(), Number()), "[lo, hi]"), 1),
                        "one range [lo, hi] per cable in its command's units: alpha (springs, > 0; default [0.3, 1]), "
                        "pull in m (default [0, L0/4]) or tension in N (required)", default=None,
                        example=[[0.3, 1.0]]),
        "method": Field(String(("l-bfgs-b", "nelder-mead")), "optimiser (with [dynamics]: l-bfgs-b only)",
                        default="l-bfgs-b"),
        "keyframe_times": Field(
            Array(Number(Range(ge=0)), 1), "with [dynamics] (required there): the times of the schedule's keyframes, "
            "increasing, within dt * steps; each cable's command is piecewise linear through them from its [[cable]] "
            "command at t = 0, and held after the last", "s", default=None, example=[0.1, 0.2, 0.3, 0.4, 0.5],
            see=("Estimate and control in time", "#estimate-and-control-in-time"),
        ),
        "reach_time": Field(
            Number(Range(gt=0)), "with [dynamics] (required there): the time T, a multiple of dt, from which [target] "
            "should be reached and held to the end of the run", "s", default=None, example=0.5,
        ),
    },
    doc="sorofem control (sorofem.control): find cable commands (alphas, tendon pulls or tensions) that bring "
    "[target] closest; with [dynamics], a schedule of them (keyframes) that brings [target] there at reach_time and "
    "holds it to the end of the run.",
)

#: The files `sorofem run` writes, each switchable in [output] (defaults: all of them).
_OUTPUT = Table(
    {
        "directory": Field(
            String(), "output folder, relative to the scene file (created); `--out DIR` on the command line "
            "overrides it", example="results/beam",
        ),
        "summary": Field(Boolean(), "write summary.json (solver report, timings, material, extreme values)",
                         default=True),
        "vtu": Field(Boolean(), "write result.vtu (the rest mesh with point data displacement, pressure and cell "
                     "data J, von Mises: Warp By Vector in ParaView shows the deformed body)", default=True),
        "deformed": Field(Boolean(), "also write deformed.vtu: the same data on the deformed mesh (to open without a "
                          "filter; do not warp it again)", default=False),
        "png": Field(Boolean(), "write the figures: shape.png and convergence.png, trajectory.png with "
                     "[dynamics], fit.png (and profile.png) for estimate and control", default=True),
        "cables": Field(Boolean(), "write cables.vtu (the cables as lines with their tension; static scenes "
                        "with [[cable]] entries)", default=True),
        "pvd": Field(Boolean(), "write trajectory.pvd and its frames in trajectory/ (scenes with [dynamics])",
                     default=True),
        "color_by": Field(
            String(COLOR_FIELDS), "field that colours the deformed surface in shape.png: displacement magnitude, "
            "von Mises stress, pressure (kind = \"mixed\" only) or the volume ratio J", default="displacement",
        ),
    },
    doc="What sorofem run writes and where (every file but deformed.vtu is on by default); estimate and control "
    "also follow directory, summary, vtu and png.",
)

SCENE = Table(
    {
        "mesh": Field(_MESH, "the mesh", required=True, missing="a scene needs a [mesh] table"),
        "material": Field(_MATERIAL, "the material", required=True, missing="a scene needs a [material] table"),
        "formulation": Field(_FORMULATION, "the formulation"),
        "fixed": Field(
            Tables(_FIXED, "fixed"),
            "[[fixed]] entries: supports and prescribed displacements (a body without any must rest on "
            "[[obstacle]] entries)",
            default=[],
        ),
        "loads": Field(_LOADS, "gravity and nodal forces"),
        "solver": Field(_SOLVER, "Newton options"),
        "cable": Field(Tables(_CABLE, "cable"), "[[cable]] entries", default=[]),
        "obstacle": Field(Tables(_OBSTACLE, "obstacle"), "[[obstacle]] entries: rigid obstacles", default=[]),
        "contact": Field(_CONTACT, "contact settings"),
        "dynamics": Field(_DYNAMICS, "time integration instead of a static solve"),
        "target": Field(_TARGET, "target of sorofem estimate / control"),
        "estimate": Field(_ESTIMATE, "sorofem estimate options"),
        "control": Field(_CONTROL, "sorofem control options"),
        "output": Field(_OUTPUT, "what sorofem run writes, and where"),
    },
    doc="A sorofem scene: one simulation (mesh, material, supports, loads, solver, cables, dynamics, the "
    "target of an estimate or control, and the outputs).",
)
#: The scene's top-level tables, in file order.
TOP_KEYS = tuple(SCENE.fields)


def defaults(name: str) -> Any:
    """The table ``name`` (a key of :data:`SCENE`) with every default filled in, as the
    validator returns it for an empty table."""
    return SCENE.fields[name].spec.check(Checker(Path(), ""), {}, name)


def json_schema() -> dict[str, Any]:
    """The JSON Schema (draft 2020-12) of scene files, from the same definitions the validator uses.

    Editors use it to complete and check scene files (``#:schema ./scene.schema.json`` as the
    first line of a scene, for VS Code's Even Better TOML or taplo). It checks structure, types,
    ranges and allowed values; the checks that need the mesh or other files (indices in range,
    boxes that select something, files that exist, one value per cable or parameter) are only
    done by :meth:`Scene.load`.

    Examples
    --------
    >>> import json, sorofem as sf
    >>> schema = sf.scene.json_schema()
    >>> schema["$schema"], schema["properties"]["material"]["properties"]["poisson_ratio"]["exclusiveMaximum"]
    ('https://json-schema.org/draft/2020-12/schema', 0.5)
    >>> text = json.dumps(schema, indent=2)   # what `sorofem schema` prints
    """
    return {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": "sorofem scene file",
        **SCENE.schema(),
    }


def schema_text() -> str:
    """:func:`json_schema` as the text of ``sorofem schema`` and ``docs/scene.schema.json``."""
    return json.dumps(json_schema(), indent=2) + "\n"
