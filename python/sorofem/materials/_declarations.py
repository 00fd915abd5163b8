"""The declaration machinery of :mod:`sorofem.materials`: transforms, :class:`Parameter`,
:class:`Form`, :class:`MaterialModel` and the :class:`Material` base class that checks and converts
a model's values. The models themselves are declared in :mod:`sorofem.materials.neo_hookean` and
:mod:`sorofem.materials.decoupled`."""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Mapping

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._validate import Range, as_float_array
from ..errors import ParameterError, ShapeError

__all__ = [
    "Range",
    "Transform",
    "LOG",
    "IDENTITY",
    "logit",
    "Parameter",
    "Form",
    "MaterialModel",
    "Material",
    "DENSITY",
    "CLASSES",
    "keywords",
]


# ---------------------------------------------------------------------------
# Transforms


@dataclass(frozen=True)
class Transform:
    """The unbounded variable ``s`` in which :func:`sorofem.estimate` optimises a parameter
    ``theta``: ``"log"`` (``s = ln theta``, theta > 0), ``"logit"`` (``s = ln(theta / (upper -
    theta))``, 0 < theta < upper) or ``"identity"``. Mu and lambda, orders of magnitude apart,
    are equally well scaled in log space."""

    kind: str
    upper: float = 1.0

    def to_s(self, theta: NDArray[np.float64]) -> NDArray[np.float64]:
        """``s(theta)``, elementwise."""
        with np.errstate(divide="ignore"):
            if self.kind == "log":
                return np.log(np.abs(theta))
            if self.kind == "logit":
                return np.log(theta / np.abs(self.upper - theta))
        return np.asarray(theta, dtype=np.float64)

    def from_s(self, s: NDArray[np.float64]) -> NDArray[np.float64]:
        """``theta(s)``, elementwise."""
        with np.errstate(over="ignore"):
            if self.kind == "log":
                return np.exp(s)
            if self.kind == "logit":
                return self.upper / (1 + np.exp(-s))
        return np.asarray(s, dtype=np.float64)

    def dtheta_ds(self, s: NDArray[np.float64]) -> NDArray[np.float64]:
        """``d theta / d s``, elementwise."""
        theta = self.from_s(s)
        if self.kind == "log":
            return theta
        if self.kind == "logit":
            return theta * (1 - theta / self.upper)
        return np.ones_like(theta)

    def contains(self, theta: ArrayLike) -> NDArray[np.bool_]:
        """Whether ``theta`` lies where ``s`` is finite."""
        x = np.asarray(theta, dtype=np.float64)
        if self.kind == "log":
            return x > 0
        if self.kind == "logit":
            return (x > 0) & (x < self.upper)
        return np.isfinite(x)

    def domain(self) -> str:
        """Where the transform is defined, for messages: ``"> 0"``, ``"in (0, 0.5)"``."""
        return {"log": "> 0", "logit": f"in (0, {self.upper:g})"}.get(self.kind, "finite")


#: ``s = ln theta``: positive parameters.
LOG = Transform("log")
#: ``s = theta``: parameters of any sign (gravity).
IDENTITY = Transform("identity")


def logit(upper: float) -> Transform:
    """``s = ln(theta / (upper - theta))`` for a parameter in ``(0, upper)``."""
    return Transform("logit", upper)


# ---------------------------------------------------------------------------
# Declarations


@dataclass(frozen=True)
class Parameter:
    """One material parameter.

    Attributes
    ----------
    name
        The keyword of the material class, the scene key and the :func:`sorofem.estimate` name.
    symbol
        For messages and documentation (``"E"``, ``"nu"``).
    units
        SI units (``""``: dimensionless).
    doc
        What it is, in a few words.
    range
        Valid values in every formulation.
    transform
        The space the inverse problems optimise it in.
    formulation_ranges
        ``(formulation, Range)`` pairs: stricter ranges a formulation needs (the mixed one
        divides by lambda).
    core_key
        For a core parameter, its name in the extension (``Model.set_material_model``'s
        parameter keys and the sensitivities' ``Model.adjoint``/``Model.forward`` keys: ``"mu"``,
        ``"lambda"``, ``"c10"``, ``"mu:0"``); ``"rho"`` for density.
    default
        The value a material class takes when the parameter is not given (Yeoh's ``c20 = 0``);
        None: required. Scene files read it too.
    """

    name: str
    symbol: str
    units: str
    doc: str
    range: Range
    transform: Transform = LOG
    formulation_ranges: tuple[tuple[str, Range], ...] = ()
    core_key: str = ""
    default: float | None = None

    def check(self, values: ArrayLike) -> None:
        """Raise a :class:`ParameterError` naming this parameter when a value is out of range."""
        self.range.check(values, self.name, self.symbol, self.units)

    def range_for(self, formulation: str) -> Range | None:
        """The stricter range ``formulation`` needs, or None."""
        return dict(self.formulation_ranges).get(formulation)


@dataclass(frozen=True)
class Form:
    """One way to give a model's parameters: the names, and (except for the core's own form)
    the conversion to the core's parameters.

    Attributes
    ----------
    names
        The parameters given together, e.g. ``("youngs_modulus", "poisson_ratio")``.
    to_core
        ``f(*values) -> core values`` (in the order of the model's first form), elementwise on
        arrays; None for the core's own form.
    from_core
        The inverse conversion: ``f(*core values) -> values`` in the order of ``names``.
    jacobian
        ``f(*values) -> J`` with ``J[i][j] = d core_j / d names_i``, elementwise.
    blame
        ``(core name, given name)`` pairs: which given parameter to name when a converted core
        value breaks a formulation's range (lambda = 0 comes from nu = 0).
    """

    names: tuple[str, ...]
    to_core: Callable[..., tuple[Any, ...]] | None = None
    from_core: Callable[..., tuple[Any, ...]] | None = None
    jacobian: Callable[..., tuple[tuple[Any, ...], ...]] | None = None
    blame: tuple[tuple[str, str], ...] = ()

    def label(self) -> str:
        return "(" + ", ".join(self.names) + ")"


@dataclass(frozen=True)
class MaterialModel:
    """A hyperelastic model as the Python side sees it: its parameters and the forms they come in.

    Attributes
    ----------
    name
        The scene's ``[material] model`` and ``to_dict()["model"]``.
    title
        For documentation and messages.
    energy
        The strain energy density, for documentation.
    parameters
        Every parameter of every form.
    forms
        ``forms[0]`` is the core's own (the extension's ``set_material`` order); the others
        convert to it.
    fields
        Core parameters :func:`sorofem.estimate` may fit per element (``"<name>_field"``).
    core_name
        The extension's name of the model (``Model.set_material_model``): ``"neo_hookean"``.
    core_options
        The model options the extension takes with it (Ogden's ``("terms", 2)``).

    A parameter named ``"base:k"`` is component k of a vector given as one keyword ``base``
    (Ogden's ``mu=[...]`` holds ``"mu:0"``, ``"mu:1"``, ...): :func:`keywords` groups them.
    """

    name: str
    title: str
    energy: str
    parameters: tuple[Parameter, ...]
    forms: tuple[Form, ...]
    fields: tuple[str, ...] = ()
    core_name: str = ""
    core_options: tuple[tuple[str, Any], ...] = ()

    def parameter(self, name: str) -> Parameter:
        """The declaration of ``name`` (density included)."""
        if name == DENSITY.name:
            return DENSITY
        for p in self.parameters:
            if p.name == name:
                return p
        raise KeyError(name)

    @property
    def names(self) -> tuple[str, ...]:
        """Every parameter name, density last."""
        return tuple(p.name for p in self.parameters) + (DENSITY.name,)

    @property
    def core_form(self) -> Form:
        return self.forms[0]

    def form_of(self, given: Mapping[str, Any], owner: str) -> Form:
        """The form whose names are exactly those ``given``, or a :class:`ParameterError`
        (``owner``: the class name for the message)."""
        names = set(given)
        for form in self.forms:
            if names == set(form.names):
                return form
        choices = " or ".join(f.label() for f in self.forms)
        article = "pair" if all(len(f.names) == 2 for f in self.forms) else "set"
        ordered = [p.name for p in self.parameters if p.name in names]
        raise ParameterError(
            f"{owner}: give exactly one {article}, {choices}; got {', '.join(ordered) or 'none'}",
            ordered[0] if ordered else self.forms[-1].names[0],
        )

    def keywords(self, form: Form | None = None) -> tuple[str, ...]:
        """The material class's keywords for ``form`` (default: every form's), vectors grouped:
        ``("mu", "alpha", "d1")`` for Ogden."""
        forms = self.forms if form is None else (form,)
        return keywords([name for f in forms for name in f.names])

    def estimable(self) -> tuple[str, ...]:
        """The :func:`sorofem.estimate` names of this model: its parameters, density and the
        per-element fields."""
        return self.names + tuple(f"{name}_field" for name in self.fields)


# ---------------------------------------------------------------------------


def keywords(names: Iterable[str]) -> tuple[str, ...]:
    """Parameter names as a material class's keywords: ``"mu:0"``, ``"mu:1"`` -> ``"mu"``."""
    return tuple(dict.fromkeys(name.partition(":")[0] for name in names))


#: Density, common to every model: it only matters under gravity and in dynamics.
DENSITY = Parameter("density", "rho", "kg/m^3", "density", Range(ge=0), core_key="rho")


# ---------------------------------------------------------------------------
# Material values


def _material_value(value: Any, name: str) -> float | NDArray[np.float64]:
    """A finite scalar, or a finite 1-D per-element array (read-only)."""
    if isinstance(value, bool):
        raise ParameterError(f"{name}: expected a number or a per-element array, got {value!r}", name)
    if isinstance(value, numbers.Real):
        out = float(value)
        if not math.isfinite(out):
            raise ParameterError(f"{name}: expected a finite value, got {out}", name)
        return out
    try:
        arr = as_float_array(value, name, (None,))
    except ShapeError as exc:
        raise ParameterError(
            f"{name}: expected a number or a per-element array of shape (n_tets,): {exc}", name
        ) from None
    if arr.size == 0:
        raise ParameterError(f"{name}: expected a number or a per-element array, got an empty array", name)
    if not np.all(np.isfinite(arr)):
        raise ParameterError(f"{name}: expected finite values, got {arr[~np.isfinite(arr)][0]}", name)
    arr.setflags(write=False)
    return arr


def _plain(value: Any) -> Any:
    """Scalars as float, so repr and to_dict stay readable."""
    return float(value) if np.ndim(value) == 0 else value


#: The material class of each model, by the model's name (filled as the classes are defined).
CLASSES: dict[str, type[Material]] = {}


def _getter(p: Parameter) -> Callable[[Material], Any]:
    def get(self: Material) -> Any:
        return self.value(p.name)

    return get


class Material:
    """Values of one :class:`MaterialModel`'s parameters, each a scalar or a per-element array.

    Subclasses set the model (``class NeoHookean(Material, model=NEO_HOOKEAN)``) and name the
    keyword arguments; this class checks the values against the declaration (ranges, exactly
    one form, finiteness), converts them to the core's parameters and back, and gives every
    parameter of the model as a property.

    Parameters
    ----------
    values
        Parameter name -> value (None: not given); the names given must be exactly one form.
    density
        kg/m^3, >= 0.

    Attributes
    ----------
    model
        The declaration (a class attribute; an Ogden material carries the one of its term count).
    source
        Where the values come from (:data:`sorofem.materials.library` entries: the citation,
        location and quote), or None; :meth:`to_dict` includes it.
    """

    model: MaterialModel
    source: Mapping[str, Any] | None = None

    def __init_subclass__(cls, model: MaterialModel | None = None, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if model is not None:
            cls.model = model
            CLASSES[model.name] = cls
            for p in (*model.parameters, DENSITY):
                if p.name not in cls.__dict__ and p.name.isidentifier():
                    setattr(cls, p.name, property(_getter(p), doc=f"{p.symbol}, {p.units or 'dimensionless'}."))

    def __init__(self, values: Mapping[str, ArrayLike | None], density: ArrayLike = 0.0) -> None:
        spec = self.model
        given = {k: v for k, v in values.items() if v is not None}
        form = spec.form_of(given, type(self).__name__)
        checked = {}
        for name in form.names:
            value = _material_value(given[name], name)
            spec.parameter(name).check(value)
            checked[name] = value
        rho = _material_value(density, DENSITY.name)
        DENSITY.check(rho)
        core_names = spec.core_form.names
        core = [checked[n] for n in core_names] if form.to_core is None else list(form.to_core(*checked.values()))
        if form.to_core is None:
            for name, value in zip(core_names, core):
                spec.parameter(name).check(value)
        self._form = form
        self._values: dict[str, Any] = dict(zip(core_names, core))
        for other in spec.forms[1:]:
            self._values.update(zip(other.names, other.from_core(*core)))  # type: ignore[misc]
        self._values.update(checked)
        self._values[DENSITY.name] = rho
        self._values = {k: _plain(v) for k, v in self._values.items()}

    # -- values -----------------------------------------------------------------------

    @property
    def form(self) -> Form:
        """The form the values were given in."""
        return self._form

    def value(self, name: str) -> float | NDArray[np.float64]:
        """The value of parameter ``name`` (any form's, or ``"density"``): a float or a
        per-element array."""
        return self._values[name]

    def given(self) -> dict[str, float | NDArray[np.float64]]:
        """The values as given (one form, and density), by name."""
        return {name: self._values[name] for name in (*self._form.names, DENSITY.name)}

    def to_core(self) -> list[float | NDArray[np.float64]]:
        """The core's parameters (the first form's), scalars or per-element arrays."""
        return [self._values[name] for name in self.model.core_form.names]

    def per_element(self, n_tets: int) -> tuple[NDArray[np.float64], ...]:
        """The core's parameters and the density, each ``(n_tets,)`` float64: the arguments of
        :meth:`core_material` (for Neo-Hookean ``(mu, lambda, rho)``).

        Raises
        ------
        ParameterError
            A per-element array does not have length ``n_tets``; the error names the parameter
            as given.
        """
        out = []
        core = self.model.core_form.names
        blame = dict(self._form.blame)
        for name in (*core, DENSITY.name):
            value = np.asarray(self._values[name], dtype=np.float64)
            if value.ndim == 0:
                value = np.full(n_tets, float(value))
            elif value.shape != (n_tets,):
                shown = name if name == DENSITY.name or self._form.to_core is None else "/".join(self._form.names)
                raise ParameterError(
                    f"{shown}: per-element values must have shape ({n_tets},) (one per tet), got shape {value.shape}",
                    blame.get(name, name),
                )
            out.append(np.ascontiguousarray(value))
        return tuple(out)

    def core_material(self, n_tets: int) -> tuple[str, dict[str, NDArray[np.float64]], NDArray[np.float64], dict[str, Any] | None]:
        """The arguments of the extension's ``Model.set_material_model``: the core's model
        name, its parameters by core name (each ``(n_tets,)``), the density ``(n_tets,)`` and
        the model's options (None: none).

        Raises
        ------
        ParameterError
            As :meth:`per_element`.
        """
        *core, density = self.per_element(n_tets)
        names = [self.model.parameter(n).core_key for n in self.model.core_form.names]
        return self.model.core_name, dict(zip(names, core)), density, dict(self.model.core_options) or None

    def keyword_values(self, form: Form | None = None) -> dict[str, Any]:
        """The values of ``form``'s parameters (default: the form given) as the class's keyword
        arguments, vectors grouped (Ogden's ``mu=[...]``); density not included."""
        names = (form or self._form).names
        out: dict[str, Any] = {}
        for name in names:
            base, vector, _ = name.partition(":")
            if vector:
                out.setdefault(base, []).append(self._values[name])
            else:
                out[name] = self._values[name]
        return out

    def with_values(self, values: Mapping[str, Any], density: ArrayLike) -> "Material":
        """A material of the same class (and, for Ogden, term count) from the values of the
        core's parameters by name (``self.model.core_form.names``; scalars or per-element
        arrays) and ``density``; checked like the constructor's."""
        kwargs: dict[str, Any] = {}
        for name in self.model.core_form.names:
            base, vector, _ = name.partition(":")
            if vector:
                kwargs.setdefault(base, []).append(values[name])
            else:
                kwargs[name] = values[name]
        return type(self)(**kwargs, density=density)

    def with_source(self, source: Mapping[str, Any]) -> "Material":
        """This material, saying where its values come from (``source``: plain data for
        ``summary.json``)."""
        out = type(self)(**self.keyword_values(), density=self._values[DENSITY.name])
        out.source = dict(source)
        return out

    def check_formulation(self, formulation: str, n_tets: int) -> None:
        """Raise a :class:`ParameterError` when a core value breaks ``formulation``'s stricter
        range (lambda > 0 for ``"mixed"``), naming the parameter as given."""
        values = self.per_element(n_tets)
        blame = dict(self._form.blame)
        for name, value in zip(self.model.core_form.names, values):
            strict = self.model.parameter(name).range_for(formulation)
            if strict is None or np.all(strict.contains(value)):
                continue
            parameter = self.model.parameter(name)
            shown = blame.get(name, name)
            bad = float(value[~strict.contains(value)][0])
            raise ParameterError(
                f"{shown}: formulation={formulation!r} needs {name} {strict.describe()} in every element, got "
                f"{name} = {bad} {parameter.units}; {strict.low_note or strict.high_note}",
                shown,
            )

    def to_dict(self) -> dict[str, Any]:
        """Plain summary: the model, every parameter (per-element arrays as their min and max;
        vectors as lists, Ogden's ``"mu": [...]``), density, and the source when there is one."""

        def plain(v: Any) -> Any:
            if isinstance(v, list):
                return [plain(x) for x in v]
            if np.ndim(v) == 0:
                return float(v)
            return {"min": float(np.min(v)), "max": float(np.max(v)), "per_element": True}

        values: dict[str, Any] = {}
        for name in self.model.names:
            base, vector, _ = name.partition(":")
            if vector:
                values.setdefault(base, []).append(self._values[name])
            else:
                values[name] = self._values[name]
        out = {"model": self.model.name, **{name: plain(v) for name, v in values.items()}}
        if self.source is not None:
            out["source"] = dict(self.source)
        return out

    def __repr__(self) -> str:
        def fmt(v: Any) -> str:
            if isinstance(v, list):
                return "[" + ", ".join(fmt(x) for x in v) + "]"
            return f"{float(v):.6g}" if np.ndim(v) == 0 else f"<{np.size(v)} values>"

        given = {**self.keyword_values(), DENSITY.name: self._values[DENSITY.name]}
        args = ", ".join(f"{name}={fmt(value)}" for name, value in given.items())
        return f"{type(self).__name__}({args})"
