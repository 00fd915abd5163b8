"""Scene files: a whole static simulation described in TOML.

Schema
------
::

    [mesh]                     # required: exactly one of `file` or `box`
    file = "beam.vtu"          # relative to the scene file; .tet or any format meshio reads
    # box = { size = [1.0, 0.1, 0.1], cells = [8, 2, 2] }   # optional origin = [x, y, z]
    scale = 1.0                # optional, > 0; coordinates are multiplied by this
    axes = ["x", "y", "z"]     # optional, after `scale`: new axis i is old axis axes[i], signed;
                               # ["x", "-z", "y"] turns a y-up CAD mesh into a z-up one

    [material]                 # required; Neo-Hookean
    youngs_modulus = 66e3      # Pa; or shear_modulus + lame_lambda (Pa)
    poisson_ratio = 0.45       # 0 <= nu < 0.5 (nu = 0.5 is rejected: lambda must be finite)
    density = 1080             # kg/m^3, optional (default 0)

    [[material.region]]        # optional, any number: other material values for some elements
    name = "tip"               # optional; lets [estimate] fit e.g. "shear_modulus:tip"
    box = { min = [0.3, -1, -1], max = [0.4, 1, 1] }   # elements whose centroid is inside; or
    # cells = [0, 1, 2]        # ... element (tet) indices, 0-based
    youngs_modulus = 132e3     # any of the [material] values (one pair's kind); the others are
                               # inherited from [material]; a later entry overrides an earlier one

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
    damping = 0.0              # N s/m per segment: force damping * dL/dt (dynamics only)

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
    params = ["shear_modulus", "lame_lambda"]   # names of sorofem.inverse.PARAMETERS; material
                               # ones may name a region: "shear_modulus:tip"
    x0 = [20e3, 0.2e6]         # initial values, one per name
    bounds = [[1e3, 1e6], [1e3, 1e8]]           # optional, one [lo, hi] per name
    method = "least-squares"   # optional: "least-squares", "l-bfgs-b" or "nelder-mead"
    starts = 0                 # optional: number of extra random starts

    [control]                  # optional: `sorofem control` finds cable actuations for [target]
    cables = [0]               # indices of [[cable]] entries (default: all)
    bounds = [[0.3, 1.0]]      # optional, one alpha range per cable
    method = "l-bfgs-b"        # optional: or "nelder-mead"

    [output]                   # optional: what `sorofem run` writes, and where
    directory = "results/beam" # relative to the scene file; `--out DIR` overrides it
    summary = true             # summary.json          (each switch defaults to true)
    vtu = true                 # result.vtu
    png = true                 # shape.png + convergence.png, or trajectory.png with [dynamics]
    cables = true              # cables.vtu (static scenes with cables)
    pvd = true                 # trajectory.pvd + trajectory/ (scenes with [dynamics])
    color_by = "displacement"  # shape.png's colours: "displacement", "von_mises", "J" or
                               # "pressure" (kind = "mixed" only)

Validation is strict: an unknown key, a wrong type, a missing mesh file, a ``[[fixed]]``
entry selecting no node, a ``[[material.region]]`` entry selecting no element or an
out-of-range value raises :class:`~sorofem.SceneError` with the file, the dotted key (e.g.
``fixed[0].box.min``) and, when it can be found, the line.

Every key, its type, range, default and meaning is written once, as data (``_SCENE`` below):
the validator reads it, and so does :func:`json_schema`, which turns it into a JSON Schema
(draft 2020-12) of the file (``sorofem schema``; the repository keeps a copy in
``docs/scene.schema.json``). Editors that understand TOML schemas (VS Code's Even Better
TOML, taplo) complete and check scene files against it when the file starts with a
``#:schema ./scene.schema.json`` line (a path relative to the scene file, or a URL). What the
schema cannot say (node and element indices within the mesh, files that exist, one value per
cable or parameter) only the validator checks.

Examples
--------
>>> import sorofem as sf
>>> scene = sf.Scene.load("cantilever.toml")      # doctest: +SKIP
>>> result = scene.solve()                        # doctest: +SKIP
>>> schema = sf.scene.json_schema()               # a dict, ready for json.dump
>>> sorted(schema["properties"])[:3]
['cable', 'control', 'dynamics']
"""

from __future__ import annotations

import copy
import inspect
import json
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
from .inverse import _MATERIAL as _MATERIAL_PARAMETERS
from .inverse import PARAMETERS
from .io import read_mesh
from .plot import COLOR_FIELDS
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

__all__ = ["Scene", "json_schema"]

_HEADER = re.compile(r"^\s*(\[\[?)\s*([^\]]+?)\s*\]\]?\s*(#.*)?$")
_KEY_PART = re.compile(r"^([A-Za-z0-9_\-]+)(?:\[(\d+)\])?$")


# ---------------------------------------------------------------------------
# The schema as data. Each node of the tree below knows how to check a parsed TOML value
# (with messages naming the dotted key, what was expected and what was given) and how to
# write itself as JSON Schema; the scene's sections are built from them once (_SCENE), and
# both the validator (Scene.from_toml) and json_schema() read that one tree.


def _type_name(value: Any) -> str:
    return {
        bool: "a boolean",
        int: "an integer",
        float: "a number",
        str: "a string",
        list: "an array",
        dict: "a table",
    }.get(type(value), type(value).__name__)


def _shown(value: Any) -> str:
    """``a string '0.45'``, ``an integer 3``: a value with its TOML type, for messages."""
    text = ("true" if value else "false") if isinstance(value, bool) else repr(value)
    if len(text) > 60:
        text = text[:57] + "..."
    return f"{_type_name(value)} {text}"


def _or(items: list[str]) -> str:
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " or " + items[-1]


def _quoted(names: tuple[str, ...] | list[str]) -> list[str]:
    return [f"'{n}'" for n in names]


def _join(key: str, name: str) -> str:
    return f"{key}.{name}" if key else name


class _Spec:
    """A node of the schema: a type with its constraints."""

    def what(self) -> str:
        """Singular description with an article, for messages: ``a number > 0``."""
        raise NotImplementedError

    def plural(self) -> str:
        """Plural description without article: ``numbers > 0``."""
        raise NotImplementedError

    def check(self, c: "_Checker", value: Any, key: str, at: str = "") -> Any:
        """The value, checked and normalised (numbers as float, defaults filled in).

        ``key`` is the dotted key errors name; ``at`` the position inside an array that
        errors report by the array's key (``[2]``), or ``""``.
        """
        raise NotImplementedError

    def schema(self) -> dict[str, Any]:
        """This node as JSON Schema."""
        raise NotImplementedError


@dataclass(frozen=True)
class _Number(_Spec):
    gt: float | None = None
    ge: float | None = None
    lt: float | None = None
    #: Appended to out-of-range messages.
    note: str = ""

    def _range(self) -> str:
        parts = [f"{op} {v:g}" for op, v in ((">", self.gt), (">=", self.ge), ("<", self.lt)) if v is not None]
        return " and ".join(parts)

    def what(self) -> str:
        return " ".join(filter(None, ("a number", self._range())))

    def plural(self) -> str:
        return " ".join(filter(None, ("numbers", self._range())))

    def check(self, c: "_Checker", value: Any, key: str, at: str = "") -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise c.fail(key, at, f"expected {self.what()}, got {_shown(value)}")
        x = float(value)
        if not math.isfinite(x):
            raise c.fail(key, at, f"expected a finite number, got {x}")
        if (self.gt is not None and not x > self.gt) or (self.ge is not None and not x >= self.ge) or (
            self.lt is not None and not x < self.lt
        ):
            note = f" ({self.note})" if self.note else ""
            raise c.fail(key, at, f"expected {self.what()}, got {x:g}{note}")
        return x

    def schema(self) -> dict[str, Any]:
        out: dict[str, Any] = {"type": "number"}
        for name, v in (("exclusiveMinimum", self.gt), ("minimum", self.ge), ("exclusiveMaximum", self.lt)):
            if v is not None:
                out[name] = v
        return out


@dataclass(frozen=True)
class _Integer(_Spec):
    ge: int | None = None

    def what(self) -> str:
        return "an integer" + (f" >= {self.ge}" if self.ge is not None else "")

    def plural(self) -> str:
        return "integers" + (f" >= {self.ge}" if self.ge is not None else "")

    def check(self, c: "_Checker", value: Any, key: str, at: str = "") -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise c.fail(key, at, f"expected {self.what()}, got {_shown(value)}")
        if self.ge is not None and value < self.ge:
            raise c.fail(key, at, f"expected {self.what()}, got {value}")
        return value

    def schema(self) -> dict[str, Any]:
        out: dict[str, Any] = {"type": "integer"}
        if self.ge is not None:
            out["minimum"] = self.ge
        return out


@dataclass(frozen=True)
class _String(_Spec):
    #: Allowed values (None: any string) ...
    enum: tuple[str, ...] | None = None
    #: ... or, besides them, strings matching this regular expression (described by ``pattern_doc``).
    pattern: str | None = None
    pattern_doc: str = ""

    def what(self) -> str:
        if self.enum is None and self.pattern is None:
            return "a string"
        options = [repr(v) for v in self.enum or ()] + ([self.pattern_doc] if self.pattern else [])
        return f"one of {', '.join(options)}"

    def plural(self) -> str:
        return "strings" if self.enum is None and self.pattern is None else f"strings, each {self.what()}"

    def check(self, c: "_Checker", value: Any, key: str, at: str = "") -> str:
        if not isinstance(value, str):
            raise c.fail(key, at, f"expected {'a string' if self.enum is None else self.what()}, got {_shown(value)}")
        if self.enum is not None or self.pattern is not None:
            if value not in (self.enum or ()) and not (self.pattern and re.fullmatch(self.pattern, value)):
                raise c.fail(key, at, f"expected {self.what()}, got {value!r}")
        return value

    def schema(self) -> dict[str, Any]:
        out: dict[str, Any] = {"type": "string"}
        if self.enum is not None and self.pattern is not None:
            out["anyOf"] = [{"enum": list(self.enum)}, {"pattern": f"^(?:{self.pattern})$"}]
        elif self.enum is not None:
            out["enum"] = list(self.enum)
        elif self.pattern is not None:
            out["pattern"] = f"^(?:{self.pattern})$"
        return out


@dataclass(frozen=True)
class _Boolean(_Spec):
    def what(self) -> str:
        return "true or false"

    def plural(self) -> str:
        return "booleans"

    def check(self, c: "_Checker", value: Any, key: str, at: str = "") -> bool:
        if not isinstance(value, bool):
            raise c.fail(key, at, f"expected true or false, got {_shown(value)}")
        return value

    def schema(self) -> dict[str, Any]:
        return {"type": "boolean"}


@dataclass(frozen=True)
class _Array(_Spec):
    items: _Spec
    min_items: int = 0
    max_items: int | None = None
    #: Errors inside name the item's own key (``dynamics.actuation[1]``), not the array's.
    indexed: bool = False
    #: Plural name of the items for messages (default: the items' own description).
    noun: str = ""

    def _describe(self, article: bool) -> str:
        inner = self.noun or self.items.plural()
        a = "an array" if article else "arrays"
        if self.max_items is not None and self.max_items == self.min_items:
            return f"{a} of {self.min_items} {inner}"
        if self.min_items == 1:
            return f"{'a non-empty array' if article else 'non-empty arrays'} of {inner}"
        if self.min_items > 1:
            return f"{a} of at least {self.min_items} {inner}"
        return f"{a} of {inner}"

    def what(self) -> str:
        return self._describe(True)

    def plural(self) -> str:
        return self._describe(False)

    def check(self, c: "_Checker", value: Any, key: str, at: str = "") -> list[Any]:
        if not isinstance(value, list):
            raise c.fail(key, at, f"expected {self.what()}, got {_shown(value)}")
        n = len(value)
        if n < self.min_items or (self.max_items is not None and n > self.max_items):
            got = "an empty array" if n == 0 else f"an array of length {n}"
            raise c.fail(key, at, f"expected {self.what()}, got {got}")
        if self.indexed:
            return [self.items.check(c, v, f"{key}[{i}]", "") for i, v in enumerate(value)]
        return [self.items.check(c, v, key, f"{at}[{i}]") for i, v in enumerate(value)]

    def schema(self) -> dict[str, Any]:
        out: dict[str, Any] = {"type": "array", "items": self.items.schema()}
        if self.min_items:
            out["minItems"] = self.min_items
        if self.max_items is not None:
            out["maxItems"] = self.max_items
        return out


@dataclass(frozen=True)
class _Tuple(_Spec):
    """A fixed-length array whose items differ, e.g. ``[time, alpha]``."""

    items: tuple[_Spec, ...]
    noun: str  # "[time, alpha]"

    def what(self) -> str:
        return f"a pair {self.noun}" if len(self.items) == 2 else f"an array {self.noun}"

    def plural(self) -> str:
        return f"{self.noun} pairs" if len(self.items) == 2 else f"arrays {self.noun}"

    def check(self, c: "_Checker", value: Any, key: str, at: str = "") -> list[Any]:
        if not isinstance(value, list) or len(value) != len(self.items):
            shown = f"an array of length {len(value)}" if isinstance(value, list) else _shown(value)
            raise c.fail(key, at, f"expected {self.what()} of {len(self.items)} {self._kinds()}, got {shown}")
        return [spec.check(c, v, key, f"{at}[{i}]") for i, (spec, v) in enumerate(zip(self.items, value))]

    def _kinds(self) -> str:
        kinds = {type(s) for s in self.items}
        return self.items[0].plural().split()[0] if len(kinds) == 1 else "values"

    def schema(self) -> dict[str, Any]:
        # prefixItems types each position and minItems = maxItems fixes the length, so "items"
        # (the items after the prefix) has nothing to check in draft 2020-12: it only gives
        # validators of older drafts, which do not know prefixItems (taplo), the common type.
        n = len(self.items)
        out: dict[str, Any] = {"type": "array", "prefixItems": [s.schema() for s in self.items]}
        types = {s.schema().get("type") for s in self.items}
        if len(types) == 1 and None not in types:
            out["items"] = {"type": types.pop()}
        return {**out, "minItems": n, "maxItems": n}


@dataclass(frozen=True)
class _Either(_Spec):
    options: tuple[_Spec, ...]

    def what(self) -> str:
        return " or ".join(o.what() for o in self.options)

    def plural(self) -> str:
        return " or ".join(o.plural() for o in self.options)

    def check(self, c: "_Checker", value: Any, key: str, at: str = "") -> Any:
        for option in self.options:
            try:
                return option.check(c, value, key, at)
            except SceneError:
                continue
        raise c.fail(key, at, f"expected {self.what()}, got {_shown(value)}")

    def schema(self) -> dict[str, Any]:
        return {"anyOf": [o.schema() for o in self.options]}


class _Missing:
    def __repr__(self) -> str:
        return "<no default>"


_NO_DEFAULT: Any = _Missing()


@dataclass(frozen=True)
class _Field:
    """One key of a table."""

    spec: _Spec
    #: What it means (the schema's description; editors show it).
    doc: str
    units: str = ""
    required: bool = False
    #: Filled in when the key is absent (and written to the schema), unless _NO_DEFAULT or None.
    default: Any = _NO_DEFAULT
    #: Message after "missing: " when a required key is absent (default: ``doc``).
    missing: str = ""

    def schema(self) -> dict[str, Any]:
        out = dict(self.spec.schema())
        out["description"] = self.doc + (f" [{self.units}]" if self.units else "")
        if self.default is not _NO_DEFAULT and self.default is not None:
            out["default"] = self.default
        return out


@dataclass(frozen=True)
class _Group:
    """Keys that go together; ``extras`` are optional keys allowed only with them."""

    keys: tuple[str, ...]
    extras: tuple[str, ...] = ()

    def label(self) -> str:
        return " + ".join(_quoted(self.keys))


@dataclass(frozen=True)
class _Choice:
    """Exactly one (``required``) or at most one of several groups of keys.

    A group is chosen by giving any key that belongs to it alone; then all its keys are
    required (unless ``partial``: any of them), and keys of the other groups are not allowed.
    """

    groups: tuple[_Group, ...]
    required: bool = True
    partial: bool = False

    def _all(self, group: _Group) -> tuple[str, ...]:
        return group.keys + group.extras

    def keys(self) -> list[str]:
        return list(dict.fromkeys(k for g in self.groups for k in self._all(g)))

    def check(self, c: "_Checker", table: dict[str, Any], key: str) -> None:
        counts: dict[str, int] = {}
        for g in self.groups:
            for k in g.keys:
                counts[k] = counts.get(k, 0) + 1
        chosen = [g for g in self.groups if any(k in table and counts[k] == 1 for k in g.keys)]
        options = _or([g.label() for g in self.groups])
        if len(chosen) > 1 or (self.required and not chosen):
            given = [k for k in self.keys() if k in table]
            got = f"got {', '.join(_quoted(given))}" if given else "got none of them"
            raise c.error(key or None, f"expected {'exactly' if self.required else 'at most'} one of {options}; {got}")
        group = chosen[0] if chosen else None
        if group is not None and not self.partial:
            missing = [k for k in group.keys if k not in table]
            if missing:
                others = [g.label() for g in self.groups if g is not group]
                raise c.error(
                    _join(key, missing[0]),
                    f"missing: expected {group.label()} together (or {_or(others)} instead)",
                )
        allowed = set(self._all(group)) if group is not None else set()
        for k in self.keys():
            if k in table and k not in allowed:
                owners = _or([g.label() for g in self.groups if k in self._all(g)])
                with_what = f", not with {group.label()}" if group is not None else f" (and {owners} is not given)"
                raise c.error(_join(key, k), f"only allowed with {owners}{with_what}")

    def schema(self) -> dict[str, Any]:
        every = self.keys()
        alternatives = []
        for g in self.groups:
            alt: dict[str, Any] = {}
            if not self.partial:
                alt["required"] = list(g.keys)
            forbidden = [k for k in every if k not in self._all(g)]
            if forbidden:
                alt["not"] = {"anyOf": [{"required": [k]} for k in forbidden]}
            alternatives.append(alt)
        if not self.required and not self.partial:
            alternatives.append({"not": {"anyOf": [{"required": [k]} for k in every]}})
        return {"anyOf": alternatives}


@dataclass(frozen=True)
class _Table(_Spec):
    fields: dict[str, _Field]
    choices: tuple[_Choice, ...] = ()
    #: Shown after "expected a table" when something else is given.
    hint: str = ""
    doc: str = ""

    def what(self) -> str:
        return "a table" + self.hint

    def plural(self) -> str:
        return "tables"

    def check(self, c: "_Checker", value: Any, key: str, at: str = "") -> dict[str, Any]:
        if not isinstance(value, dict):
            raise c.fail(key, at, f"expected a table{self.hint}, got {_type_name(value)}")
        for name in value:
            if name not in self.fields:
                raise c.error(_join(key, name), f"unknown key '{name}' (allowed: {', '.join(self.fields)})")
        for choice in self.choices:
            choice.check(c, value, key)
        for name, f in self.fields.items():
            if f.required and name not in value:
                raise c.error(_join(key, name), f"missing: {f.missing or f.doc}")
        out = {name: self.fields[name].spec.check(c, v, _join(key, name)) for name, v in value.items()}
        for name, f in self.fields.items():
            if name not in out and f.default is not _NO_DEFAULT:
                out[name] = copy.deepcopy(f.default)
        return out

    def schema(self) -> dict[str, Any]:
        out: dict[str, Any] = {"type": "object"}
        if self.doc:
            out["description"] = self.doc
        out["properties"] = {name: f.schema() for name, f in self.fields.items()}
        required = [name for name, f in self.fields.items() if f.required]
        if required:
            out["required"] = required
        out["additionalProperties"] = False
        if len(self.choices) == 1:
            out.update(self.choices[0].schema())
        elif self.choices:
            out["allOf"] = [ch.schema() for ch in self.choices]
        return out


@dataclass(frozen=True)
class _Tables(_Spec):
    """An array of tables: ``[[name]]`` entries (or an inline array of tables)."""

    table: _Table
    header: str
    min_items: int = 0
    #: Appended to the message when there are fewer than ``min_items`` entries.
    note: str = ""

    def what(self) -> str:
        return f"an array of tables ([[{self.header}]])"

    def plural(self) -> str:
        return "arrays of tables"

    def check(self, c: "_Checker", value: Any, key: str, at: str = "") -> list[dict[str, Any]]:
        if isinstance(value, dict):
            raise c.fail(key, at, f"expected an array of tables: write [[{self.header}]], not [{self.header}]")
        if not isinstance(value, list):
            raise c.fail(key, at, f"expected {self.what()}, got {_type_name(value)}")
        if len(value) < self.min_items:
            raise c.fail(key, at, f"at least {self.min_items} [[{self.header}]] entry is required{self.note}")
        return [self.table.check(c, v, f"{key}[{i}]") for i, v in enumerate(value)]

    def schema(self) -> dict[str, Any]:
        out: dict[str, Any] = {"type": "array", "items": self.table.schema()}
        if self.min_items:
            out["minItems"] = self.min_items
        return out


# -- the scene's keys ---------------------------------------------------------------------

_VEC3 = _Array(_Number(), 3, 3)
_POINTS = _Array(_VEC3, 1, noun="[x, y, z] points")
_NODES = _Array(_Integer(ge=0), 1)
#: Names of regions and of ``"shear_modulus:NAME"`` parameters.
_NAME = r"[A-Za-z_][A-Za-z0-9_\-]*"
_BOX_HINT = " like { min = [x, y, z], max = [x, y, z] }"


def _box(what: str) -> _Table:
    return _Table(
        {
            "min": _Field(_VEC3, "lowest corner", "m", required=True),
            "max": _Field(_VEC3, "highest corner (>= min)", "m", required=True),
        },
        hint=_BOX_HINT,
        doc=f"Closed axis-aligned box: {what} inside it (boundary included).",
    )


_NODE_BOX = _box("the nodes")
_SELECT_NODES = _Choice((_Group(("nodes",)), _Group(("box",))))

#: The material values, shared by [material] and its [[material.region]] entries.
_MATERIAL_VALUES: dict[str, _Field] = {
    "youngs_modulus": _Field(_Number(gt=0), "Young's modulus E (with poisson_ratio)", "Pa"),
    "poisson_ratio": _Field(
        _Number(ge=0, lt=0.5, note="nu = 0.5 means lame_lambda = inf; model nearly incompressible silicone "
                "with e.g. nu = 0.4999 and [formulation] kind = \"mixed\""),
        "Poisson's ratio nu, 0 <= nu < 0.5 (with youngs_modulus)",
    ),
    "shear_modulus": _Field(_Number(gt=0), "shear modulus mu (with lame_lambda)", "Pa"),
    "lame_lambda": _Field(
        _Number(ge=0), "Lame's first parameter lambda, > 0 for kind = \"mixed\" (with shear_modulus)", "Pa"
    ),
}
_MATERIAL_PAIRS = (_Group(("youngs_modulus", "poisson_ratio")), _Group(("shear_modulus", "lame_lambda")))
_MATERIAL_KEYS = (*_MATERIAL_VALUES, "density")

_REGION = _Table(
    {
        "name": _Field(
            _String(pattern=_NAME, pattern_doc="a name of letters, digits, '_' and '-'"),
            "name of the region, unique; [estimate] params may then name it, e.g. \"shear_modulus:NAME\"",
        ),
        "box": _Field(_box("the elements whose centroid lies"), "select the elements whose centroid is in this box"),
        "cells": _Field(_Array(_Integer(ge=0), 1), "select these elements (tetrahedron indices, 0-based)"),
        **_MATERIAL_VALUES,
        "density": _Field(_Number(ge=0), "density rho of these elements", "kg/m^3"),
    },
    choices=(
        _Choice((_Group(("box",)), _Group(("cells",)))),
        _Choice(_MATERIAL_PAIRS, required=False, partial=True),
    ),
    doc="Other material values for some elements; values not given are the [material] table's, and a later "
    "entry overrides an earlier one where they overlap.",
)

_MATERIAL = _Table(
    {
        **_MATERIAL_VALUES,
        "density": _Field(
            _Number(ge=0), "density rho (only matters under gravity and in dynamics)", "kg/m^3", default=0.0
        ),
        "region": _Field(
            _Tables(_REGION, "material.region"),
            "[[material.region]] entries: per-element materials (see the entry's description)",
            default=[],
        ),
    },
    choices=(_Choice(_MATERIAL_PAIRS),),
    doc="Compressible Neo-Hookean material: exactly one pair, youngs_modulus + poisson_ratio or shear_modulus "
    "+ lame_lambda.",
)

_MESH = _Table(
    {
        "file": _Field(_String(), "mesh file, relative to the scene file: .tet or any volume format meshio reads"),
        "box": _Field(
            _Table(
                {
                    "size": _Field(_Array(_Number(gt=0), 3, 3), "edge lengths [x, y, z]", "m", required=True),
                    "cells": _Field(_Array(_Integer(ge=1), 3, 3), "hexahedral cells along x, y, z (6 tets each)",
                                    required=True),
                    "origin": _Field(_VEC3, "lowest corner", "m", default=[0.0, 0.0, 0.0]),
                },
                hint=" like { size = [1, 0.1, 0.1], cells = [8, 2, 2] }",
                doc="A box meshed with nx * ny * nz hexahedra of 6 tetrahedra each.",
            ),
            "a box mesh instead of a file",
        ),
        "scale": _Field(_Number(gt=0), "multiplies all coordinates (for box: size and origin)", default=1.0),
        "axes": _Field(
            _Array(_String(Mesh.AXIS_NAMES), 3, 3),
            "after scale, new axis i is old axis axes[i], with its sign: a signed permutation of x, y, z; "
            "[\"x\", \"-z\", \"y\"] turns a y-up mesh into a z-up one",
            default=["x", "y", "z"],
        ),
    },
    choices=(_Choice((_Group(("file",)), _Group(("box",)))),),
    doc="The tetrahedral mesh: exactly one of file or box.",
)

_FORMULATION = _Table(
    {
        "kind": _Field(_String(FORMULATIONS), "displacement only (\"standard\") or displacement + nodal pressure "
                       "(\"mixed\", no locking as nu -> 0.5)", default="standard"),
        "volumetric": _Field(
            _String(VOLUMETRIC_MEASURES), "volumetric measure c(J): ln J (\"log\") or J - 1 (\"linear\")", default="log"
        ),
        "pressure_mass": _Field(_String(PRESSURE_MASSES), "pressure mass matrix of the mixed formulation",
                                default="consistent"),
    },
    doc="Finite element formulation.",
)

_FIXED = _Table(
    {
        "nodes": _Field(_NODES, "node indices, 0-based"),
        "box": _Field(_NODE_BOX, "the nodes inside this closed box"),
        "displacement": _Field(_VEC3, "prescribed displacement of the selected nodes", "m", default=[0.0, 0.0, 0.0]),
    },
    choices=(_SELECT_NODES,),
    doc="Supports: exactly one of nodes or box; each entry must select at least one node.",
)

_FORCE = _Table(
    {
        "nodes": _Field(_NODES, "node indices, 0-based"),
        "box": _Field(_NODE_BOX, "the nodes inside this closed box"),
        "force": _Field(_VEC3, "force added to each selected node", "N", required=True),
    },
    choices=(_SELECT_NODES,),
    hint=" like { nodes = [..], force = [fx, fy, fz] }",
    doc="A nodal force: exactly one of nodes or box, and force.",
)

_LOADS = _Table(
    {
        "gravity": _Field(_VEC3, "acceleration of gravity", "m/s^2", default=[0.0, 0.0, 0.0]),
        "forces": _Field(_Tables(_FORCE, "loads.forces"), "nodal forces", default=[]),
    },
    doc="External loads.",
)

_SOLVER = _Table(
    {
        "tolerance": _Field(_Number(gt=0), "Newton stops when the residual norm over the load norm is below this",
                            default=1e-8),
        "max_iterations": _Field(_Integer(ge=1), "Newton iterations per load step", default=50),
        "load_steps": _Field(_Integer(ge=1), "equal load increments (the solver may cut a step back)", default=1),
    },
    doc="Newton solver options.",
)

#: Defaults of the cable options: sorofem.Cable's own.
_CABLE_DEFAULTS = {
    name: p.default for name, p in inspect.signature(Cable.__init__).parameters.items() if p.default is not p.empty
}
_CABLE_OPTIONS = ("stiffness", "actuation", "transition", "anchor_first", "snap_tolerance", "outside", "free_node_mass",
                  "damping")

_CABLE = _Table(
    {
        "points": _Field(_Array(_VEC3, 2, noun="[x, y, z] points"), "the cable's points at rest", "m"),
        "start": _Field(_VEC3, "first point of a straight cable", "m"),
        "direction": _Field(_VEC3, "direction of a straight cable (any non-zero length)"),
        "length": _Field(_Number(gt=0), "length of a straight cable", "m"),
        "divisions": _Field(_Integer(ge=1), "equal segments of a straight cable"),
        "stiffness": _Field(_Number(gt=0), "stiffness of each segment spring", "N/m", required=True,
                            missing="the stiffness of each segment, N/m"),
        "actuation": _Field(_Number(gt=0), "alpha: segment rest lengths are scaled by it (1 rest, < 1 pulled)",
                            default=_CABLE_DEFAULTS["actuation"]),
        "transition": _Field(_Number(gt=0, lt=1), "width of the smooth slack-taut transition, fraction of a "
                             "segment's rest length", default=_CABLE_DEFAULTS["transition"]),
        "anchor_first": _Field(_Boolean(), "the first point is fixed in the world (a motor)",
                               default=_CABLE_DEFAULTS["anchor_first"]),
        "snap_tolerance": _Field(_Number(ge=0), "points this far outside the mesh attach to the nearest tet", "m",
                                 default=_CABLE_DEFAULTS["snap_tolerance"]),
        "outside": _Field(_String(OUTSIDE_MODES), "points farther outside are an error, or free nodes with their "
                          "own mass", default=_CABLE_DEFAULTS["outside"]),
        "free_node_mass": _Field(_Number(ge=0), "mass of each free node", "kg",
                                 default=_CABLE_DEFAULTS["free_node_mass"]),
        "damping": _Field(_Number(ge=0), "dashpot of each segment: a force damping * dL/dt in time integration",
                          "N s/m", default=_CABLE_DEFAULTS["damping"]),
    },
    choices=(_Choice((_Group(("points",)), _Group(("start", "direction", "length", "divisions")))),),
    doc="A cable of unilateral springs embedded in the mesh: points, or start + direction + length + divisions.",
)

_DYNAMICS = _Table(
    {
        "dt": _Field(_Number(gt=0), "time step", "s", required=True),
        "steps": _Field(_Integer(ge=1), "number of time steps", required=True),
        "mass_damping": _Field(_Number(ge=0), "Rayleigh alpha_M", "1/s", default=0.0),
        "stiffness_damping": _Field(_Number(ge=0), "Rayleigh beta_K", "s", default=0.0),
        "save_every": _Field(_Integer(ge=1), "write a frame every this many steps (plus the first and last)",
                             default=1),
        "initial": _Field(_String(("rest", "static")), "start at rest from the rest shape, or from the static "
                          "equilibrium", default="rest"),
        "actuation": _Field(
            _Array(_Array(_Tuple((_Number(), _Number(gt=0)), "[time, alpha]"), 1, noun="[time, alpha] pairs"),
                   indexed=True),
            "one array of [time, alpha] keyframes per [[cable]], linearly interpolated and held outside their "
            "range (default: each cable keeps its actuation)",
            default=None,
        ),
    },
    doc="Integrate in time (implicit Euler, lumped mass) instead of a static solve.",
)

_TARGET = _Table(
    {
        "nodes": _Field(_NODES, "observed mesh nodes (with positions)"),
        "points": _Field(_POINTS, "observed marker points at rest, inside the mesh (with positions)", "m"),
        "positions": _Field(_POINTS, "goal position of each node or point", "m"),
        "surface": _Field(_String(), "goal surface file, relative to the scene file"),
        "scale": _Field(_Number(gt=0), "coordinate scale of the surface files", default=1.0),
        "rest": _Field(_String(), "the body's own rest surface (default: the mesh boundary)"),
    },
    choices=(
        _Choice((
            _Group(("nodes", "positions")), _Group(("points", "positions")), _Group(("surface",), ("scale", "rest"))
        )),
    ),
    doc="Where parts of the body should be, for sorofem estimate / control: exactly one of nodes, points or surface.",
)

#: Parameter names [estimate] accepts: sorofem.inverse's, material ones optionally ":REGION".
_MATERIAL_PARAMETER_NAMES = tuple(p for p in PARAMETERS if p in _MATERIAL_PARAMETERS)
_ESTIMATE = _Table(
    {
        "params": _Field(
            _Array(_String(PARAMETERS, pattern=f"(?:{'|'.join(_MATERIAL_PARAMETER_NAMES)}):{_NAME}",
                           pattern_doc="a material one followed by ':REGION' (a named [[material.region]])"), 1),
            "names of the parameters to fit (sorofem.inverse.PARAMETERS)",
            required=True,
        ),
        "x0": _Field(_Array(_Either((_Number(), _Array(_Number(), 1))), 1), "initial values, one per parameter",
                     required=True),
        "bounds": _Field(_Array(_Tuple((_Number(), _Number()), "[lo, hi]"), 1), "one [lo, hi] per parameter",
                         default=None),
        "method": _Field(_String(("least-squares", "l-bfgs-b", "nelder-mead")), "optimiser", default="least-squares"),
        "starts": _Field(_Integer(ge=0), "number of extra random starts", default=0),
    },
    doc="sorofem estimate: fit these parameters so that the equilibrium meets [target].",
)

_CONTROL = _Table(
    {
        "cables": _Field(_Array(_Integer(ge=0), 1), "indices of the [[cable]] entries to actuate (default: all)",
                         default=None),
        "bounds": _Field(_Array(_Tuple((_Number(gt=0), _Number(gt=0)), "[lo, hi]"), 1),
                         "one actuation range [lo, hi] per cable (default [0.3, 1])", default=None),
        "method": _Field(_String(("l-bfgs-b", "nelder-mead")), "optimiser", default="l-bfgs-b"),
    },
    doc="sorofem control: find cable actuations that bring [target] closest.",
)

#: The files `sorofem run` writes, each switchable in [output] (defaults: all of them).
_OUTPUT = _Table(
    {
        "directory": _Field(
            _String(), "output folder, relative to the scene file (created); `--out DIR` on the command line "
            "overrides it",
        ),
        "summary": _Field(_Boolean(), "write summary.json (solver report, timings, material, extreme values)",
                          default=True),
        "vtu": _Field(_Boolean(), "write result.vtu (deformed mesh with displacement, J, von Mises, pressure)",
                      default=True),
        "png": _Field(_Boolean(), "write the figures: shape.png and convergence.png, or trajectory.png with "
                      "[dynamics]", default=True),
        "cables": _Field(_Boolean(), "write cables.vtu (the cables as lines with their tension; static scenes "
                         "with [[cable]] entries)", default=True),
        "pvd": _Field(_Boolean(), "write trajectory.pvd and its frames in trajectory/ (scenes with [dynamics])",
                      default=True),
        "color_by": _Field(
            _String(COLOR_FIELDS), "field that colours the deformed surface in shape.png: displacement magnitude, "
            "von Mises stress, pressure (mixed formulation only) or the volume ratio J", default="displacement",
        ),
    },
    doc="What sorofem run writes and where (every file is on by default); estimate and control also follow "
    "directory, summary and vtu.",
)

_SCENE = _Table(
    {
        "mesh": _Field(_MESH, "the mesh", required=True, missing="a scene needs a [mesh] table"),
        "material": _Field(_MATERIAL, "the material", required=True, missing="a scene needs a [material] table"),
        "formulation": _Field(_FORMULATION, "the formulation"),
        "fixed": _Field(
            _Tables(_FIXED, "fixed", min_items=1, note=": an unsupported body has no equilibrium"),
            "[[fixed]] entries: supports and prescribed displacements",
            required=True,
            missing="a scene needs a [[fixed]] entry",
        ),
        "loads": _Field(_LOADS, "gravity and nodal forces"),
        "solver": _Field(_SOLVER, "Newton options"),
        "cable": _Field(_Tables(_CABLE, "cable"), "[[cable]] entries", default=[]),
        "dynamics": _Field(_DYNAMICS, "time integration instead of a static solve"),
        "target": _Field(_TARGET, "target of sorofem estimate / control"),
        "estimate": _Field(_ESTIMATE, "sorofem estimate options"),
        "control": _Field(_CONTROL, "sorofem control options"),
        "output": _Field(_OUTPUT, "what sorofem run writes, and where"),
    },
    doc="A sorofem scene: one simulation (mesh, material, supports, loads, solver, cables, dynamics, the "
    "target of an estimate or control, and the outputs).",
)
_TOP_KEYS = tuple(_SCENE.fields)


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
        **_SCENE.schema(),
    }


def _schema_text() -> str:
    """:func:`json_schema` as the text of ``sorofem schema`` and ``docs/scene.schema.json``."""
    return json.dumps(json_schema(), indent=2) + "\n"


# ---------------------------------------------------------------------------
# Errors that point into the file


class _Checker:
    """Builds errors that name the scene file, the dotted key and (when found) the line."""

    def __init__(self, path: Path, text: str) -> None:
        self.path = path
        self.lines = text.splitlines()

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

    def fail(self, key: str, at: str, message: str) -> SceneError:
        """An error about the value at ``key`` (``at``: the item inside it, e.g. ``[2]``)."""
        return self.error(key or None, message + (f" (item {at})" if at else ""))


# ---------------------------------------------------------------------------
# The scene


@dataclass
class Scene:
    """A static simulation read from a TOML scene file (schema in the module docstring).

    Attributes
    ----------
    path
        The scene file.
    mesh, material, body
        The model, with the ``[[fixed]]`` conditions and ``[loads].forces`` applied to ``body``.
        With ``[[material.region]]`` entries ``material`` holds per-element arrays.
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
    solver: dict[str, Any] = field(default_factory=lambda: _SOLVER.check(_Checker(Path(), ""), {}, "solver"))
    formulation_options: dict[str, str] = field(
        default_factory=lambda: {k: v.default for k, v in _FORMULATION.fields.items() if k != "kind"}
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
    #: Named ``[[material.region]]`` entries: name -> indices of the elements that have the
    #: entry's material (those no later entry overrides); the ``regions=`` of
    #: :func:`sorofem.estimate` for ``"shear_modulus:NAME"`` parameters.
    regions: dict[str, np.ndarray] = field(default_factory=dict)
    #: Per element, the index of the ``[[material.region]]`` entry that set its material, or -1
    #: for ``[material]`` itself; ``(n_tets,)`` int64, or None without regions.
    material_region: np.ndarray | None = None
    #: ``[output]`` with defaults filled in: ``directory`` (a Path, resolved against the scene
    #: file's folder, or None), the switches ``summary``, ``vtu``, ``png``, ``cables``, ``pvd``
    #: (booleans) and ``color_by``.
    output: dict[str, Any] = field(
        default_factory=lambda: {**_OUTPUT.check(_Checker(Path(), ""), {}, "output"), "directory": None}
    )
    #: The files the scene reads: itself, the mesh file and the ``[target]`` surface files
    #: (``sorofem run`` never writes over them).
    input_files: list[Path] = field(default_factory=list)

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
            raw = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            match = re.search(r"line (\d+)", str(exc))
            raise SceneError(
                f"invalid TOML: {exc}", path=path, line=int(match.group(1)) if match else None
            ) from None
        # Structure, types, ranges and allowed values (everything json_schema() says), with
        # defaults filled in; then what needs the mesh and the other files.
        data = _SCENE.check(check, raw, "")
        for name in ("formulation", "loads", "solver", "output"):
            if name not in data:
                data[name] = _SCENE.fields[name].spec.check(check, {}, name)

        mesh = _build_mesh(check, data["mesh"], path.parent)
        formulation = data["formulation"]["kind"]
        options = {k: v for k, v in data["formulation"].items() if k != "kind"}
        material, regions, owner = _build_material(check, data["material"], mesh, formulation)
        try:
            body = Body(mesh, material, formulation=formulation, **options)
        except ParameterError as exc:
            raise check.error(f"material.{exc.parameter or 'youngs_modulus'}", str(exc)) from None
        _apply_fixed(check, data["fixed"], body)
        gravity = _apply_loads(check, data["loads"], body)
        cables = _apply_cables(check, data["cable"], body)
        dynamics = _build_dynamics(check, data["dynamics"], body) if "dynamics" in data else None
        target, target_files = None, []
        if "target" in data:
            target, target_files = _build_target(check, data["target"], body, path.parent)
        estimate = _build_estimate(check, data["estimate"], regions) if "estimate" in data else None
        control = _build_control(check, data["control"], body) if "control" in data else None
        output = _build_output(check, data["output"], formulation, path.parent)
        return cls(
            path=path,
            mesh=mesh,
            material=material,
            body=body,
            formulation=formulation,
            gravity=gravity,
            solver=data["solver"],
            formulation_options=options,
            cables=cables,
            dynamics=dynamics,
            target=target,
            estimate=estimate,
            control=control,
            regions=regions,
            material_region=owner,
            output=output,
            input_files=[p for p in (path, mesh.source, *target_files) if p is not None],
        )

    def solve(self) -> StaticResult:
        """Run :func:`sorofem.solve_static` with the scene's loads and solver options."""
        return solve_static(self.body, self.gravity, **self.solver)

    def simulate(
        self, *, body: Body | None = None, equilibrium: StaticResult | None = None, progress: bool | None = None
    ) -> Trajectory:
        """Run :func:`sorofem.simulate` with the scene's ``[dynamics]`` (from the rest shape,
        or from :meth:`solve`'s equilibrium with ``initial = "static"``).

        Parameters
        ----------
        body
            Integrate this body instead of ``scene.body`` (the viewer passes its own, with the
            formulation and cable actuations set in the page); cables without keyframes hold
            its actuations.
        equilibrium
            With ``initial = "static"``: the equilibrium of ``body`` to start from, if already
            solved (default: solved here). Ignored with ``initial = "rest"``.
        progress
            See :func:`sorofem.simulate`.

        Raises
        ------
        InputError
            The scene has no ``[dynamics]`` table.
        """
        if self.dynamics is None:
            raise InputError(f"{self.path}: the scene has no [dynamics] table")
        d = self.dynamics
        body = self.body if body is None else body
        initial = None
        if d["initial"] == "static":
            initial = equilibrium if equilibrium is not None else solve_static(body, self.gravity, **self.solver)
        return simulate(
            body, d["dt"], d["steps"], actuation=d["actuation"], gravity=self.gravity,
            damping=(d["mass_damping"], d["stiffness_damping"]), initial=initial, save_every=d["save_every"],
            tolerance=self.solver["tolerance"], max_iterations=self.solver["max_iterations"], progress=progress,
        )

    def to_dict(self) -> dict[str, Any]:
        """Plain summary of the scene's settings."""
        return {
            "scene": str(self.path),
            "mesh": None if self.mesh.source is None else str(self.mesh.source),
            "formulation": self.formulation,
            "formulation_options": self.body.formulation_options,
            "material": self.material.to_dict(),
            "material_regions": None if self.material_region is None else {
                "elements_per_entry": np.bincount(self.material_region + 1).tolist()[1:],
                "named": {name: int(e.size) for name, e in self.regions.items()},
            },
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
            "output": {**self.output, "directory": None if self.output["directory"] is None
                       else str(self.output["directory"])},
        }


# ---------------------------------------------------------------------------
# Sections: what the schema cannot check (the mesh, other files, counts), on checked data


def _build_mesh(check: _Checker, table: dict[str, Any], base: Path) -> Mesh:
    scale = table["scale"]
    if "file" in table:
        name = table["file"]
        file = Path(name) if Path(name).is_absolute() else base / name
        if not file.is_file():
            raise check.error("mesh.file", f"mesh file not found: {file}")
        try:
            mesh = read_mesh(file, scale=scale)
        except InputError as exc:
            raise check.error("mesh.file", f"could not read the mesh: {exc}") from None
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


def _box_bounds(check: _Checker, box: dict[str, Any], key: str) -> tuple[np.ndarray, np.ndarray]:
    lo, hi = np.array(box["min"]), np.array(box["max"])
    if np.any(lo > hi):
        raise check.error(key, f"expected min <= max, got min {lo.tolist()}, max {hi.tolist()}")
    return lo, hi


def _span(mesh: Mesh) -> str:
    lo, hi = mesh.bounds()
    return f"the mesh spans {np.round(lo, 6).tolist()} .. {np.round(hi, 6).tolist()}"


def _new_material(check: _Checker, values: dict[str, float], key: str) -> NeoHookean:
    try:
        return NeoHookean(**values)
    except ParameterError as exc:
        name = exc.parameter if exc.parameter in values else next(iter(values), "youngs_modulus")
        raise check.error(f"{key}.{name}", str(exc).removeprefix(f"{name}: ")) from None


def _build_material(
    check: _Checker, table: dict[str, Any], mesh: Mesh, formulation: str
) -> tuple[NeoHookean, dict[str, np.ndarray], np.ndarray | None]:
    """The material (per-element with regions), the named regions' elements and each element's entry."""
    base = _new_material(check, {k: table[k] for k in _MATERIAL_KEYS if k in table}, "material")
    entries = table["region"]
    if not entries:
        return base, {}, None
    m = mesh.n_tets
    centroids = mesh.points[mesh.tets].mean(axis=1)
    owner = np.full(m, -1, dtype=np.int64)
    materials: list[NeoHookean] = []
    names: dict[str, int] = {}
    lame = "shear_modulus" in table
    for i, entry in enumerate(entries):
        prefix = f"material.region[{i}]"
        given = {k: entry[k] for k in _MATERIAL_KEYS if k in entry}
        if not given and "name" not in entry:
            raise check.error(
                prefix, f"gives no material value and no name: expected any of {', '.join(_quoted(_MATERIAL_KEYS))} "
                "(the others are inherited from [material]), or a name for [estimate]",
            )
        if "name" in entry:
            if entry["name"] in names:
                raise check.error(
                    f"{prefix}.name", f"{entry['name']!r} is already the name of material.region[{names[entry['name']]}]"
                )
            names[entry["name"]] = i
        # Values not given are the base material's, in the pair the entry uses.
        if "youngs_modulus" in given or "poisson_ratio" in given:
            pair = {"youngs_modulus": base.youngs_modulus, "poisson_ratio": base.poisson_ratio}
        else:
            pair = {"shear_modulus": base.shear_modulus, "lame_lambda": base.lame_lambda}
            lame = lame or "shear_modulus" in given or "lame_lambda" in given
        values = {**pair, "density": base.density, **given}
        materials.append(_new_material(check, values, prefix))
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
    attrs = ("shear_modulus", "lame_lambda") if lame else ("youngs_modulus", "poisson_ratio")
    arrays = {a: np.array([getattr(mat, a) for mat in every])[owner + 1] for a in (*attrs, "density")}
    lam = np.array([mat.lame_lambda for mat in every])[owner + 1]
    if formulation == "mixed" and not np.all(lam > 0):
        bad = int(owner[np.argmax(~(lam > 0))])
        entry = entries[bad] if bad >= 0 else table
        prefix = f"material.region[{bad}]" if bad >= 0 else "material"
        name = next((k for k in ("poisson_ratio", "lame_lambda") if k in entry), None)
        raise check.error(
            f"{prefix}.{name}" if name else prefix,
            "formulation 'mixed' needs lame_lambda > 0 (poisson_ratio > 0) in every element: it divides by lambda",
        )
    material = NeoHookean(**arrays)
    regions = {name: np.flatnonzero(owner == i).astype(np.int64) for name, i in names.items()}
    return material, regions, owner


def _select_nodes(check: _Checker, entry: dict[str, Any], prefix: str, mesh: Mesh) -> np.ndarray:
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


def _apply_fixed(check: _Checker, entries: list[dict[str, Any]], body: Body) -> None:
    for i, entry in enumerate(entries):
        body.fix(_select_nodes(check, entry, f"fixed[{i}]", body.mesh), entry["displacement"])


def _apply_loads(check: _Checker, table: dict[str, Any], body: Body) -> np.ndarray:
    for i, entry in enumerate(table["forces"]):
        body.add_force(_select_nodes(check, entry, f"loads.forces[{i}]", body.mesh), entry["force"])
    return np.array(table["gravity"])


def _apply_cables(check: _Checker, entries: list[dict[str, Any]], body: Body) -> list[Cable]:
    """Build each ``[[cable]]`` entry, add it to ``body`` and locate its points in the mesh."""
    cables = []
    for i, entry in enumerate(entries):
        prefix = f"cable[{i}]"
        options = {name: entry[name] for name in _CABLE_OPTIONS}
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


def _build_dynamics(check: _Checker, table: dict[str, Any], body: Body) -> dict[str, Any]:
    options = dict(table)
    schedule = table["actuation"]
    if schedule is not None:
        n_cables = len(body.cables)
        if len(schedule) != n_cables:
            raise check.error(
                "dynamics.actuation",
                f"expected one list of [time, alpha] keyframes per [[cable]] ({n_cables}), got {len(schedule)} entries",
            )
        options["actuation"] = []
        for c, frames in enumerate(schedule):
            try:
                options["actuation"].append(Keyframes(frames))
            except InputError as exc:
                raise check.error(f"dynamics.actuation[{c}]", str(exc)) from None
    return options


def _build_output(check: _Checker, table: dict[str, Any], formulation: str, base: Path) -> dict[str, Any]:
    out = dict(table)
    if "directory" in out:
        if not out["directory"].strip():
            raise check.error("output.directory", "expected a folder name, got an empty string")
        folder = Path(out["directory"]).expanduser()
        out["directory"] = folder if folder.is_absolute() else base / folder
    else:
        out["directory"] = None
    if out["color_by"] == "pressure" and formulation != "mixed":
        raise check.error(
            "output.color_by",
            f"'pressure' needs [formulation] kind = \"mixed\": the {formulation} formulation has no pressure field "
            f"(choose one of {', '.join(repr(f) for f in COLOR_FIELDS if f != 'pressure')})",
        )
    return out


def _build_target(check: _Checker, table: dict[str, Any], body: Body, base: Path) -> tuple[Target, list[Path]]:
    """The target, and the surface files it was read from."""
    files: dict[str, Path] = {}
    if "surface" in table:
        for name in ("surface", "rest"):
            if name in table:
                file = Path(table[name])
                file = file if file.is_absolute() else base / file
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
        positions = np.array(table["positions"])
        if kind == "nodes":
            nodes = np.array(table["nodes"], dtype=np.int64)
            if nodes.max() >= body.mesh.n_nodes:
                raise check.error(
                    "target.nodes",
                    f"node index {int(nodes.max())} out of range: the mesh has {body.mesh.n_nodes} nodes",
                )
            rest = nodes
        else:
            rest = np.array(table["points"])
        if len(positions) != len(rest):
            raise check.error(
                "target.positions", f"expected {len(rest)} positions, one per entry of '{kind}', got {len(positions)}"
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


def _bounds(
    check: _Checker, value: list[list[float]] | None, key: str, count: int, what: str
) -> list[tuple[float, float]] | None:
    if value is None:
        return None
    if len(value) != count:
        raise check.error(key, f"expected one [lo, hi] per {what} ({count}), got {len(value)} entries")
    for lo, hi in value:
        if lo >= hi:
            raise check.error(key, f"expected lo < hi, got [{lo:g}, {hi:g}]")
    return [(lo, hi) for lo, hi in value]


def _build_estimate(check: _Checker, table: dict[str, Any], regions: dict[str, np.ndarray]) -> dict[str, Any]:
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


def _build_control(check: _Checker, table: dict[str, Any], body: Body) -> dict[str, Any]:
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
    return {
        "cables": cables,
        "bounds": _bounds(check, table["bounds"], "control.bounds", len(cables), "cable"),
        "method": table["method"],
    }
