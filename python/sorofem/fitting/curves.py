"""Homogeneous test curves: nominal stress against stretch in uniaxial, equibiaxial and planar
(pure shear) tension or compression, their derivatives with respect to every coefficient, and
the Drucker stability of a model.

The three tests stretch direction 1 by ``lambda``; direction 3 is free of traction:

============  =====================================  ==============================
mode          principal stretches                    incompressible lateral stretch
============  =====================================  ==============================
uniaxial      ``(lambda, t, t)``                      ``t = lambda^(-1/2)``
equibiaxial   ``(lambda, lambda, t)``                 ``t = lambda^(-2)``
planar        ``(lambda, 1, t)``                      ``t = lambda^(-1)``
============  =====================================  ==============================

Incompressible, the pressure follows from ``sigma_3 = 0`` and the nominal (first Piola)
stress is ``P = (tau_1 - tau_3) / lambda`` (closed form). Compressible (a bulk modulus K), the
lateral stretch ``t`` solves ``tau_3(lambda, t) = 0`` by Newton's method in ``ln t`` with the
analytic ``d tau_3 / d ln t``, and ``P = tau_1 / lambda``; its parameter derivatives follow by the
implicit function theorem, ``d ln t / d theta = -(d tau_3/d theta) / (d tau_3/d ln t)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import brentq

from ..errors import ParameterError, SolverError
from .models import ModelSpec, kirchhoff

__all__ = ["MODES", "StableRange", "incompressible_lateral", "lateral_log_stretch", "nominal_stress",
           "stable_range"]

Array = NDArray[np.float64]

#: Test modes, in the order figures and reports list them.
MODES = ("uniaxial", "equibiaxial", "planar")

# d eps / d (ln t): which principal directions the lateral stretch t moves.
_LATERAL = {"uniaxial": np.array([0.0, 1.0, 1.0]), "equibiaxial": np.array([0.0, 0.0, 1.0]),
            "planar": np.array([0.0, 0.0, 1.0])}
# eps = ln(lambda) * _AXIAL + ln(t) * _LATERAL
_AXIAL = {"uniaxial": np.array([1.0, 0.0, 0.0]), "equibiaxial": np.array([1.0, 1.0, 0.0]),
          "planar": np.array([1.0, 0.0, 0.0])}
# ln t = _INCOMPRESSIBLE * ln(lambda) keeps J = 1.
_INCOMPRESSIBLE = {"uniaxial": -0.5, "equibiaxial": -2.0, "planar": -1.0}

#: Stretch range the Drucker check scans (Abaqus checks nominal strains -0.9 .. 9 the same way).
DRUCKER_RANGE = (0.1, 10.0)


def check_mode(mode: str) -> str:
    if mode not in MODES:
        raise ParameterError(f"unknown test mode {mode!r}; expected one of {', '.join(MODES)}", "mode")
    return mode


def _log_stretches(mode: str, log_stretch: Array, log_lateral: Array) -> Array:
    return log_stretch[:, None] * _AXIAL[mode] + log_lateral[:, None] * _LATERAL[mode]


def incompressible_lateral(mode: str, stretch: Array) -> Array:
    """The lateral stretch ``t`` that keeps ``J = 1``."""
    return np.asarray(stretch, dtype=np.float64) ** _INCOMPRESSIBLE[check_mode(mode)]


def lateral_log_stretch(spec: ModelSpec, theta: Array, mode: str, stretch: Array, bulk: float,
                        tol: float = 1e-13, max_iterations: int = 60) -> tuple[Array, Array, Array]:
    """``ln t`` with ``tau_3 = 0`` for a compressible model, by Newton from the incompressible value.

    Returns ``(ln t, tau_3, d tau_3 / d ln t)`` at the solution, each ``(n,)``. Newton stops when
    the step in ``ln t`` is below ``tol``; a point where it fails (a non-monotone model far
    outside its stable range) falls back to bracketing with Brent's method.

    Raises
    ------
    SolverError
        No lateral stretch in ``[lambda_incompressible e^-5, lambda_incompressible e^5]`` frees
        direction 3 of traction.
    """
    check_mode(mode)
    log_stretch = np.log(np.asarray(stretch, dtype=np.float64))
    s = _INCOMPRESSIBLE[mode] * log_stretch
    lateral = _LATERAL[mode]

    def residual(s_: Array, at: Array) -> tuple[Array, Array]:
        tau, dtau, _ = kirchhoff(spec, theta, _log_stretches(mode, log_stretch[at], s_), bulk)
        return tau[:, 2], dtau[:, 2, :] @ lateral

    active = np.arange(s.size)
    for _ in range(max_iterations):
        if active.size == 0:
            break
        r, dr = residual(s[active], active)
        with np.errstate(divide="ignore", invalid="ignore"):
            step = -r / dr
        # tau_3 grows with the lateral stretch wherever the model is stable; elsewhere, or on
        # a step longer than a factor e, Newton is not to be trusted: bracket instead.
        failed = ~(dr > 0) | ~(np.abs(step) <= 1.0)
        for i in active[failed]:
            s[i] = _bracketed(lambda x, i=i: residual(np.array([x]), np.array([i]))[0][0],
                              _INCOMPRESSIBLE[mode] * log_stretch[i], log_stretch[i], mode)
        ok = ~failed
        s[active[ok]] += step[ok]
        converged = np.abs(step[ok]) <= tol * np.maximum(1.0, np.abs(s[active[ok]]))
        active = active[ok][~converged]
    for i in active:
        s[i] = _bracketed(lambda x, i=i: residual(np.array([x]), np.array([i]))[0][0],
                          _INCOMPRESSIBLE[mode] * log_stretch[i], log_stretch[i], mode)
    r, dr = residual(s, np.arange(s.size))
    return s, r, dr


def _bracketed(f, s0: float, log_stretch: float, mode: str) -> float:
    """Brent's method on ``tau_3(ln t)`` in a bracket widened around ``s0`` until it changes sign."""
    for width in (0.05, 0.2, 1.0, 5.0):
        lo, hi = s0 - width, s0 + width
        f_lo, f_hi = float(f(lo)), float(f(hi))
        if f_lo < 0.0 < f_hi:
            return brentq(f, lo, hi, xtol=1e-15, rtol=4 * np.finfo(float).eps, maxiter=200)
    raise SolverError(
        f"{mode}: no lateral stretch frees the lateral faces of traction at stretch {np.exp(log_stretch):g} "
        "(the model is not monotone there: check its stable range)"
    )


def nominal_stress(spec: ModelSpec, theta: Array, mode: str, stretch: Array, bulk: float | None,
                   with_gradient: bool = False) -> tuple[Array, Array | None]:
    """Nominal stress ``P`` (Pa, ``(n,)``) of a homogeneous test and, when asked, ``dP/dtheta``
    ``(n, m)`` (Pa per unit of each parameter, all of ``spec.param_names``).

    ``bulk=None`` is the incompressible closed form; otherwise the lateral stretch is solved
    for zero lateral traction (:func:`lateral_log_stretch`).
    """
    check_mode(mode)
    stretch = np.asarray(stretch, dtype=np.float64)
    log_stretch = np.log(stretch)
    if bulk is None:
        s = _INCOMPRESSIBLE[mode] * log_stretch
        tau, _, dtheta = kirchhoff(spec, theta, _log_stretches(mode, log_stretch, s), None)
        stress = (tau[:, 0] - tau[:, 2]) / stretch
        grad = (dtheta[:, 0, :] - dtheta[:, 2, :]) / stretch[:, None] if with_gradient else None
        return stress, grad
    s, _, dr = lateral_log_stretch(spec, theta, mode, stretch, bulk)
    tau, dtau, dtheta = kirchhoff(spec, theta, _log_stretches(mode, log_stretch, s), bulk)
    stress = tau[:, 0] / stretch
    if not with_gradient:
        return stress, None
    ds_dtheta = -dtheta[:, 2, :] / dr[:, None]
    dtau1_ds = dtau[:, 0, :] @ _LATERAL[mode]
    grad = (dtheta[:, 0, :] + dtau1_ds[:, None] * ds_dtheta) / stretch[:, None]
    return stress, grad


def drucker_eigenvalue(spec: ModelSpec, theta: Array, mode: str, stretch: Array) -> Array:
    """Smallest eigenvalue (Pa) of the incompressible Drucker tangent at each stretch of ``mode``.

    With ``eps_3 = -eps_1 - eps_2``, ``dtau : deps = (dtau_1 - dtau_3) deps_1 + (dtau_2 - dtau_3)
    deps_2 = deps^T D deps`` with ``D_ij = d(tau_i - tau_3)/d eps_j`` (i, j = 1, 2), the Hessian of
    W in the two free log-strains: the material is Drucker stable at that state when D is
    positive definite (Abaqus Theory Manual, "Hyperelastic material behavior").
    """
    check_mode(mode)
    log_stretch = np.log(np.asarray(stretch, dtype=np.float64))
    eps = _log_stretches(mode, log_stretch, _INCOMPRESSIBLE[mode] * log_stretch)
    _, h, _ = kirchhoff(spec, theta, eps, None)
    d11 = h[:, 0, 0] - h[:, 0, 2] - h[:, 2, 0] + h[:, 2, 2]
    d22 = h[:, 1, 1] - h[:, 1, 2] - h[:, 2, 1] + h[:, 2, 2]
    d12 = 0.5 * (h[:, 0, 1] - h[:, 0, 2] - h[:, 2, 1] + h[:, 2, 2]
                 + h[:, 1, 0] - h[:, 1, 2] - h[:, 2, 0] + h[:, 2, 2])
    mean = 0.5 * (d11 + d22)
    return mean - np.sqrt((0.5 * (d11 - d22)) ** 2 + d12**2)


@dataclass(frozen=True)
class StableRange:
    """The stretch interval around 1 over which a model is Drucker stable in one test mode.

    ``lower``/``upper`` are the stretches where stability is first lost, or the ends of the
    checked range :data:`DRUCKER_RANGE` when it is kept all the way (``lower_reached`` /
    ``upper_reached`` False).
    """

    mode: str
    lower: float
    upper: float
    lower_reached: bool
    upper_reached: bool

    def contains(self, stretch: Array) -> bool:
        stretch = np.asarray(stretch)
        return bool(np.all((stretch >= self.lower) & (stretch <= self.upper)))

    def __str__(self) -> str:
        if not (self.lower_reached or self.upper_reached):
            return f"{self.mode}: stable over the whole checked range {self.lower:g} <= stretch <= {self.upper:g}"
        lo = f"{self.lower:.4g}" if self.lower_reached else f"{self.lower:g} (end of check)"
        hi = f"{self.upper:.4g}" if self.upper_reached else f"{self.upper:g} (end of check)"
        return f"{self.mode}: stable for {lo} <= stretch <= {hi}"


def stable_range(spec: ModelSpec, theta: Array, mode: str, samples: int = 400) -> StableRange | None:
    """The Drucker-stable stretch interval around 1 in ``mode`` (incompressible), or ``None`` if
    the model is unstable at rest (a shear modulus <= 0).

    The stretch is scanned geometrically from 1 to each end of :data:`DRUCKER_RANGE`; the first
    sign change of :func:`drucker_eigenvalue` is refined with Brent's method.
    """
    near_rest = drucker_eigenvalue(spec, theta, mode, np.array([1.0 + 1e-6, 1.0 - 1e-6]))
    if not np.all(near_rest > 0):
        return None
    ends = []
    for end in DRUCKER_RANGE:
        grid = np.geomspace(1.0 + (1e-6 if end > 1 else -1e-6), end, samples)
        eig = drucker_eigenvalue(spec, theta, mode, grid)
        bad = np.flatnonzero(~(eig > 0))
        if bad.size == 0:
            ends.append((end, False))
            continue
        k = bad[0]

        def f(x: float) -> float:
            return float(drucker_eigenvalue(spec, theta, mode, np.array([x]))[0])

        a, b = grid[k - 1], grid[k]
        if not np.isfinite(f(b)):
            ends.append((float(a), True))
            continue
        ends.append((float(brentq(f, a, b, xtol=1e-12)), True))
    (lo, lo_hit), (hi, hi_hit) = ends
    return StableRange(mode, lo, hi, lo_hit, hi_hit)
