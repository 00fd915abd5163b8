"""Least-squares fits of hyperelastic models to homogeneous test curves."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from ..errors import ConvergenceError, ParameterError, SolverError
from .curves import MODES, StableRange, nominal_stress, stable_range
from .data import Curve, as_curves
from .models import ModelSpec, model_spec, small_strain_moduli
from .plotting import plot_fit

__all__ = ["MaterialFit", "fit_material", "format_uncertain"]

Array = NDArray[np.float64]

# A parameter is not identifiable when it has a component in a direction whose scaled
# singular value is below this fraction of the largest (cond(J^T J) > 1e16: numerically singular).
_SINGULAR = 1e-8
# Above this condition number of the column-scaled J^T J the fit warns of correlated parameters.
_ILL_CONDITIONED = 1e8
# A standard error above this fraction of the value: the parameter is poorly determined.
_POORLY_DETERMINED = 0.5
# Relative weights floor: points with |P| below this fraction of their curve's largest |P|
# count as if they had that stress, so the rest state P = 0 does not get an infinite weight.
_RELATIVE_FLOOR = 1e-3
# Starting exponents of the Ogden multi-start (each combination of distinct values).
_ALPHA_STARTS = (-4.0, -2.0, -1.0, 1.0, 2.0, 4.0, 8.0)
_ALPHA_BOUND = (1e-3, 40.0)
_PLAUSIBLE_SHEAR = (10.0, 1e9)
_MAX_NFEV = 3000


@dataclass
class MaterialFit:
    """The result of :func:`fit_material`.

    Attributes
    ----------
    model, terms
        The model name and its number of terms (Yeoh coefficients or Ogden pairs).
    params
        Every parameter of the model by its Rust-core name (Pa, 1/Pa, dimensionless alpha),
        fitted and fixed alike; ``d1 = 0`` means incompressible.
    free
        The names that were fitted; the others were held fixed.
    standard_errors
        Per fitted name, ``sqrt(diag(s^2 (J^T J)^-1))`` with ``s^2`` the weighted residual
        variance: ``inf`` when the parameter is not identifiable from the data.
    identifiable
        Per fitted name, False when ``J^T J`` is singular in a direction the parameter moves.
    correlation
        Correlation matrix ``(p, p)`` of the fitted parameters (``free`` order; NaN-free:
        0 where undefined).
    condition_number
        Of ``J^T J`` with the columns of ``J`` scaled to unit norm (``inf`` when singular).
    bulk_modulus
        The bulk modulus K (Pa) the curves were computed with, ``None`` if incompressible.
    curves
        The data fitted.
    residuals
        Per curve, model minus data (Pa).
    rms, rms_relative
        Root mean square of the residuals in Pa, and of the residuals over
        ``max(|data|, 1e-3 max|data of the curve|)``.
    stable
        Per mode, the Drucker-stable stretch interval of the (incompressible) fitted model,
        or ``None`` when it is unstable at rest.
    shear_modulus, shear_modulus_error
        The small-strain shear modulus (Pa) and its standard error (often far better
        determined than the coefficients it is made of).
    weights
        ``"relative"``, ``"absolute"`` or ``"given"``.
    nfev, starts
        Residual evaluations over all starts, and the number of starting points.
    warnings
        Things the user should know: parameters that are not identifiable or correlated, data
        outside the stable range, an implausible modulus (wrong stress unit?).
    """

    model: str
    terms: int
    params: dict[str, float]
    free: tuple[str, ...]
    standard_errors: dict[str, float]
    identifiable: dict[str, bool]
    correlation: Array
    condition_number: float
    bulk_modulus: float | None
    curves: tuple[Curve, ...]
    residuals: tuple[Array, ...]
    rms: float
    rms_relative: float
    stable: dict[str, StableRange | None]
    shear_modulus: float
    shear_modulus_error: float
    weights: str
    nfev: int
    starts: int
    warnings: list[str] = field(default_factory=list)

    @property
    def spec(self) -> ModelSpec:
        return model_spec(self.model, self.terms if self.model in ("yeoh", "ogden") else None)

    def predict(self, mode: str, stretch: Any) -> Array:
        """Nominal stress (Pa) of the fitted model in ``mode`` at ``stretch`` (same
        compressibility as the fit)."""
        theta = np.array([self.params[n] for n in self.spec.param_names])
        return nominal_stress(self.spec, theta, mode, np.atleast_1d(np.asarray(stretch, dtype=np.float64)),
                              self.bulk_modulus)[0]

    def summary(self) -> str:
        """A readable report: every parameter rounded to its uncertainty (two significant
        digits of the standard error), the fit quality, the stability ranges and warnings."""
        n_points = sum(c.stretch.size for c in self.curves)
        compress = "incompressible" if self.bulk_modulus is None else f"bulk modulus {self.bulk_modulus:.6g} Pa"
        terms = f", {self.terms} terms" if self.model in ("yeoh", "ogden") else ""
        lines = [f"{self.model} fit ({compress}{terms}) to {len(self.curves)} curve(s), {n_points} points, "
                 f"{self.weights} weights",
                 f"  rms residual {self.rms:.3g} Pa ({100 * self.rms_relative:.3g} % relative)"]
        for curve, res in zip(self.curves, self.residuals):
            lines.append(f"  curve {curve.source}: {curve.mode}, {curve.stretch.size} points, stretch "
                         f"{curve.stretch.min():.4g}..{curve.stretch.max():.4g}, rms {np.sqrt(np.mean(res**2)):.3g} Pa")
        width = max(len(n) for n in self.params)
        for name, value in self.params.items():
            unit = "1/Pa" if name.startswith("d") else ("" if name.startswith("alpha") else "Pa")
            if name in self.standard_errors:
                text = format_uncertain(value, self.standard_errors[name], unit)
            elif name == "d1" and value == 0:
                text = "0 (incompressible)"
            elif name.startswith("d") and value == 0:
                text = "0 (no term)"
            elif name.startswith("d"):
                text = f"{value:.10g} {unit} (= 2/K)"
            else:
                text = f"{value:.10g} {unit}".rstrip() + " (fixed)"
            lines.append(f"  {name:<{width}} = {text}")
        lines.append("  small-strain shear modulus " + format_uncertain(self.shear_modulus, self.shear_modulus_error,
                                                                         "Pa"))
        cond = "inf (singular)" if not math.isfinite(self.condition_number) else f"{self.condition_number:.2g}"
        lines.append(f"  condition number of J^T J (unit columns): {cond}")
        lines.append("Drucker stability of the incompressible fit (stretch checked from 0.1 to 10):")
        for mode in MODES:
            rng = self.stable[mode]
            lines.append(f"  {rng}" if rng is not None else f"  {mode}: unstable at rest (shear modulus <= 0)")
        if self.warnings:
            lines.append("Warnings:")
            lines.extend(f"  - {w}" for w in self.warnings)
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        """Plain data for JSON, never NaN or infinity: a standard error that is infinite (the
        parameter is not identifiable) is ``null`` with ``identifiable: false``; an infinite
        condition number is ``null``; a stretch bound that is only the end of the checked
        range has ``lower_reached``/``upper_reached`` false."""

        def finite(x: float) -> float | None:
            return float(x) if math.isfinite(x) else None

        return {
            "model": self.model,
            "terms": self.terms,
            "params": {k: float(v) for k, v in self.params.items()},
            "free": list(self.free),
            "standard_errors": {k: finite(v) for k, v in self.standard_errors.items()},
            "identifiable": dict(self.identifiable),
            "correlation": [[finite(x) for x in row] for row in self.correlation],
            "condition_number": finite(self.condition_number),
            "bulk_modulus": self.bulk_modulus,
            "incompressible": self.bulk_modulus is None,
            "shear_modulus": float(self.shear_modulus),
            "shear_modulus_error": finite(self.shear_modulus_error),
            "weights": self.weights,
            "rms": float(self.rms),
            "rms_relative": float(self.rms_relative),
            "stable": {mode: (None if r is None else {"lower": r.lower, "upper": r.upper,
                                                      "lower_reached": r.lower_reached,
                                                      "upper_reached": r.upper_reached})
                       for mode, r in self.stable.items()},
            "data": [{"source": c.source, "mode": c.mode, "points": int(c.stretch.size),
                      "stretch_min": float(c.stretch.min()), "stretch_max": float(c.stretch.max()),
                      "rms": float(np.sqrt(np.mean(r**2)))} for c, r in zip(self.curves, self.residuals)],
            "nfev": self.nfev,
            "starts": self.starts,
            "warnings": list(self.warnings),
        }

    def plot(self, ax: Any = None) -> Any:
        """Data against fit, one panel per test mode present; returns the matplotlib Figure.

        ``ax`` None draws on a new Figure (Agg canvas: no window, the backend untouched); an
        Axes draws every mode into it; a sequence of Axes, one per mode, draws mode by mode.
        A dashed line marks a Drucker stability limit inside the plotted range.
        """
        return plot_fit(self, ax)


def format_uncertain(value: float, std: float, unit: str = "") -> str:
    """``value ± std`` with the standard error rounded to two significant digits and the value
    to the same decimal place (at most 10 significant digits: a smaller error prints as
    ``< 1`` unit of the last digit shown).

    >>> format_uncertain(12345.678, 67.2, "Pa")
    '12346 ± 67 Pa'
    >>> format_uncertain(1.23456e-7, 2.1e-9, "1/Pa")
    '(1.235 ± 0.021)e-07 1/Pa'
    >>> format_uncertain(300.0, 0.0, "Pa")
    '300.0000000 ± <0.0000001 Pa'
    >>> format_uncertain(2.5e4, math.inf, "Pa")
    '2.5e+04 Pa (not identifiable)'
    """
    suffix = f" {unit}" if unit else ""
    if not math.isfinite(std):
        return f"{value:.2g}{suffix} (not identifiable)"
    magnitude = max(abs(value), std)
    if magnitude == 0:
        return f"0 ± 0{suffix}"
    top = math.floor(math.log10(magnitude))
    last = max(math.floor(math.log10(std)) - 1 if std > 0 else top - 9, top - 9)
    tiny = std < 0.5 * 10.0**last
    if -3 <= top <= 5:
        decimals = max(0, -last)
        v, s = (round(value, -last), round(std, -last)) if last > 0 else (value, std)
        std_text = f"<{10.0**last:.{decimals}f}" if tiny else f"{s:.{decimals}f}"
        return f"{v:.{decimals}f} ± {std_text}{suffix}"
    scale = 10.0**top
    decimals = top - last
    std_text = f"<{10.0**(last - top):.{decimals}f}" if tiny else f"{std / scale:.{decimals}f}"
    return f"({value / scale:.{decimals}f} ± {std_text})e{top:+03d}{suffix}"


def fit_material(
    model: str,
    data: Any,
    *,
    terms: int | None = None,
    bulk_modulus: float | None = None,
    x0: Mapping[str, float] | None = None,
    fixed: Mapping[str, float] | None = None,
    weights: str | Sequence[Any] = "relative",
    bounds: Mapping[str, tuple[float, float]] | None = None,
    mode: str | None = None,
    stress_unit: str | None = None,
) -> MaterialFit:
    """Fit a hyperelastic model to homogeneous test curves by least squares.

    Parameters
    ----------
    model
        ``"neo_hookean"``, ``"mooney_rivlin"``, ``"yeoh"`` or ``"ogden"`` (energies in
        :mod:`sorofem.fitting.models`).
    data
        One or more curves: a :class:`~sorofem.fitting.Curve`, a dict with ``mode``,
        ``stretch`` and ``nominal_stress`` (Pa), or a CSV file (format in
        :mod:`sorofem.fitting.data`); or a list of these.
    terms
        Yeoh: how many of ``c10, c20, c30`` are fitted (default 3; the rest are 0). Ogden: the
        number of ``(mu, alpha)`` pairs, 1 to 3 (default 3).
    bulk_modulus
        K in Pa: the curves are computed compressible (lateral stretch solved for zero lateral
        traction) with ``d1 = 2/K`` (Neo-Hookean: ``lambda = K - 2 mu/3``). ``None``:
        incompressible, ``d1 = 0``. K is never fitted: these tests hardly see it.
    x0
        Starting values by name (fitted names only). Without it: the linear least-squares
        solution of the incompressible problem (Neo-Hookean, Mooney-Rivlin, Yeoh are linear in
        their coefficients) or, for Ogden, a multi-start over exponent combinations, each with
        its linear-least-squares ``mu`` values.
    fixed
        Values of coefficients to hold fixed, by name (e.g. ``{"alpha:0": 2.0}``).
    weights
        ``"relative"`` (default: residuals divided by ``max(|P|, 1e-3 max|P| of the curve)``, so
        small-stretch points count as much as large ones), ``"absolute"`` (plain Pa), or one
        array of positive weights per curve multiplying the residuals in Pa.
    bounds
        ``{name: (lower, upper)}`` for fitted names (default unbounded; Ogden exponents keep
        the sign of their start and ``1e-3 <= |alpha| <= 40``). Ogden terms come back sorted by
        increasing exponent unless some are fixed or bounded.
    mode, stress_unit
        For CSV files that do not name their test mode or stress unit.

    Returns
    -------
    MaterialFit

    Raises
    ------
    ParameterError, DataFileError
        Bad model, terms, names, values or data (the message names the parameter or the file
        and line).
    ConvergenceError
        The least-squares solver did not converge (``report`` holds the cost history).

    Examples
    --------
    >>> import numpy as np
    >>> from sorofem.fitting import fit_material
    >>> stretch = np.linspace(1.0, 3.0, 21)
    >>> stress = 2 * (stretch - stretch**-2) * (12e3 + 2 * 400 * (stretch**2 + 2 / stretch - 3))
    >>> fit = fit_material("yeoh", {"mode": "uniaxial", "stretch": stretch, "nominal_stress": stress}, terms=2)
    >>> round(fit.params["c10"]), round(fit.params["c20"])
    (12000, 400)
    """
    spec = model_spec(model, terms)
    curves = tuple(as_curves(data, mode=mode, stress_unit=stress_unit))
    bulk = _check_bulk(bulk_modulus)
    theta = np.zeros(len(spec.param_names))
    if "d1" in spec.param_names and bulk is not None:
        theta[spec.param_names.index("d1")] = 2.0 / bulk
    fixed = dict(fixed or {})
    _check_names(spec, fixed, "fixed")
    for name, value in fixed.items():
        theta[spec.param_names.index(name)] = _check_value(spec, name, value, "fixed")
    free = tuple(n for n in spec.coefficient_names if n not in fixed)
    if not free:
        raise ParameterError("every coefficient is fixed: nothing to fit", "fixed")
    n_points = sum(c.stretch.size for c in curves)
    if n_points <= len(free):
        raise ParameterError(f"{len(free)} parameters need more than {len(free)} data points, got {n_points}", "data")
    free_idx = np.array([spec.param_names.index(n) for n in free])
    scales = _weights(curves, weights)
    lower, upper = _bounds(spec, free, bounds)
    problem = _Problem(spec, theta, free_idx, curves, scales, bulk)

    if x0 is not None:
        _check_names(spec, x0, "x0")
        unknown = sorted(set(x0) - set(free))
        if unknown:
            raise ParameterError(f"x0 names {unknown}, which are not fitted (fitted: {', '.join(free)})", "x0")
        given = {name: _check_value(spec, name, value, "x0") for name, value in x0.items()}
        missing = [n for n in free if n.startswith("alpha") and n not in given]
        if missing:
            raise ParameterError(f"x0 must give every fitted Ogden exponent; missing {', '.join(missing)}", missing[0])
        start = problem.linear_start({free.index(n): v for n, v in given.items() if n.startswith("alpha")})
        for name, value in given.items():
            start[free.index(name)] = value
        starts = [start]
    elif spec.name == "ogden":
        starts = problem.ogden_starts(free)
    else:
        starts = [problem.linear_start(None)]

    # Many starts are scouted on the incompressible curves (cheap, and close for any realistic
    # K); the best few are then converged on the real problem.
    scout = problem if len(starts) == 1 or bulk is None else _Problem(spec, theta, free_idx, curves, scales, None)
    runs = []
    feasible = [(start, box) for start in starts if (box := _start_bounds(spec, free, start, lower, upper))]
    if not feasible:
        raise ParameterError("bounds leave no non-zero value for the Ogden exponents (of the sign they start with)",
                             "bounds")
    for start, (lo, hi) in feasible:
        runs.append(scout.solve(np.clip(start, lo, hi), lo, hi, max_nfev=60 if len(starts) > 1 else _MAX_NFEV))
    if len(starts) > 1:
        runs.sort(key=lambda r: r.cost if np.isfinite(r.cost) else np.inf)
        runs = [problem.solve(r.x, r.lo, r.hi, max_nfev=_MAX_NFEV) for r in runs[:3]]
    converged = [r for r in runs if r.status > 0 and np.isfinite(r.cost)]
    if not converged:
        history = problem.history[-10:]
        raise ConvergenceError(
            f"the least-squares fit of {model} did not converge ({runs[0].message}); weighted cost of the last "
            f"evaluations: {', '.join(f'{c:.4g}' for c in history)}",
            report={"history": list(problem.history), "message": runs[0].message},
        )
    best = min(converged, key=lambda r: r.cost)
    # Sorting the terms would move fixed or bounded values to other names.
    x = _ogden_ordered(spec, free, best.x) if spec.name == "ogden" and not fixed and not bounds else best.x
    problem.nfev += scout.nfev if scout is not problem else 0
    return problem.result(x, free, weights if isinstance(weights, str) else "given", len(starts))


def _ogden_ordered(spec: ModelSpec, free: tuple[str, ...], x: Array) -> Array:
    """The Ogden terms sorted by increasing exponent (the energy does not depend on their order)."""
    pairs = sorted((x[free.index(f"alpha:{k}")], x[free.index(f"mu:{k}")]) for k in range(spec.terms))
    out = x.copy()
    for k, (alpha, mu) in enumerate(pairs):
        out[free.index(f"alpha:{k}")], out[free.index(f"mu:{k}")] = alpha, mu
    return out


def _check_bulk(bulk_modulus: Any) -> float | None:
    if bulk_modulus is None:
        return None
    try:
        bulk = float(bulk_modulus)
    except (TypeError, ValueError):
        raise ParameterError(f"bulk_modulus must be a number in Pa, got {bulk_modulus!r}", "bulk_modulus") from None
    if not (math.isfinite(bulk) and bulk > 0):
        raise ParameterError(f"bulk_modulus must be finite and > 0 Pa, got {bulk_modulus!r}", "bulk_modulus")
    return bulk


def _check_names(spec: ModelSpec, values: Mapping[str, Any], what: str) -> None:
    if not isinstance(values, Mapping):
        raise ParameterError(f"{what} must be a mapping from parameter name to value", what)
    for name in values:
        if name in spec.volumetric_names:
            raise ParameterError(f"{what}[{name!r}]: the compliances d_i are set by bulk_modulus (d1 = 2/K), "
                                 "not fitted or fixed here", name)
        if name not in spec.coefficient_names:
            raise ParameterError(f"{what} names {name!r}, which {spec.name} with {spec.terms} term(s) does not have; "
                                 f"its coefficients are {', '.join(spec.coefficient_names)}", name)


def _check_value(spec: ModelSpec, name: str, value: Any, what: str) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ParameterError(f"{what}[{name!r}] must be a number, got {value!r}", name) from None
    if not math.isfinite(number):
        raise ParameterError(f"{what}[{name!r}] must be finite, got {value!r}", name)
    if name.startswith("alpha") and number == 0.0:
        raise ParameterError(f"{what}[{name!r}] = 0: an Ogden exponent must be non-zero (W has 2 mu/alpha^2)", name)
    return number


def _weights(curves: Sequence[Curve], weights: Any) -> list[Array]:
    """Per curve, the factor each residual in Pa is multiplied by."""
    if isinstance(weights, str):
        if weights == "relative":
            return [1.0 / np.maximum(np.abs(c.nominal_stress), _RELATIVE_FLOOR * np.abs(c.nominal_stress).max()
                                     if np.abs(c.nominal_stress).max() > 0 else 1.0) for c in curves]
        if weights == "absolute":
            peak = max(float(np.abs(c.nominal_stress).max()) for c in curves) or 1.0
            return [np.full(c.stretch.size, 1.0 / peak) for c in curves]
        raise ParameterError(f"weights must be 'relative', 'absolute' or one array per curve, got {weights!r}",
                             "weights")
    if not isinstance(weights, (list, tuple)) or len(weights) != len(curves):
        raise ParameterError(f"weights must be 'relative', 'absolute' or a list of {len(curves)} arrays (one per "
                             "curve)", "weights")
    out = []
    for i, (w, c) in enumerate(zip(weights, curves)):
        w = np.asarray(w, dtype=np.float64)
        if w.shape != c.stretch.shape or not np.all(np.isfinite(w) & (w > 0)):
            raise ParameterError(f"weights[{i}] must hold {c.stretch.size} finite positive values", "weights")
        out.append(w)
    return out


def _bounds(spec: ModelSpec, free: tuple[str, ...], bounds: Mapping[str, Any] | None) -> tuple[Array, Array]:
    lower = np.full(len(free), -np.inf)
    upper = np.full(len(free), np.inf)
    for name, pair in (bounds or {}).items():
        if name not in free:
            raise ParameterError(f"bounds names {name!r}, which is not fitted (fitted: {', '.join(free)})", name)
        try:
            lo, hi = (float(v) for v in pair)
        except (TypeError, ValueError):
            raise ParameterError(f"bounds[{name!r}] must be a pair (lower, upper), got {pair!r}", name) from None
        if not lo < hi:
            raise ParameterError(f"bounds[{name!r}]: lower {lo:g} must be below upper {hi:g}", name)
        k = free.index(name)
        lower[k], upper[k] = lo, hi
    return lower, upper


def _start_bounds(spec: ModelSpec, free: tuple[str, ...], start: Array, lower: Array, upper: Array
                  ) -> tuple[Array, Array] | None:
    """Ogden exponents stay on the side of zero they start on (W is singular at alpha = 0);
    ``None`` when the user's bounds exclude that side."""
    lo, hi = lower.copy(), upper.copy()
    for k, name in enumerate(free):
        if name.startswith("alpha"):
            if start[k] > 0:
                lo[k], hi[k] = max(lo[k], _ALPHA_BOUND[0]), min(hi[k], _ALPHA_BOUND[1])
            else:
                lo[k], hi[k] = max(lo[k], -_ALPHA_BOUND[1]), min(hi[k], -_ALPHA_BOUND[0])
            if not lo[k] < hi[k]:
                return None
    return lo, hi


@dataclass
class _Run:
    x: Array
    cost: float
    status: int
    message: str
    nfev: int
    lo: Array
    hi: Array


class _Problem:
    """The weighted residuals ``w (P_model - P_data)`` over all curves and their Jacobian."""

    def __init__(self, spec: ModelSpec, theta: Array, free_idx: Array, curves: Sequence[Curve],
                 scales: list[Array], bulk: float | None) -> None:
        self.spec, self.theta, self.free_idx = spec, theta, free_idx
        self.curves, self.scales, self.bulk = curves, scales, bulk
        self.history: list[float] = []
        self.nfev = 0
        self._cache: tuple[bytes, Array, Array] | None = None

    def full(self, x: Array) -> Array:
        theta = self.theta.copy()
        theta[self.free_idx] = x
        return theta

    def evaluate(self, x: Array, bulk: float | None = -1.0) -> tuple[Array, Array]:
        """Weighted residuals ``(n,)`` and Jacobian ``(n, p)`` at free values ``x``."""
        bulk = self.bulk if bulk == -1.0 else bulk
        key = x.tobytes() + repr(bulk).encode()
        if self._cache is not None and self._cache[0] == key:
            return self._cache[1], self._cache[2]
        theta = self.full(x)
        res, jac = [], []
        for curve, w in zip(self.curves, self.scales):
            stress, grad = nominal_stress(self.spec, theta, curve.mode, curve.stretch, bulk, with_gradient=True)
            res.append(w * (stress - curve.nominal_stress))
            jac.append(w[:, None] * grad[:, self.free_idx])
        r, j = np.concatenate(res), np.concatenate(jac)
        self._cache = (key, r, j)
        return r, j

    def _residual(self, x: Array) -> Array:
        self.nfev += 1
        try:
            r = self.evaluate(x)[0]
        except SolverError:
            r = np.full(sum(c.stretch.size for c in self.curves), 1e6)
        if not np.all(np.isfinite(r)):
            r = np.full(r.shape, 1e6)
        self.history.append(0.5 * float(r @ r))
        return r

    def _jacobian(self, x: Array) -> Array:
        try:
            j = self.evaluate(x)[1]
        except SolverError:
            return np.zeros((sum(c.stretch.size for c in self.curves), x.size))
        return np.where(np.isfinite(j), j, 0.0)

    def linear_start(self, x_nonlinear: Mapping[int, float] | None) -> Array:
        """Free values from the incompressible problem, linear in every coefficient but the
        Ogden exponents: those (free or fixed) are taken from ``theta`` or ``x_nonlinear``
        (position in the free vector -> value), the rest solved by weighted linear least squares."""
        x = np.zeros(self.free_idx.size)
        for k, value in (x_nonlinear or {}).items():
            x[k] = value
        linear = np.array([not self.spec.param_names[i].startswith("alpha") for i in self.free_idx])
        base, jac = self.evaluate(np.where(linear, 0.0, x), bulk=None)
        coef = np.linalg.lstsq(jac[:, linear], -base, rcond=None)[0]
        x[linear] = coef
        return x

    def ogden_starts(self, free: tuple[str, ...]) -> list[Array]:
        alpha_pos = [k for k, n in enumerate(free) if n.startswith("alpha")]
        combos = itertools.combinations(_ALPHA_STARTS, len(alpha_pos)) if alpha_pos else [()]
        starts = []
        for combo in combos:
            starts.append(self.linear_start(dict(zip(alpha_pos, combo))))
        return starts

    def solve(self, x0: Array, lo: Array, hi: Array, max_nfev: int) -> _Run:
        bounded = np.isfinite(lo).any() or np.isfinite(hi).any()
        result = least_squares(self._residual, x0, jac=self._jacobian, bounds=(lo, hi) if bounded else (-np.inf, np.inf),
                               method="trf", x_scale="jac", ftol=1e-14, xtol=1e-14, gtol=1e-14, max_nfev=max_nfev)
        return _Run(result.x, float(result.cost), int(result.status), str(result.message), int(result.nfev), lo, hi)

    def result(self, x: Array, free: tuple[str, ...], weights: str, starts: int) -> MaterialFit:
        spec = self.spec
        r, jac = self.evaluate(x)
        theta = self.full(x)
        n, p = jac.shape
        s2 = float(r @ r) / (n - p)
        cov, identifiable, cond = _covariance(jac, s2)
        std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        std = np.where(identifiable, std, np.inf)
        with np.errstate(divide="ignore", invalid="ignore"):
            corr = cov / np.outer(std, std)
        corr = np.where(np.isfinite(corr), corr, 0.0)
        np.fill_diagonal(corr, np.where(identifiable, 1.0, 0.0))
        residuals = []
        relative = []
        for curve in self.curves:
            stress = nominal_stress(spec, theta, curve.mode, curve.stretch, self.bulk)[0]
            residuals.append(stress - curve.nominal_stress)
            peak = np.abs(curve.nominal_stress).max()
            relative.append((stress - curve.nominal_stress)
                            / np.maximum(np.abs(curve.nominal_stress), _RELATIVE_FLOOR * peak if peak > 0 else 1.0))
        all_res = np.concatenate(residuals)
        mu, _ = small_strain_moduli(spec, theta, self.bulk)
        dmu = _shear_gradient(spec, free)
        mu_err = float(np.sqrt(max(dmu @ cov @ dmu, 0.0))) if np.all(identifiable | (dmu == 0)) else math.inf
        stable = {mode: stable_range(spec, theta, mode) for mode in MODES}
        fit = MaterialFit(
            model=spec.name, terms=spec.terms,
            params={name: float(v) for name, v in zip(spec.param_names, theta)},
            free=free,
            standard_errors={name: float(v) for name, v in zip(free, std)},
            identifiable={name: bool(v) for name, v in zip(free, identifiable)},
            correlation=corr, condition_number=cond, bulk_modulus=self.bulk, curves=tuple(self.curves),
            residuals=tuple(residuals), rms=float(np.sqrt(np.mean(all_res**2))),
            rms_relative=float(np.sqrt(np.mean(np.concatenate(relative) ** 2))),
            stable=stable, shear_modulus=mu, shear_modulus_error=mu_err, weights=weights, nfev=self.nfev,
            starts=starts,
        )
        fit.warnings.extend(_warnings(fit))
        return fit


def _covariance(jac: Array, s2: float) -> tuple[Array, Array, float]:
    """``s^2 (J^T J)^-1`` from the SVD of the column-scaled J; which parameters are identifiable;
    the condition number of the scaled ``J^T J``."""
    p = jac.shape[1]
    norms = np.linalg.norm(jac, axis=0)
    identifiable = norms > 0
    scaled = jac / np.where(identifiable, norms, 1.0)
    _, sv, vt = np.linalg.svd(scaled, full_matrices=False)
    null = sv < _SINGULAR * sv[0] if sv[0] > 0 else np.ones(p, dtype=bool)
    for k in np.flatnonzero(null):
        identifiable &= np.abs(vt[k]) <= 1e-6
    keep = ~null
    inv = (vt[keep].T / sv[keep] ** 2) @ vt[keep]
    cov = s2 * inv / np.outer(np.where(norms > 0, norms, 1.0), np.where(norms > 0, norms, 1.0))
    cond = math.inf if null.any() or sv[-1] == 0 else float((sv[0] / sv[-1]) ** 2)
    return cov, identifiable, cond


def _shear_gradient(spec: ModelSpec, free: tuple[str, ...]) -> Array:
    """d(small-strain shear modulus)/d(free parameter)."""
    weights = {"neo_hookean": {"mu": 1.0}, "mooney_rivlin": {"c10": 2.0, "c01": 2.0}, "yeoh": {"c10": 2.0},
               "ogden": {f"mu:{k}": 1.0 for k in range(spec.terms)}}[spec.name]
    return np.array([weights.get(n, 0.0) for n in free])


def _warnings(fit: MaterialFit) -> list[str]:
    out = []
    lost = [n for n, ok in fit.identifiable.items() if not ok]
    if lost:
        out.append(f"not identifiable from these data: {', '.join(lost)} (J^T J is singular; fix them or add "
                   "test modes / a wider stretch range)")
    elif fit.condition_number > _ILL_CONDITIONED:
        out.append(f"ill-conditioned: cond(J^T J) = {fit.condition_number:.2g} with unit columns")
    p = len(fit.free)
    for i, name in enumerate(fit.free):
        value, err = fit.params[name], fit.standard_errors[name]
        if name in lost or not err > _POORLY_DETERMINED * abs(value):
            continue
        text = f"{name} is poorly determined ({format_uncertain(value, err)})"
        if p > 1:
            others = np.abs(fit.correlation[i]) * (np.arange(p) != i)
            j = int(np.argmax(others))
            if others[j] > 0.9:
                text += f": correlated with {fit.free[j]} (r = {fit.correlation[i, j]:+.4f})"
        out.append(text + "; the data hardly constrain it (add test modes or a wider stretch range)")
    if fit.shear_modulus <= 0:
        out.append(f"small-strain shear modulus {fit.shear_modulus:.4g} Pa <= 0: the fit is unstable at rest")
    elif not _PLAUSIBLE_SHEAR[0] <= fit.shear_modulus <= _PLAUSIBLE_SHEAR[1]:
        out.append(f"small-strain shear modulus {fit.shear_modulus:.4g} Pa is outside what elastomers and gels "
                   f"have ({_PLAUSIBLE_SHEAR[0]:g} .. {_PLAUSIBLE_SHEAR[1]:g} Pa): check the stress unit")
    for curve in fit.curves:
        rng = fit.stable[curve.mode]
        if rng is not None and not rng.contains(curve.stretch):
            out.append(f"{curve.source}: data reach stretch {curve.stretch.min():g}..{curve.stretch.max():g}, "
                       f"beyond the fit's Drucker-stable range ({rng})")
    return out
