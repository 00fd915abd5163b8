"""The compressible Neo-Hookean model (sorofem's default): its declaration and :class:`NeoHookean`."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._validate import Range
from ._declarations import Form, Material, MaterialModel, Parameter, logit

__all__ = ["NEO_HOOKEAN", "NeoHookean", "lame_from_young", "young_from_lame"]


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
            formulation_ranges=(("mixed", _MIXED_LAMBDA),), core_key="lambda",
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
    core_name="neo_hookean",
)


class NeoHookean(Material, model=NEO_HOOKEAN):
    """Compressible Neo-Hookean material.

    Strain energy per unit rest volume (``I1 = tr(F^T F)``, ``J = det F``)::

        W = mu/2 (I1 - 3) - mu ln J + lambda/2 c(J)^2

    with ``c(J) = ln J`` (default) or ``J - 1``, chosen per body (``Body(volumetric=...)``).
    In the mixed formulation ``lambda/2 c(J)^2`` becomes the pressure field.

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
