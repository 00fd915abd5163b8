"""The parametrisation of the inverse problems: a vector theta of named parameters -> the core's
per-element material, gravity and cable values, with the chain rule back and the scaled
variable ``s`` the optimisers see.

Material names, their conversions (Young's modulus and Poisson's ratio to the Lame parameters)
and their transforms (log, logit) come from the body's material model declaration
(:mod:`sorofem.materials`); gravity and the cable values are declared here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..cables import cable_index
from .._validate import describe
from ..errors import InputError, ParameterError
from ..materials import IDENTITY, LOG, NEO_HOOKEAN, Form, MaterialModel, Transform

__all__ = ["PARAMETERS", "COMMAND_PARAMETERS", "parameter_names", "core_sensitivities", "Parameters", "Block", "State"]

#: Parameters that are not the material's: gravity (``(3,)``, m/s^2, :func:`sorofem.gradient`
#: only), per spring cable its actuation alpha and segment stiffness (N/m), and per tendon its
#: pull (m) or tension (N), whichever command drives it.
_GRAVITY, _CABLES = "gravity", ("cable_actuation", "cable_stiffness", "cable_pull", "cable_tension")
_TRANSFORMS = {_GRAVITY: IDENTITY, "cable_actuation": LOG, "cable_stiffness": LOG, "cable_pull": IDENTITY,
               "cable_tension": IDENTITY}
#: The cable command each cable parameter needs (:attr:`sorofem.Body.commands`).
_CABLE_COMMAND = {"cable_actuation": "actuation", "cable_stiffness": "actuation", "cable_pull": "pull",
                  "cable_tension": "tension"}
#: The cable parameters that are commands (the others are properties of the cable).
COMMAND_PARAMETERS = ("cable_actuation", "cable_pull", "cable_tension")
_FIELD = "_field"


def parameter_names(model: MaterialModel) -> tuple[str, ...]:
    """The names :func:`sorofem.gradient`, :func:`sorofem.estimate` and :func:`sorofem.control`
    understand for a body of material ``model``."""
    return model.estimable() + (_GRAVITY, *_CABLES)


#: Parameter names understood by :func:`gradient`, :func:`estimate` and :func:`control` for a
#: Neo-Hookean body (see the module docstring of :mod:`sorofem.inverse`).
PARAMETERS: tuple[str, ...] = parameter_names(NEO_HOOKEAN)


@dataclass
class Block:
    """One named parameter: ``size`` entries of theta from ``offset``."""

    name: str
    kind: str  # the name without its region
    elements: NDArray[np.int64]  # elements a material block acts on
    cables: NDArray[np.int64]  # cables a cable block acts on
    size: int
    transform: Transform
    offset: int = 0

    @property
    def slice(self) -> slice:
        return slice(self.offset, self.offset + self.size)

    @property
    def is_field(self) -> bool:
        return self.kind.endswith(_FIELD)


@dataclass
class State:
    """The core's values at a theta: every material parameter per element (the core's own and
    those of the other forms), gravity (None: the scenario's), each cable's command value (alpha,
    pull or tension, as :attr:`sorofem.Body.commands`) and stiffness."""

    material: dict[str, NDArray[np.float64]]
    gravity: NDArray[np.float64] | None
    actuation: NDArray[np.float64]
    stiffness: NDArray[np.float64]

    def core(self, model: MaterialModel) -> tuple[str, dict[str, NDArray[np.float64]], NDArray[np.float64], dict[str, Any] | None]:
        """The arguments of the extension's ``Model.set_material_model``."""
        params = {model.parameter(name).core_key: self.material[name] for name in model.core_form.names}
        return model.core_name, params, self.material["density"], dict(model.core_options) or None


def core_sensitivities(adjoint: Mapping[str, Any]) -> dict[str, NDArray[np.float64]]:
    """The extension's sensitivities (``Model.adjoint``) as one flat dict by key: the
    ``"material"`` entry's parameters (core names: ``"mu"``, ``"c10"``, ``"mu:0"``) beside the
    other blocks (``"density"``, ``"gravity"``, ...) and the original aliases (``"lam"``, ``"rho"``)."""
    out = {k: np.asarray(v, dtype=np.float64) for k, v in adjoint.items() if k != "material"}
    out.update({k: np.asarray(v, dtype=np.float64) for k, v in adjoint.get("material", {}).items()})
    return out


class Parameters:
    """Named parameter blocks of a body; theta is the concatenation of their values."""

    def __init__(
        self,
        body: Any,
        names: str | Sequence[str],
        regions: Mapping[str, ArrayLike] | None = None,
        cables: Sequence[Any] | Mapping[str, Sequence[Any]] | None = None,
    ) -> None:
        if isinstance(names, str):
            names = [names]
        if not isinstance(names, (list, tuple)) or not names:
            raise InputError(f"params: expected a list of parameter names, got {describe(names)}")
        model: MaterialModel = body.material.model
        known = parameter_names(model)
        material_names = set(model.estimable())
        m = body.mesh.n_tets
        n_cables = len(body.cables)
        commands = [kind for kind, _ in body.commands]

        def cable_ids(kind: str) -> NDArray[np.int64]:
            """The cables of a cable block: those given (per name, when a mapping), else every
            cable the parameter applies to."""
            chosen = cables.get(kind) if isinstance(cables, Mapping) else cables
            if chosen is None:
                return np.array([c for c in range(n_cables) if commands[c] == _CABLE_COMMAND[kind]], dtype=np.int64)
            ids = np.array([cable_index(body, c) for c in chosen], dtype=np.int64)
            for c in ids:
                if commands[c] != _CABLE_COMMAND[kind]:
                    what = {"actuation": "a spring cable", "pull": "a tendon driven by its pull",
                            "tension": "a tendon driven by its tension"}
                    raise InputError(
                        f"params: {kind!r} applies to {what[_CABLE_COMMAND[kind]]}; cable {int(c)} is "
                        f"{what[commands[c]]}"
                    )
            return ids
        self.body = body
        self.model = model
        self.blocks: list[Block] = []
        # Per form, the elements its parameters act on: two forms on one element conflict.
        in_form = {form.names: np.zeros(m, dtype=bool) for form in model.forms}
        offset = 0
        for name in names:
            if not isinstance(name, str):
                raise InputError(f"params: expected parameter names (str), got {name!r}")
            # Names may hold a ':' themselves (Ogden's "mu:0"): the region follows the last one.
            kind, region = (name, "") if name in known else name.rpartition(":")[::2]
            if kind not in known:
                raise InputError(f"params: unknown parameter {name!r}; expected one of {list(known)} (material ones optionally ':region')")
            elements = np.arange(m, dtype=np.int64)
            if region:
                if kind not in material_names:
                    raise InputError(f"params: {kind!r} cannot be restricted to a region ({name!r})")
                if not regions or region not in regions:
                    raise InputError(f"params: region {region!r} of {name!r} is not in regions= (given: {sorted(regions or {})})")
                elements = _element_set(regions[region], m, f"regions[{region!r}]")
            base = kind.removesuffix(_FIELD)
            for form in model.forms:
                if base in form.names:
                    in_form[form.names][elements] = True
            ids = np.zeros(0, dtype=np.int64)
            if kind in _CABLES:
                if n_cables == 0:
                    raise InputError(f"params: {name!r} needs cables; the body has none")
                ids = cable_ids(kind)
                if ids.size == 0:
                    raise InputError(f"params: {name!r} applies to none of the body's cables")
                size = len(ids)
            elif kind == _GRAVITY:
                size = 3
            elif kind.endswith(_FIELD):
                size = len(elements)
            else:
                size = 1
            if any(b.name == name for b in self.blocks):
                raise InputError(f"params: {name!r} given twice")
            transform = _TRANSFORMS.get(kind) or model.parameter(base).transform
            self.blocks.append(Block(name, kind, elements, ids, size, transform, offset))
            offset += size
        used = [form for form in model.forms if in_form[form.names].any()]
        for i, a in enumerate(used):
            for b in used[i + 1:]:
                if np.any(in_form[a.names] & in_form[b.names]):
                    raise InputError(
                        f"params: {a.label()} and {b.label()} act on the same elements; choose one "
                        f"{'pair' if len(a.names) == 2 else 'set'}"
                    )
        self.size = offset
        #: Per non-core form, the elements whose core values it sets.
        self.converted: list[tuple[Form, NDArray[np.bool_]]] = [
            (form, in_form[form.names]) for form in model.forms[1:] if in_form[form.names].any()
        ]
        core = dict(zip((*model.core_form.names, "density"), body.material.per_element(m)))
        self.material0 = dict(core)
        for form in model.forms[1:]:
            self.material0.update(zip(form.names, form.from_core(*[core[n] for n in model.core_form.names])))
        self.alpha0 = np.array(body.actuations, dtype=np.float64)
        self.k0 = np.array(body.cable_stiffnesses, dtype=np.float64)

    # -- values ---------------------------------------------------------------------------

    def current(self, gravity: ArrayLike | None = None) -> NDArray[np.float64]:
        """theta of the body as it is (material blocks: the mean over their elements)."""
        theta = np.zeros(self.size)
        for b in self.blocks:
            source = self.material0.get(b.kind.removesuffix(_FIELD))
            if b.is_field:
                theta[b.slice] = source[b.elements]
            elif source is not None:
                theta[b.slice] = float(np.mean(source[b.elements]))
            elif b.kind == _GRAVITY:
                theta[b.slice] = np.zeros(3) if gravity is None else np.asarray(gravity, dtype=np.float64)
            elif b.kind in COMMAND_PARAMETERS:
                theta[b.slice] = self.alpha0[b.cables]
            else:
                theta[b.slice] = self.k0[b.cables]
        return theta

    def from_user(self, values: Any, what: str) -> NDArray[np.float64]:
        """theta from a user's list (one entry per name; arrays for fields, gravity, cables)
        or dict name -> value."""
        if isinstance(values, Mapping):
            unknown = [k for k in values if k not in self.names]
            if unknown:
                raise InputError(f"{what}: {unknown} are not parameters being fitted; expected names among {self.names}")
            values = [values[b.name] if b.name in values else self.current()[b.slice] for b in self.blocks]
        if isinstance(values, np.ndarray):
            values = list(values.reshape(-1)) if values.ndim <= 1 and values.size != len(self.blocks) else list(values)
        elif np.isscalar(values) or values is None:
            values = [values]
        elif not isinstance(values, (list, tuple)):
            raise InputError(f"{what}: expected one value per parameter {self.names}, got {describe(values)}")
        values = list(values)
        if len(values) != len(self.blocks):
            # A flat vector of the full size is accepted too.
            try:
                flat = np.asarray(values, dtype=np.float64).reshape(-1)
            except (TypeError, ValueError):
                flat = np.zeros(0)
            if flat.size == self.size and len(values) == self.size:
                return flat
            raise InputError(f"{what}: expected {len(self.blocks)} value(s), one per parameter {self.names}, got {len(values)}")
        theta = np.zeros(self.size)
        for b, v in zip(self.blocks, values):
            try:
                arr = np.asarray(v, dtype=np.float64).reshape(-1)
            except (TypeError, ValueError):
                raise InputError(f"{what}: {b.name!r} expects {'a number' if b.size == 1 else f'{b.size} numbers'}, "
                                 f"got {describe(v)}") from None
            if arr.size == 1:
                arr = np.full(b.size, float(arr[0]))
            if arr.size != b.size:
                kind = "a scalar parameter: one number" if b.size == 1 else f"{b.size} value(s)"
                raise InputError(f"{what}: {b.name!r} is {kind}, got {arr.size} values")
            theta[b.slice] = arr
        return theta

    @property
    def names(self) -> list[str]:
        return [b.name for b in self.blocks]

    def as_dict(self, theta: NDArray[np.float64]) -> dict[str, Any]:
        """name -> float (scalar blocks) or array."""
        out: dict[str, Any] = {}
        for b in self.blocks:
            v = theta[b.slice]
            out[b.name] = float(v[0]) if b.size == 1 and b.kind not in _CABLES and not b.is_field else v.copy()
        return out

    def state(self, theta: NDArray[np.float64]) -> State:
        material = {name: values.copy() for name, values in self.material0.items()}
        gravity = None
        alpha, k = self.alpha0.copy(), self.k0.copy()
        for b in self.blocks:
            v = theta[b.slice]
            if b.kind == _GRAVITY:
                gravity = v.copy()
            elif b.kind in COMMAND_PARAMETERS:
                alpha[b.cables] = v
            elif b.kind == "cable_stiffness":
                k[b.cables] = v
            else:
                material[b.kind.removesuffix(_FIELD)][b.elements] = v if b.is_field else v[0]
        core_names = self.model.core_form.names
        for form, elements in self.converted:
            converted = form.to_core(*[material[n][elements] for n in form.names])
            for name, values in zip(core_names, converted):
                material[name][elements] = values
        return State(material, gravity, alpha, k)

    # -- chain rule -----------------------------------------------------------------------

    def _partials(self, b: Block, st: State) -> dict[str, NDArray[np.float64]]:
        """d(core parameters)/d theta_b for a scalar material block, per element, by the
        extension's keys."""
        m = len(self.material0["density"])
        el = b.elements
        spec = self.model.parameter(b.kind)
        if spec.core_key:  # the core's own parameter, or density
            d = np.zeros(m)
            d[el] = 1.0
            return {spec.core_key: d}
        form = next(f for f in self.model.forms if b.kind in f.names)
        row = form.jacobian(*[st.material[n][el] for n in form.names])[form.names.index(b.kind)]  # type: ignore[misc]
        out = {}
        for name, derivative in zip(self.model.core_form.names, row):
            d = np.zeros(m)
            d[el] = derivative
            out[self.model.parameter(name).core_key] = d
        return out

    def pullback(self, adjoint: Mapping[str, Any], theta: NDArray[np.float64]) -> NDArray[np.float64]:
        """dO/dtheta from the extension's dO/d(core parameters) (``Model.adjoint``'s dict, or
        :func:`core_sensitivities` of it)."""
        adjoint = core_sensitivities(adjoint)
        st = self.state(theta)
        grad = np.zeros(self.size)
        for b in self.blocks:
            if b.is_field:
                key = self.model.parameter(b.kind.removesuffix(_FIELD)).core_key
                grad[b.slice] = adjoint[key][b.elements]
            elif b.kind == _GRAVITY:
                grad[b.slice] = adjoint["gravity"]
            elif b.kind in _CABLES:
                grad[b.slice] = adjoint[b.kind][b.cables]
            else:
                grad[b.offset] = sum(float(np.dot(adjoint[k], d)) for k, d in self._partials(b, st).items())
        return grad

    def directions(self, theta: NDArray[np.float64]) -> list[dict[str, Any]]:
        """One forward-sensitivity direction (the extension's keys) per component of theta."""
        st = self.state(theta)
        out: list[dict[str, Any]] = []
        m = len(self.material0["density"])
        for b in self.blocks:
            if b.is_field:
                key = self.model.parameter(b.kind.removesuffix(_FIELD)).core_key
                for e in b.elements:
                    d = np.zeros(m)
                    d[e] = 1.0
                    out.append({key: d})
            elif b.kind == _GRAVITY:
                out.extend({"gravity": np.eye(3)[i]} for i in range(3))
            elif b.kind in _CABLES:
                for c in b.cables:
                    d = np.zeros(len(self.alpha0))
                    d[c] = 1.0
                    out.append({b.kind: d})
            else:
                out.append(self._partials(b, st))
        return out

    # -- scaling: s = transform(theta), block by block --------------------------------------

    def check(self, theta: NDArray[np.float64], what: str) -> None:
        for b in self.blocks:
            v = theta[b.slice]
            if not np.all(b.transform.contains(v)):
                raise ParameterError(f"{what}: {b.name} must be {b.transform.domain()}, got {v.tolist()}", b.name)
            if not np.all(np.isfinite(v)):
                raise ParameterError(f"{what}: {b.name} must be finite, got {v.tolist()}", b.name)

    def to_s(self, theta: NDArray[np.float64]) -> NDArray[np.float64]:
        s = np.empty(self.size)
        for b in self.blocks:
            s[b.slice] = b.transform.to_s(theta[b.slice])
        return s

    def from_s(self, s: NDArray[np.float64]) -> NDArray[np.float64]:
        theta = np.empty(self.size)
        for b in self.blocks:
            theta[b.slice] = b.transform.from_s(s[b.slice])
        return theta

    def dtheta_ds(self, s: NDArray[np.float64]) -> NDArray[np.float64]:
        out = np.empty(self.size)
        for b in self.blocks:
            out[b.slice] = b.transform.dtheta_ds(s[b.slice])
        return out

    def bounds_s(self, bounds: Any) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Bounds in s; user bounds are one (lo, hi) per name (None = open) in theta units. A
        bound outside the transform's domain (0 for a log parameter) is no bound."""
        lo, hi = np.full(self.size, -np.inf), np.full(self.size, np.inf)
        if bounds is None:
            return lo, hi
        if isinstance(bounds, Mapping):
            unknown = [k for k in bounds if k not in self.names]
            if unknown:
                raise InputError(f"bounds: {unknown} are not parameters being fitted; expected names among {self.names}")
            bounds = [bounds.get(name) for name in self.names]
        if not isinstance(bounds, (list, tuple, np.ndarray)) or len(bounds) != len(self.blocks):
            raise InputError(f"bounds: expected one (lo, hi) per parameter {self.names}, got {describe(bounds)}")
        for b, pair in zip(self.blocks, bounds):
            if pair is None:
                continue
            if not isinstance(pair, (list, tuple, np.ndarray)) or len(pair) != 2:
                raise InputError(f"bounds: expected (lo, hi) for {b.name!r}, got {describe(pair)}")
            a, c = pair
            for value, target in ((a, lo), (c, hi)):
                if value is None:
                    continue
                if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) \
                        or math.isnan(float(value)):
                    raise InputError(f"bounds: expected numbers or None for {b.name!r}, got {describe(value)}")
                if not b.transform.contains(value):
                    continue
                target[b.slice] = b.transform.to_s(np.full(b.size, float(value)))
        if np.any(lo > hi):
            raise InputError(f"bounds: lower bound above upper bound for {self.names}")
        return lo, hi


def _element_set(value: ArrayLike, m: int, name: str) -> NDArray[np.int64]:
    arr = np.asarray(value)
    if arr.dtype == np.bool_:
        if arr.shape != (m,):
            raise InputError(f"{name}: a boolean element mask must have shape ({m},), got {arr.shape}")
        arr = np.flatnonzero(arr)
    arr = arr.astype(np.int64).reshape(-1)
    if arr.size == 0 or arr.min() < 0 or arr.max() >= m:
        raise InputError(f"{name}: expected a non-empty set of element indices in [0, {m})")
    return arr
