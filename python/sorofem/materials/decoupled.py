"""The decoupled (isochoric + volumetric) models silicones are fitted with, in the form Abaqus and
ANSYS use: :class:`MooneyRivlin`, :class:`Yeoh` and :class:`Ogden` (1 to 3 terms).

With ``J = det F``, ``I1b = J^(-2/3) tr(F^T F)``, ``I2b = J^(-4/3) I2`` and ``lb_i = J^(-1/3)
lambda_i`` (``lambda_i`` the principal stretches)::

    Mooney-Rivlin  W = c10 (I1b - 3) + c01 (I2b - 3) + (J - 1)^2 / d1
    Yeoh           W = sum_i ci0 (I1b - 3)^i + sum_i (J - 1)^(2i) / d_i          (i = 1..3)
    Ogden          W = sum_p 2 mu_p / alpha_p^2 (lb_1^alpha_p + lb_2^alpha_p + lb_3^alpha_p - 3)
                       + (J - 1)^2 / d1

Moduli ``c``, ``mu`` in Pa, compressibilities ``d`` in 1/Pa. Small-strain shear modulus
``2 (c10 + c01)``, ``2 c10``, ``sum_p mu_p``; bulk modulus ``2 / d1``. ``d1 > 0`` in both
formulations: with ``formulation="mixed"`` the volumetric term becomes the pressure field, whose
compliance vanishes as ``d1 -> 0`` (the incompressible limit), while ``d1 = 0`` itself has no bulk
modulus; Yeoh's ``d2``, ``d3`` terms stay displacement-based there (they have no stiffness at
``J = 1``, so they cannot lock). Coefficients fits give of either sign (``c01``, ``c20``, ``c30``,
Ogden's ``mu_p`` and ``alpha_p``) are optimised by :func:`sorofem.estimate` as they are; positive
moduli and compressibilities in log space.

Examples
--------
>>> import sorofem as sf
>>> sf.Yeoh(c10=12e3, c20=-0.3e3, c30=0.02e3, d1=2e-6, density=1070).to_dict()["c20"]
-300.0
>>> sf.Ogden(mu=[1887, 22250, 3574], alpha=[-3.848, 0.663, 4.225], d1=2.93e-6).terms
3
"""

from __future__ import annotations

from typing import Any, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._validate import Range, describe
from ..errors import ParameterError
from ._declarations import IDENTITY, LOG, Form, Material, MaterialModel, Parameter

__all__ = ["MOONEY_RIVLIN", "YEOH", "OGDEN", "OGDEN_TERMS", "MooneyRivlin", "Yeoh", "Ogden"]

#: The most Ogden terms a material may have.
MAX_OGDEN_TERMS = 3

_D1 = Parameter(
    "d1", "D1", "1/Pa", "compressibility, bulk modulus K = 2 / d1",
    Range(gt=0, low_note="d1 = 0 (incompressible) has no bulk modulus; for a nearly incompressible silicone give "
          "a small d1, e.g. 1e-3 / shear modulus, with formulation='mixed'"),
    core_key="d1",
)


def _higher_compressibility(name: str) -> Parameter:
    return Parameter(
        name, name.upper(), "1/Pa", f"compressibility of the (J - 1)^{2 * int(name[1])} term (0: no term)",
        Range(ge=0, low_note="a negative compressibility makes the energy unbounded below; 0 means no such term"),
        core_key=name, default=0.0,
    )


MOONEY_RIVLIN = MaterialModel(
    name="mooney-rivlin",
    title="decoupled Mooney-Rivlin",
    energy="W = c10 (I1b - 3) + c01 (I2b - 3) + (J - 1)^2 / d1",
    parameters=(
        Parameter("c10", "C10", "Pa", "first Mooney-Rivlin coefficient (c10 + c01 > 0)", Range(), IDENTITY,
                  core_key="c10"),
        Parameter("c01", "C01", "Pa", "second Mooney-Rivlin coefficient (c10 + c01 > 0)", Range(), IDENTITY,
                  core_key="c01"),
        _D1,
    ),
    forms=(Form(("c10", "c01", "d1")),),
    core_name="mooney_rivlin",
)

YEOH = MaterialModel(
    name="yeoh",
    title="decoupled Yeoh",
    energy="W = c10 (I1b - 3) + c20 (I1b - 3)^2 + c30 (I1b - 3)^3 + (J - 1)^2 / d1 + (J - 1)^4 / d2 + (J - 1)^6 / d3",
    parameters=(
        Parameter("c10", "C10", "Pa", "first Yeoh coefficient (shear modulus 2 c10)",
                  Range(gt=0, low_note="the small-strain shear modulus is 2 c10"), LOG, core_key="c10"),
        Parameter("c20", "C20", "Pa", "second Yeoh coefficient", Range(), IDENTITY, core_key="c20"),
        Parameter("c30", "C30", "Pa", "third Yeoh coefficient", Range(), IDENTITY, core_key="c30"),
        _D1,
        _higher_compressibility("d2"),
        _higher_compressibility("d3"),
    ),
    forms=(Form(("c10", "c20", "c30", "d1", "d2", "d3")),),
    core_name="yeoh",
)


def _ogden(terms: int) -> MaterialModel:
    parameters: list[Parameter] = []
    for p in range(terms):
        parameters.append(Parameter(f"mu:{p}", f"mu_{p}", "Pa", f"modulus of Ogden term {p} (sum of the mu_p > 0)",
                                    Range(), IDENTITY, core_key=f"mu:{p}"))
        parameters.append(Parameter(f"alpha:{p}", f"alpha_{p}", "", f"exponent of Ogden term {p} (nonzero)",
                                    Range(), IDENTITY, core_key=f"alpha:{p}"))
    parameters.append(_D1)
    return MaterialModel(
        name="ogden",
        title="decoupled Ogden",
        energy="W = sum_p 2 mu_p / alpha_p^2 (lb_1^alpha_p + lb_2^alpha_p + lb_3^alpha_p - 3) + (J - 1)^2 / d1",
        parameters=tuple(parameters),
        forms=(Form(tuple(p.name for p in parameters)),),
        core_name="ogden",
        core_options=(("terms", terms),),
    )


#: The Ogden declaration of each term count; :data:`OGDEN` (3 terms) lists every name.
OGDEN_TERMS: dict[int, MaterialModel] = {n: _ogden(n) for n in range(1, MAX_OGDEN_TERMS + 1)}
OGDEN = OGDEN_TERMS[MAX_OGDEN_TERMS]


def _check_shear(material: Material, names: Sequence[str], what: str) -> None:
    """``sum of names > 0`` in every element (a positive small-strain shear modulus)."""
    total = np.sum([np.asarray(material.value(n), dtype=np.float64) for n in names], axis=0)
    if np.all(total > 0):
        return
    bad = float(np.ravel(total)[np.ravel(total <= 0)][0])
    where = " (per-element)" if np.ndim(total) else ""
    raise ParameterError(
        f"{names[0]}: expected {' + '.join(names)} > 0 Pa (the small-strain shear modulus is {what}), got a sum of "
        f"{bad}{where}",
        names[0],
    )


class MooneyRivlin(Material, model=MOONEY_RIVLIN):
    """Decoupled Mooney-Rivlin material, ``W = c10 (I1b - 3) + c01 (I2b - 3) + (J - 1)^2 / d1``.

    Each value is a scalar or a per-element array ``(n_tets,)``.

    Parameters
    ----------
    c10, c01
        Pa, either sign (fits often give ``c01 < 0``) with ``c10 + c01 > 0``: the small-strain
        shear modulus is ``2 (c10 + c01)``.
    d1
        1/Pa, > 0: the bulk modulus is ``2 / d1``.
    density
        kg/m^3, >= 0.

    Raises
    ------
    ParameterError
        A value out of range or not finite, ``c10 + c01 <= 0``; the message names the parameter.

    Examples
    --------
    >>> import sorofem as sf
    >>> silicone = sf.MooneyRivlin(c10=10e3, c01=2e3, d1=4e-6, density=1070)
    >>> silicone
    MooneyRivlin(c10=10000, c01=2000, d1=4e-06, density=1070)
    """

    def __init__(self, c10: ArrayLike, c01: ArrayLike, d1: ArrayLike, *, density: ArrayLike = 0.0) -> None:
        super().__init__({"c10": c10, "c01": c01, "d1": d1}, density)
        _check_shear(self, ("c10", "c01"), "2 (c10 + c01)")


class Yeoh(Material, model=YEOH):
    """Decoupled Yeoh material,
    ``W = sum_i ci0 (I1b - 3)^i + sum_i (J - 1)^(2i) / d_i`` (i = 1..3).

    Each value is a scalar or a per-element array ``(n_tets,)``.

    Parameters
    ----------
    c10
        Pa, > 0: the small-strain shear modulus is ``2 c10``.
    c20, c30
        Pa, either sign (fits commonly give ``c20 < 0``); 0 by default.
    d1
        1/Pa, > 0 (required): the bulk modulus is ``2 / d1``.
    d2, d3
        1/Pa, >= 0; 0 (the default) means no such term.
    density
        kg/m^3, >= 0.

    Raises
    ------
    ParameterError
        ``d1`` not given, a value out of range or not finite; the message names the parameter.

    Examples
    --------
    >>> import sorofem as sf
    >>> sf.Yeoh(12e3, -300.0, 20.0, 2e-6)
    Yeoh(c10=12000, c20=-300, c30=20, d1=2e-06, d2=0, d3=0, density=0)
    """

    def __init__(
        self,
        c10: ArrayLike,
        c20: ArrayLike = 0.0,
        c30: ArrayLike = 0.0,
        d1: ArrayLike | None = None,
        d2: ArrayLike = 0.0,
        d3: ArrayLike = 0.0,
        *,
        density: ArrayLike = 0.0,
    ) -> None:
        if d1 is None:
            raise ParameterError("d1: required, the compressibility > 0 in 1/Pa (bulk modulus 2 / d1)", "d1")
        super().__init__({"c10": c10, "c20": c20, "c30": c30, "d1": d1, "d2": d2, "d3": d3}, density)


def _terms(value: Any, name: str) -> list[Any]:
    """Ogden's per-term values: a list (or 1-D array) of numbers, or of per-element arrays (or a
    ``(terms, n_tets)`` array)."""
    if isinstance(value, np.ndarray) and value.ndim in (1, 2):
        return list(value)
    if isinstance(value, (list, tuple)):
        return list(value)
    raise ParameterError(f"{name}: expected a list of 1 to {MAX_OGDEN_TERMS} values, one per Ogden term, got "
                         f"{describe(value)}", name)


class Ogden(Material, model=OGDEN):
    """Decoupled Ogden material with 1 to 3 terms,
    ``W = sum_p 2 mu_p / alpha_p^2 (lb_1^alpha_p + lb_2^alpha_p + lb_3^alpha_p - 3) + (J - 1)^2 / d1``.

    In this convention (Abaqus's) ``alpha = 2`` is Mooney-Rivlin's ``c10 = mu/2`` and
    ``alpha = -2`` its ``c01 = mu/2``. The parameter names of :func:`sorofem.estimate` are
    ``"mu:0"``, ``"alpha:0"``, ``"mu:1"``, ... and ``"d1"``. Each value (each term's, for ``mu``
    and ``alpha``) is a scalar or a per-element array ``(n_tets,)``.

    Parameters
    ----------
    mu
        Pa, one per term (1 to 3), either sign with ``sum_p mu_p > 0``: the small-strain shear
        modulus.
    alpha
        One nonzero exponent per term.
    d1
        1/Pa, > 0: the bulk modulus is ``2 / d1``.
    density
        kg/m^3, >= 0.

    Raises
    ------
    ParameterError
        ``mu`` and ``alpha`` of different lengths, no term or more than 3, ``alpha_p = 0``,
        ``sum mu_p <= 0``, ``d1 <= 0``, a value not finite; the message names the parameter
        (``"alpha:1"`` for the second exponent).

    Examples
    --------
    >>> import sorofem as sf
    >>> rubber = sf.Ogden(mu=[30e3, -1e3], alpha=[1.8, -2.2], d1=5e-6)
    >>> rubber.terms, rubber.mu, rubber.alpha
    (2, (30000.0, -1000.0), (1.8, -2.2))
    """

    def __init__(
        self, mu: Sequence[ArrayLike], alpha: Sequence[ArrayLike], d1: ArrayLike, *, density: ArrayLike = 0.0
    ) -> None:
        moduli, exponents = _terms(mu, "mu"), _terms(alpha, "alpha")
        if len(exponents) != len(moduli):
            raise ParameterError(
                f"alpha: expected as many exponents as moduli mu ({len(moduli)}), got {len(exponents)}", "alpha"
            )
        if not 1 <= len(moduli) <= MAX_OGDEN_TERMS:
            raise ParameterError(f"mu: expected 1 to {MAX_OGDEN_TERMS} Ogden terms, got {len(moduli)}", "mu")
        self.model = OGDEN_TERMS[len(moduli)]
        values: dict[str, Any] = {}
        for p, (m, a) in enumerate(zip(moduli, exponents)):
            values[f"mu:{p}"], values[f"alpha:{p}"] = m, a
        super().__init__({**values, "d1": d1}, density)
        for p in range(len(moduli)):
            if np.any(np.asarray(self.value(f"alpha:{p}")) == 0):
                raise ParameterError(f"alpha:{p}: expected a nonzero exponent (the term divides by it), got 0",
                                     f"alpha:{p}")
        _check_shear(self, [f"mu:{p}" for p in range(len(moduli))], "sum_p mu_p")

    @property
    def terms(self) -> int:
        """The number of terms (1 to 3)."""
        return len(self.model.parameters) // 2

    @property
    def mu(self) -> tuple[float | NDArray[np.float64], ...]:
        """``mu_p``, Pa, one per term."""
        return tuple(self.value(f"mu:{p}") for p in range(self.terms))

    @property
    def alpha(self) -> tuple[float | NDArray[np.float64], ...]:
        """``alpha_p``, one per term."""
        return tuple(self.value(f"alpha:{p}") for p in range(self.terms))
