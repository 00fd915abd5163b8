"""What a fit determines, beyond the Gauss-Newton covariance: the fitted material's standard
errors in each of its forms (linear propagation), and the profile of the misfit along the worst
determined parameter (profile likelihood: Venzon & Moolgavkar 1988; Raue et al., Bioinformatics
25(15), 2009, for its use on identifiability)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.stats import chi2

from ..errors import InputError, SolverError
from ._optimizers import levenberg_marquardt
from ._parameters import Parameters
from ._problem import Problem, fitted_material
from .results import Profile, Uncertainty

__all__ = ["material_std", "profile_index", "profile_span", "profile", "PROFILE_CONDITION", "PROFILE_SPAN", "PROFILE_POINTS"]

#: ``profile=None`` profiles when the scaled Jacobian's condition number exceeds this: the
#: worst determined combination then moves the residual 1000 times less than the best one, and
#: a linear standard error along it says little.
PROFILE_CONDITION = 1e3
#: The farthest an automatic profile reaches on each side of the optimum, in the optimiser's
#: scaling (log theta; the logit of the Poisson ratio): a factor 1000 either way (both sides'
#: span from a bound).
PROFILE_SPAN = math.log(1e3)
#: Points of an automatic profile (the optimum is added to them).
PROFILE_POINTS = 9


def material_std(body: Any, p: Parameters, theta: NDArray[np.float64], unc: Uncertainty) -> dict[str, float]:
    """Standard error of every parameter of the fitted material in each form, by linear
    propagation of ``unc.covariance`` (central differences of the conversion; parameters at a
    bound held there). Empty unless every fitted parameter is a scalar material one of the whole
    body."""
    model = p.model
    m = body.mesh.n_tets
    if not all(b.size == 1 and b.kind in model.names and len(b.elements) == m for b in p.blocks):
        return {}
    names = [n for form in model.forms for n in form.names]
    cov = np.nan_to_num(unc.covariance, nan=0.0)
    if not np.all(np.isfinite(cov)):
        return {}

    def values(t: NDArray[np.float64]) -> NDArray[np.float64]:
        mat = fitted_material(body, p.state(t))
        return np.array([float(mat.value(n)) for n in names])

    G = np.empty((len(names), len(theta)))
    for j in range(len(theta)):
        h = 1e-6 * max(abs(theta[j]), 1e-300)
        up, down = theta.copy(), theta.copy()
        up[j] += h
        down[j] -= h
        try:
            G[:, j] = (values(up) - values(down)) / (2 * h)
        except (InputError, ValueError):  # a step leaves the domain (nu at 0.5): one-sided
            G[:, j] = (values(theta) - values(down)) / h
    var = np.einsum("ij,jk,ik->i", G, cov, G)
    return {n: float(math.sqrt(max(v, 0.0))) for n, v in zip(names, var)}


def profile_index(unc: Uncertainty) -> int:
    """The parameter with the largest weight in the worst determined direction."""
    assert unc.weak_direction is not None
    return int(np.argmax(np.abs(unc.weak_direction)))


def profile_span(unc: Uncertainty, index: int, dts: NDArray[np.float64]) -> float:
    """How far an automatic profile reaches either side of the optimum, in the optimiser's
    scaling: four linear standard errors (twice the 95 % interval), at most
    :data:`PROFILE_SPAN`; all of that where the standard error is unknown (a parameter at a
    bound) or not finite."""
    std_s = float(unc.std[index]) / abs(float(dts[index])) if dts[index] else math.inf
    return min(PROFILE_SPAN, 4.0 * std_s) if math.isfinite(std_s) and std_s > 0 else PROFILE_SPAN


def _grid(s_opt: float, lo: float, hi: float, points: int, span: float) -> NDArray[np.float64]:
    a, b = s_opt - span, s_opt + span
    if s_opt - lo <= 1e-9 * (1 + abs(s_opt)):  # at the lower bound: all on one side
        a, b = lo, lo + 2 * span
    elif hi - s_opt <= 1e-9 * (1 + abs(s_opt)):
        a, b = hi - 2 * span, hi
    a, b = max(a, lo), min(b, hi)
    return np.unique(np.r_[np.linspace(a, b, max(points, 2)), s_opt])


def profile(
    problem: Problem,
    s_opt: NDArray[np.float64],
    r_opt: NDArray[np.float64],
    index: int,
    lo: NDArray[np.float64],
    hi: NDArray[np.float64],
    values: ArrayLike | None = None,
    points: int = PROFILE_POINTS,
    span: float = PROFILE_SPAN,
    confidence: float = 0.95,
    max_evaluations: int = 30,
    xtol: float = 1e-8,
    ftol: float = 1e-8,
) -> Profile:
    """Profile of ``1/2 |r|^2`` along parameter ``index``: at each value the other parameters
    are fitted again (Levenberg-Marquardt with that one pinned), sweeping outwards from the
    optimum ``s_opt`` so that each fit starts from its neighbour's.

    ``values`` (in the parameter's units) replace the automatic grid: ``points`` values over
    ``span`` either side of the optimum in the optimiser's scaling (:func:`profile_span`),
    within the bounds (all on one side for a parameter at a bound)."""
    p = problem.params
    block = next(b for b in p.blocks if b.offset <= index < b.offset + b.size)
    if block.size != 1:
        raise InputError(f"profile: {block.name!r} has {block.size} values; only a scalar parameter can be profiled")
    if values is None:
        grid = _grid(float(s_opt[index]), float(lo[index]), float(hi[index]), points, span)
    else:
        theta = np.asarray(values, dtype=np.float64).reshape(-1)
        if theta.size < 2 or not np.all(block.transform.contains(theta)) or not np.all(np.isfinite(theta)):
            raise InputError(f"profile_values: expected at least two values of {block.name!r}, each "
                             f"{block.transform.domain()}, got {theta.tolist()}")
        grid = np.unique(block.transform.to_s(theta))
    solves_before = problem.forward_solves
    warm = [sc.initial for sc in problem.scenarios]
    n = len(grid)
    loss, rms = np.full(n, np.nan), np.full(n, np.nan)
    fitted = np.full((n, p.size), np.nan)
    start = int(np.argmin(np.abs(grid - s_opt[index])))
    record = lambda *args: None  # noqa: E731 - the profile's inner fits keep no history
    for order in (range(start, n), range(start - 1, -1, -1)):
        for sc, x in zip(problem.scenarios, warm):
            sc.initial = x
        s_prev = s_opt.copy()
        for k in order:
            lo_k, hi_k = lo.copy(), hi.copy()
            lo_k[index] = hi_k[index] = grid[k]
            s0 = np.clip(s_prev, lo_k, hi_k)
            try:
                s, r, _, _, _, _ = levenberg_marquardt(problem, s0, lo_k, hi_k, record, max_evaluations, xtol, ftol)
            except SolverError:
                continue  # no equilibrium here: a gap in the profile
            loss[k], rms[k] = 0.5 * float(r @ r), problem.rms(r)
            fitted[k] = p.from_s(s)
            s_prev = s
    for sc, x in zip(problem.scenarios, warm):
        sc.initial = x
    n_free = len(s_opt) - sum(1 for i in range(len(s_opt)) if lo[i] == hi[i])
    data = r_opt[: problem.n_data]
    sigma2 = float(data @ data) / max(problem.n_data - n_free, 1)
    threshold = 0.5 * float(chi2.ppf(confidence, 1)) * sigma2
    values_theta = block.transform.from_s(grid)
    interval, closed = _interval(grid, loss, threshold, block.transform)
    others = {b.name: fitted[:, b.offset] for b in p.blocks if b is not block and b.size == 1}
    return Profile(block.name, values_theta, loss, rms, others, threshold, interval, closed, confidence,
                   problem.forward_solves - solves_before, block.transform.kind == "log")


def _interval(grid: NDArray[np.float64], loss: NDArray[np.float64], threshold: float, transform: Any
              ) -> tuple[tuple[float, float], tuple[bool, bool]]:
    """The values where ``loss <= min + threshold`` around the minimum, interpolated linearly in
    ``s`` at the crossings; an end without a crossing is the grid's end."""
    ok = np.isfinite(loss)
    if not ok.any():
        return (math.nan, math.nan), (False, False)
    best = int(np.nanargmin(loss))
    level = loss[best] + threshold
    ends, closed = [], []
    for step in (-1, 1):
        k = best
        while 0 <= k + step < len(grid) and ok[k + step] and loss[k + step] <= level:
            k += step
        j = k + step
        if 0 <= j < len(grid) and ok[j]:
            t = (level - loss[k]) / (loss[j] - loss[k])
            ends.append(float(transform.from_s(np.array([grid[k] + t * (grid[j] - grid[k])]))[0]))
            closed.append(True)
        else:
            ends.append(float(transform.from_s(np.array([grid[k]]))[0]))
            closed.append(False)
    return (ends[0], ends[1]), (closed[0], closed[1])
