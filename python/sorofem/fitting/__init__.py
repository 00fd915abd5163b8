"""Fit hyperelastic models to homogeneous test data (uniaxial, equibiaxial, planar tension or
compression): the step before any FE run with a Mooney-Rivlin, Yeoh or Ogden silicone.

* :func:`fit_material` fits a model to one or more curves (arrays or CSV files) and returns a
  :class:`MaterialFit`: parameters with standard errors and identifiability, residuals,
  Drucker stability ranges, :meth:`~MaterialFit.summary`, :meth:`~MaterialFit.plot`,
  :meth:`~MaterialFit.to_dict`.
* :func:`nominal_stress` gives the homogeneous test curves of a model (incompressible in
  closed form, or compressible with the lateral stretch solved for zero traction) and
  :func:`nominal_stress_param_gradient` their derivatives with respect to every coefficient.
* :func:`read_curve` reads a CSV test curve (format in :mod:`sorofem.fitting.data`).

Examples
--------
>>> import numpy as np
>>> from sorofem.fitting import fit_material, nominal_stress
>>> stretch = np.linspace(0.7, 2.5, 30)
>>> truth = {"c10": 20e3, "c01": 5e3}
>>> data = [{"mode": m, "stretch": stretch, "nominal_stress": nominal_stress("mooney_rivlin", m, stretch, truth)}
...         for m in ("uniaxial", "equibiaxial")]
>>> fit = fit_material("mooney_rivlin", data)
>>> round(fit.params["c10"]), round(fit.params["c01"]), fit.identifiable["c01"]
(20000, 5000, True)
"""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from ..errors import ParameterError
from . import curves as _curves
from .cli import _cli
from .curves import MODES, StableRange
from .data import STRESS_UNITS, Curve, DataFileError, read_curve
from .fit import MaterialFit, fit_material, format_uncertain
from .models import MODELS, ModelSpec, model_spec

__all__ = [
    "MODELS",
    "MODES",
    "STRESS_UNITS",
    "Curve",
    "DataFileError",
    "MaterialFit",
    "ModelSpec",
    "StableRange",
    "fit_material",
    "format_uncertain",
    "lateral_stretch",
    "model_spec",
    "nominal_stress",
    "nominal_stress_param_gradient",
    "read_curve",
    "stable_range",
    "_cli",
]


def _theta(model: str, params: Mapping[str, float], terms: int | None, bulk_modulus: float | None
           ) -> tuple[ModelSpec, np.ndarray, float | None]:
    """The full parameter vector of ``params`` (missing coefficients 0) and the bulk modulus."""
    if terms is None and model == "ogden":
        terms = sum(1 for name in params if name.startswith("mu:"))
    spec = model_spec(model, terms)
    unknown = sorted(set(params) - set(spec.param_names))
    if unknown:
        raise ParameterError(f"{model} has no parameter {', '.join(unknown)}; its parameters are "
                             f"{', '.join(spec.param_names)}", unknown[0])
    theta = np.array([float(params.get(name, 0.0)) for name in spec.param_names])
    if not np.all(np.isfinite(theta)):
        bad = spec.param_names[int(np.flatnonzero(~np.isfinite(theta))[0])]
        raise ParameterError(f"{bad} must be finite, got {params[bad]!r}", bad)
    for k, name in enumerate(spec.param_names):
        if name.startswith("alpha") and theta[k] == 0.0:
            raise ParameterError(f"{name} = 0: an Ogden exponent must be non-zero", name)
        if name.startswith("d") and theta[k] < 0:
            raise ParameterError(f"{name} must be >= 0 (0: no volumetric term), got {theta[k]:g}", name)
    d = dict(zip(spec.param_names, theta))
    if "d1" in d:
        if d["d1"] == 0 and any(d.get(f"d{i}", 0.0) != 0 for i in (2, 3)):
            raise ParameterError("d2/d3 need d1 > 0 (d1 = 0 is the incompressible model)", "d1")
        if bulk_modulus is not None and d["d1"] == 0:
            d1 = 2.0 / float(bulk_modulus)
            theta[spec.param_names.index("d1")] = d1
        elif bulk_modulus is not None and not np.isclose(d["d1"], 2.0 / float(bulk_modulus), rtol=1e-12):
            raise ParameterError(f"bulk_modulus {bulk_modulus:g} Pa disagrees with d1 = {d['d1']:g} 1/Pa "
                                 "(K = 2/d1)", "bulk_modulus")
        bulk = 2.0 / theta[spec.param_names.index("d1")] if theta[spec.param_names.index("d1")] > 0 else None
    else:
        bulk = None if bulk_modulus is None else float(bulk_modulus)
    if bulk is not None and not (np.isfinite(bulk) and bulk > 0):
        raise ParameterError(f"bulk_modulus must be finite and > 0 Pa, got {bulk_modulus!r}", "bulk_modulus")
    return spec, theta, bulk


def nominal_stress(model: str, mode: str, stretch: Any, params: Mapping[str, float], *,
                   terms: int | None = None, bulk_modulus: float | None = None) -> np.ndarray:
    """Nominal (first Piola) stress in Pa of a homogeneous ``mode`` test at ``stretch`` ``(n,)``.

    ``params`` maps the model's parameter names to values (missing ones are 0; an Ogden term
    count is taken from the ``mu:k`` names). Incompressible unless ``bulk_modulus`` (Pa) or
    ``d1 > 0`` is given, in which case the lateral stretch is solved for zero lateral traction.

    >>> from sorofem.fitting import nominal_stress
    >>> float(nominal_stress("neo_hookean", "uniaxial", [2.0], {"mu": 1.0})[0])  # mu (lambda - lambda^-2)
    1.75
    """
    spec, theta, bulk = _theta(model, params, terms, bulk_modulus)
    stretch = _stretch(stretch)
    return _curves.nominal_stress(spec, theta, mode, stretch, bulk)[0]


def nominal_stress_param_gradient(model: str, mode: str, stretch: Any, params: Mapping[str, float], *,
                                  terms: int | None = None, bulk_modulus: float | None = None
                                  ) -> dict[str, np.ndarray]:
    """``d P / d theta`` for every parameter name: arrays ``(n,)`` in Pa per unit of the parameter
    (Neo-Hookean: at fixed bulk modulus), same arguments as :func:`nominal_stress`."""
    spec, theta, bulk = _theta(model, params, terms, bulk_modulus)
    grad = _curves.nominal_stress(spec, theta, mode, _stretch(stretch), bulk, with_gradient=True)[1]
    return {name: grad[:, k] for k, name in enumerate(spec.param_names)}


def lateral_stretch(model: str, mode: str, stretch: Any, params: Mapping[str, float], *,
                    terms: int | None = None, bulk_modulus: float | None = None) -> np.ndarray:
    """The lateral stretch ``t`` (direction 3, and 2 in uniaxial tests) of a homogeneous test:
    ``lambda^-1/2``, ``lambda^-2``, ``lambda^-1`` when incompressible, else the solution of
    zero lateral traction."""
    spec, theta, bulk = _theta(model, params, terms, bulk_modulus)
    stretch = _stretch(stretch)
    if bulk is None:
        return _curves.incompressible_lateral(mode, stretch)
    return np.exp(_curves.lateral_log_stretch(spec, theta, mode, stretch, bulk)[0])


def stable_range(model: str, mode: str, params: Mapping[str, float], *, terms: int | None = None
                 ) -> StableRange | None:
    """The Drucker-stable stretch interval of the incompressible model in ``mode`` (see
    :func:`sorofem.fitting.curves.drucker_eigenvalue`), ``None`` if unstable at rest."""
    spec, theta, _ = _theta(model, params, terms, None)
    return _curves.stable_range(spec, theta, _curves.check_mode(mode))


def _stretch(stretch: Any) -> np.ndarray:
    array = np.atleast_1d(np.asarray(stretch, dtype=np.float64))
    if array.ndim != 1 or not np.all(np.isfinite(array) & (array > 0)):
        raise ParameterError("stretch must be a 1-D array of finite positive values", "stretch")
    return array

