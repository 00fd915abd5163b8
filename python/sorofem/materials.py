"""Material models: each model's parameter names, units, valid ranges and conversions, declared once.

A :class:`MaterialModel` lists the parameters a user may give (:class:`Parameter`: name,
symbol, units, valid :class:`Range`, the :class:`Transform` the inverse problems optimise it
in) and the :class:`Form` s in which they may be given: the first form is the core's own
parameters (what the extension's ``Model.set_material`` takes), every other form comes with its
conversion to the core's parameters and that conversion's Jacobian (for the chain rule of
:func:`sorofem.estimate`). Everything that reads or writes material parameters reads this
declaration: :class:`Material` (the validation and conversions behind :class:`NeoHookean`),
:class:`sorofem.Body` (formulation-specific ranges), :mod:`sorofem.inverse` (parameter names
and transforms, ``PARAMETERS``), the ``[material]`` table of scene files and the command line.

Density is common to every model (:data:`DENSITY`). Adding a model on the Python side is one
declaration and a short :class:`Material` subclass naming its keyword arguments::

    C10 = Parameter("c10", "C10", "Pa", "first Mooney-Rivlin coefficient", Range(gt=0), LOG)
    C01 = Parameter("c01", "C01", "Pa", "second Mooney-Rivlin coefficient", Range(ge=0), LOG)
    D1 = Parameter("d1", "D1", "1/Pa", "volumetric compliance 2 / K", Range(gt=0), LOG,
                   formulation_ranges=(("mixed", Range(ge=0)),))
    MOONEY_RIVLIN = MaterialModel("mooney-rivlin", "Mooney-Rivlin", "W = c10 (I1b - 3) + ...",
                                  parameters=(C10, C01, D1), forms=(Form(("c10", "c01", "d1")),))

    class MooneyRivlin(Material, model=MOONEY_RIVLIN):
        def __init__(self, c10, c01, d1, *, density=0.0):
            super().__init__({"c10": c10, "c01": c01, "d1": d1}, density)

and one entry in :data:`MODELS` (the scene's ``[material] model``).

Examples
--------
>>> import sorofem as sf
>>> from sorofem.materials import NEO_HOOKEAN
>>> [p.name for p in NEO_HOOKEAN.parameters]
['shear_modulus', 'lame_lambda', 'youngs_modulus', 'poisson_ratio']
>>> NEO_HOOKEAN.parameter("poisson_ratio").range.describe()
'>= 0 and < 0.5'
>>> sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45).to_core()[0]  # mu, Pa
22758.620689655174
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import Any, Callable, ClassVar, Mapping

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._validate import Range, as_float_array
from .errors import ParameterError, ShapeError

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
    "NeoHookean",
    "DENSITY",
    "NEO_HOOKEAN",
    "MODELS",
    "CLASSES",
    "model",
    "material_class",
    "lame_from_young",
    "young_from_lame",
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
        The key of the extension's sensitivities (``Model.adjoint``) for a core parameter.
    """

    name: str
    symbol: str
    units: str
    doc: str
    range: Range
    transform: Transform = LOG
    formulation_ranges: tuple[tuple[str, Range], ...] = ()
    core_key: str = ""

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
    """

    name: str
    title: str
    energy: str
    parameters: tuple[Parameter, ...]
    forms: tuple[Form, ...]
    fields: tuple[str, ...] = ()

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

    def estimable(self) -> tuple[str, ...]:
        """The :func:`sorofem.estimate` names of this model: its parameters, density and the
        per-element fields."""
        return self.names + tuple(f"{name}_field" for name in self.fields)


# ---------------------------------------------------------------------------
# Neo-Hookean


def lame_from_young(E: Any, nu: Any) -> tuple[Any, Any]:
    """``(mu, lambda)`` from Young's modulus and Poisson's ratio, elementwise:
    ``mu = E / (2 (1 + nu))``, ``lambda = E nu / ((1 + nu)(1 - 2 nu))`` (Pa)."""
    nu = np.asarray(nu)
    return np.divide(E, 2 * (1 + nu)), np.divide(np.multiply(E, nu), (1 + nu) * (1 - 2 * nu))


def young_from_lame(mu: Any, lam: Any) -> tuple[Any, Any]:
    """``(E, nu)`` from the Lame parameters, elementwise: ``E = mu (3 lambda + 2 mu) / (lambda + mu)``,
    ``nu = lambda / (2 (lambda + mu))``."""
    mu, lam = np.asarray(mu), np.asarray(lam)
    return mu * (3 * lam + 2 * mu) / (lam + mu), lam / (2 * (lam + mu))


def _lame_jacobian(E: Any, nu: Any) -> tuple[tuple[Any, Any], tuple[Any, Any]]:
    """``((dmu/dE, dlambda/dE), (dmu/dnu, dlambda/dnu))`` of :func:`lame_from_young`."""
    return (
        (1 / (2 * (1 + nu)), nu / ((1 + nu) * (1 - 2 * nu))),
        (-E / (2 * (1 + nu) ** 2), E * (1 + 2 * nu**2) / ((1 + nu) ** 2 * (1 - 2 * nu) ** 2)),
    )


#: Density, common to every model: it only matters under gravity and in dynamics.
DENSITY = Parameter("density", "rho", "kg/m^3", "density", Range(ge=0), core_key="rho")

_MIXED_LAMBDA = Range(
    gt=0,
    low_note="formulation='mixed' divides by lambda (compliance C = M_p / lambda); use formulation='standard' "
    "for nu = 0",
)

NEO_HOOKEAN = MaterialModel(
    name="neo-hookean",
    title="compressible Neo-Hookean",
    energy="W = mu/2 (I1 - 3) - mu ln J + lambda/2 c(J)^2, c(J) = ln J or J - 1",
    parameters=(
        Parameter("shear_modulus", "mu", "Pa", "shear modulus", Range(gt=0), core_key="mu"),
        Parameter(
            "lame_lambda", "lambda", "Pa", "Lame's first parameter",
            Range(ge=0, low_note="compressible Neo-Hookean needs lambda >= 0"),
            formulation_ranges=(("mixed", _MIXED_LAMBDA),), core_key="lam",
        ),
        Parameter("youngs_modulus", "E", "Pa", "Young's modulus", Range(gt=0)),
        Parameter(
            "poisson_ratio", "nu", "", "Poisson's ratio",
            Range(
                ge=0, lt=0.5,
                low_note="this compressible Neo-Hookean needs lame_lambda >= 0, i.e. nu >= 0",
                high_note="nu = 0.5 means lame_lambda = inf; both formulations need a finite lambda, the mixed one "
                "because its P1-P1 pressure modes are controlled only by the compliance M_p / lambda; model "
                "nearly incompressible silicone with e.g. nu = 0.4999 and formulation='mixed'",
            ),
            transform=logit(0.5),
        ),
    ),
    forms=(
        Form(("shear_modulus", "lame_lambda")),
        Form(
            ("youngs_modulus", "poisson_ratio"),
            to_core=lame_from_young,
            from_core=young_from_lame,
            jacobian=_lame_jacobian,
            blame=(("shear_modulus", "youngs_modulus"), ("lame_lambda", "poisson_ratio")),
        ),
    ),
    fields=("shear_modulus", "lame_lambda"),
)

#: Every model, by its scene name.
MODELS: dict[str, MaterialModel] = {NEO_HOOKEAN.name: NEO_HOOKEAN}


def model(name: str) -> MaterialModel:
    """The declaration of the model called ``name`` (a key of :data:`MODELS`).

    Raises
    ------
    ParameterError
        No such model.
    """
    if not isinstance(name, str) or name not in MODELS:
        raise ParameterError(f"model: expected one of {list(MODELS)}, got {name!r}", "model")
    return MODELS[name]


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


def material_class(name: str) -> type[Material]:
    """The class of the model called ``name`` (:class:`NeoHookean` for ``"neo-hookean"``).

    Raises
    ------
    ParameterError
        No such model.
    """
    if not isinstance(name, str) or name not in CLASSES:
        raise ParameterError(f"model: expected one of {list(CLASSES)}, got {name!r}", "model")
    return CLASSES[name]


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
    """

    model: ClassVar[MaterialModel]

    def __init_subclass__(cls, model: MaterialModel | None = None, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        if model is not None:
            cls.model = model
            CLASSES[model.name] = cls
            for p in (*model.parameters, DENSITY):
                if p.name not in cls.__dict__:
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
        the extension's ``Model.set_material`` (for Neo-Hookean ``(mu, lam, rho)``).

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
        """Plain summary (per-element arrays as their min and max), every parameter of the model."""

        def plain(v: Any) -> Any:
            if np.ndim(v) == 0:
                return float(v)
            return {"min": float(np.min(v)), "max": float(np.max(v)), "per_element": True}

        return {"model": self.model.name, **{name: plain(self._values[name]) for name in self.model.names}}

    def __repr__(self) -> str:
        def fmt(v: Any) -> str:
            return f"{float(v):.6g}" if np.ndim(v) == 0 else f"<{np.size(v)} values>"

        args = ", ".join(f"{name}={fmt(value)}" for name, value in self.given().items())
        return f"{type(self).__name__}({args})"


class NeoHookean(Material, model=NEO_HOOKEAN):
    """Compressible Neo-Hookean material.

    Strain energy per unit rest volume (``I1 = tr(F^T F)``, ``J = det F``)::

        W = mu/2 (I1 - 3) - mu ln J + lambda/2 c(J)^2

    with ``c(J) = ln J`` (default) or ``J - 1``, chosen per body (``Body(volumetric=...)``).

    Give exactly one of the pairs (``youngs_modulus``, ``poisson_ratio``) or
    (``shear_modulus``, ``lame_lambda``). Each value is a scalar or a per-element
    array of shape ``(n_tets,)`` (checked against the mesh when the material is used by a
    :class:`~sorofem.Body`). Names, units and ranges are declared in :data:`NEO_HOOKEAN`.

    Parameters
    ----------
    youngs_modulus
        E in Pa, > 0.
    poisson_ratio
        nu, with 0 <= nu < 0.5: lambda = E nu / ((1 + nu)(1 - 2 nu)) must be finite and
        >= 0 (> 0 in the mixed formulation, which divides by it). Nearly incompressible
        silicone: nu = 0.499 or 0.4999 with ``Body(..., formulation="mixed")``.
    shear_modulus
        mu = E / (2 (1 + nu)) in Pa, > 0.
    lame_lambda
        lambda in Pa, >= 0 (> 0 for the mixed formulation).
    density
        kg/m^3, >= 0 (only matters under gravity).

    Examples
    --------
    >>> import sorofem as sf
    >>> silicone = sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080)
    >>> round(silicone.shear_modulus), round(silicone.lame_lambda)
    (22759, 204828)
    """

    def __init__(
        self,
        youngs_modulus: ArrayLike | None = None,
        poisson_ratio: ArrayLike | None = None,
        *,
        shear_modulus: ArrayLike | None = None,
        lame_lambda: ArrayLike | None = None,
        density: ArrayLike = 0.0,
    ) -> None:
        super().__init__(
            {"youngs_modulus": youngs_modulus, "poisson_ratio": poisson_ratio, "shear_modulus": shear_modulus,
             "lame_lambda": lame_lambda},
            density,
        )

    @property
    def youngs_modulus(self) -> float | NDArray[np.float64]:
        """E, Pa."""
        return self.value("youngs_modulus")

    @property
    def poisson_ratio(self) -> float | NDArray[np.float64]:
        """nu, dimensionless."""
        return self.value("poisson_ratio")

    @property
    def shear_modulus(self) -> float | NDArray[np.float64]:
        """mu, Pa."""
        return self.value("shear_modulus")

    @property
    def lame_lambda(self) -> float | NDArray[np.float64]:
        """lambda, Pa."""
        return self.value("lame_lambda")

    @property
    def density(self) -> float | NDArray[np.float64]:
        """rho, kg/m^3."""
        return self.value("density")
