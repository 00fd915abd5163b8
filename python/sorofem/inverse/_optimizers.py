"""The optimisers of the inverse problems, over the scaled parameters ``s``: Levenberg-Marquardt
(on the Jacobian), SciPy's L-BFGS-B (adjoint gradient) and Nelder-Mead, the history
recorder, and the Gauss-Newton uncertainty at an optimum."""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .._files import append_line
from ..errors import SolverError
from ..io import json_text
from ._problem import Problem
from .results import Uncertainty

__all__ = ["Recorder", "levenberg_marquardt", "scipy_minimize", "uncertainty", "bound_sides"]


class Recorder:
    """History of one run: kept in memory, printed when verbose, appended to a JSON-lines file
    (one durable line per accepted iterate, :func:`sorofem.io.append_line`)."""

    def __init__(self, problem: Problem, verbose: bool, path: Path | None, start: int, t0: float,
                 previous: list[dict[str, Any]] | None = None) -> None:
        self.problem, self.verbose, self.path, self.start, self.t0 = problem, verbose, path, start, t0
        #: This start's records, those of an interrupted run it resumes first.
        self.entries: list[dict[str, Any]] = list(previous or [])
        #: Loss and RMS misfit of the points evaluated lately, by the bytes of s: the optimiser's
        #: callback names a point, the value comes from here (never NaN).
        self.evaluated: dict[bytes, tuple[float, float]] = {}

    def remember(self, s: NDArray[np.float64], loss: float, rms: float) -> None:
        if len(self.evaluated) > 256:
            self.evaluated.pop(next(iter(self.evaluated)))
        self.evaluated[np.asarray(s, dtype=np.float64).tobytes()] = (float(loss), float(rms))

    def __call__(self, s: NDArray[np.float64], loss: float, rms: float, state: dict[str, Any] | None = None) -> None:
        p = self.problem.params
        values = p.as_dict(p.from_s(s))
        entry = {
            "kind": "iteration",
            "start": self.start,
            "iteration": len(self.entries),
            "params": {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in values.items()},
            "loss": float(loss),
            "rms": float(rms),
            "forward_solves": self.problem.forward_solves,
            "time": time.perf_counter() - self.t0,
            **({"optimizer": state} if state else {}),
        }
        self.entries.append(entry)
        bar = self.problem.progress
        if bar is not None:
            shown = f"it {entry['iteration']}"
            if math.isfinite(loss):
                shown += f", loss {loss:.4e}, rms {rms:.3g} m"
            bar.set(self.problem.forward_solves, postfix=shown)
        if self.verbose:
            shown = " ".join(
                f"{k}={v:.6g}" if isinstance(v, float) else f"{k}={np.array2string(v[:4], precision=5)}"
                for k, v in values.items()
            )
            line = (
                f"[start {self.start} it {entry['iteration']:3d}] loss {loss:.6e} rms {rms:.3e} m {shown} "
                f"solves {entry['forward_solves']} t {entry['time']:.2f} s"
            )
            if bar is not None and bar.active:
                bar.print(line)  # above the progress line
            else:
                print(line, file=sys.stderr, flush=True)
        self.write(entry)

    def write(self, record: dict[str, Any]) -> None:
        """Append ``record`` to the history file (if any), durably."""
        if self.path is not None:
            append_line(self.path, json_text(record, indent=None))


def levenberg_marquardt(
    problem: Problem,
    s0: NDArray[np.float64],
    lo: NDArray[np.float64],
    hi: NDArray[np.float64],
    record: Recorder,
    max_evaluations: int,
    xtol: float,
    ftol: float,
    resume: dict[str, Any] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], int, bool, str]:
    """Levenberg-Marquardt in s with Marquardt's diagonal scaling and Nielsen's damping
    update; each evaluation is one static solve per scenario plus its sensitivities. Bounds
    by projection. Returns (s, r, J, iterations, converged, message).

    ``resume``: the ``optimizer`` state of the last recorded iterate of an interrupted run
    (``damping``, ``grow``, ``evaluations``, ``iterations``), to go on from ``s0`` as that run
    would have; ``s0`` is then not recorded again."""
    s = np.clip(s0, lo, hi)
    r, J = problem.evaluate(s, "jacobian")
    cost = 0.5 * r @ r
    damping, grow = 1e-3, 2.0
    evaluations, iterations = 1, 0
    if resume:
        damping, grow = float(resume["damping"]), float(resume["grow"])
        evaluations, iterations = int(resume["evaluations"]), int(resume["iterations"])
    else:
        record(s, cost, problem.rms(r), _lm_state(damping, grow, evaluations, iterations))
    while True:
        A = J.T @ J
        g = J.T @ r
        d = np.maximum(np.diag(A), 1e-12 * max(np.diag(A).max(initial=0.0), 1e-300))
        g_free = np.where(((s <= lo) & (g > 0)) | ((s >= hi) & (g < 0)), 0.0, g)
        if cost == 0.0 or np.max(np.abs(g_free)) <= 1e-15 * max(cost, 1e-300):
            return s, r, J, iterations, True, "gradient vanishes"
        # Parameters on a bound that the gradient pushes outwards stay there (active set).
        free = ~(((s <= lo) & (g > 0)) | ((s >= hi) & (g < 0)))
        step = np.zeros_like(s)
        if not np.any(free):
            return s, r, J, iterations, True, "every parameter is held at a bound"
        M = (A + damping * np.diag(d))[np.ix_(free, free)]
        try:
            step[free] = np.linalg.solve(M, -g[free])
        except np.linalg.LinAlgError:
            step[free] = -np.linalg.lstsq(M, g[free], rcond=None)[0]
        s_new = np.clip(s + step, lo, hi)
        step = s_new - s
        if np.linalg.norm(step) <= xtol * (np.linalg.norm(s) + xtol):
            return s, r, J, iterations, True, f"step below xtol = {xtol:g}"
        if evaluations >= max_evaluations:
            return s, r, J, iterations, False, f"stopped after {evaluations} evaluations (max_evaluations)"
        try:
            r_new, J_new = problem.evaluate(s_new, "jacobian")
            cost_new = 0.5 * r_new @ r_new
        except SolverError:
            cost_new = math.inf
        evaluations += 1
        predicted = -(g @ step + 0.5 * step @ A @ step)
        ratio = (cost - cost_new) / predicted if predicted > 0 else -1.0
        if cost_new < cost and ratio > 0:
            reduction = cost - cost_new
            s, r, J, cost = s_new, r_new, J_new, cost_new
            iterations += 1
            damping *= max(1.0 / 3.0, 1.0 - (2.0 * ratio - 1.0) ** 3)
            grow = 2.0
            record(s, cost, problem.rms(r), _lm_state(damping, grow, evaluations, iterations))
            if reduction <= ftol * (cost + reduction):
                return s, r, J, iterations, True, f"relative loss decrease below ftol = {ftol:g}"
        else:
            damping *= grow
            grow *= 2.0


def _lm_state(damping: float, grow: float, evaluations: int, iterations: int) -> dict[str, Any]:
    return {"damping": damping, "grow": grow, "evaluations": evaluations, "iterations": iterations}


def scipy_minimize(
    problem: Problem,
    s0: NDArray[np.float64],
    lo: NDArray[np.float64],
    hi: NDArray[np.float64],
    record: Recorder,
    method: str,
    max_evaluations: int,
    xtol: float,
    ftol: float,
) -> tuple[NDArray[np.float64], int, bool, str]:
    """L-BFGS-B (adjoint gradient) or Nelder-Mead on ``1/2 |r|^2`` over its initial value."""
    from scipy.optimize import minimize

    r0, _ = problem.evaluate(s0, "residual")
    scale = max(0.5 * r0 @ r0, 1e-300)
    record.remember(s0, 0.5 * r0 @ r0, problem.rms(r0))
    record(s0, 0.5 * r0 @ r0, problem.rms(r0))
    gradient_based = method == "l-bfgs-b"

    def fun(s: NDArray[np.float64]) -> Any:
        try:
            r, g = problem.evaluate(np.asarray(s, dtype=np.float64), "gradient" if gradient_based else "residual")
        except SolverError:
            return (1e10, np.zeros_like(s)) if gradient_based else 1e10
        loss = 0.5 * r @ r
        record.remember(s, loss, problem.rms(r))
        return (loss / scale, g / scale) if gradient_based else loss / scale

    def callback(xk: NDArray[np.float64], *args: Any) -> None:
        # The optimisers report points they evaluated (Nelder-Mead: the best vertex).
        known = record.evaluated.get(np.asarray(xk, dtype=np.float64).tobytes())
        if known is None:
            r, _ = problem.evaluate(np.asarray(xk, dtype=np.float64), "residual")
            known = (0.5 * float(r @ r), problem.rms(r))
        record(xk, *known)

    bounds = list(zip(np.where(np.isfinite(lo), lo, None), np.where(np.isfinite(hi), hi, None)))
    if gradient_based:
        res = minimize(
            fun, s0, jac=True, method="L-BFGS-B", bounds=bounds, callback=callback,
            options={"maxfun": max_evaluations, "maxiter": max_evaluations, "ftol": ftol, "gtol": xtol * 1e-3},
        )
    else:
        simplex = np.vstack([s0] + [s0 + 0.1 * e for e in np.eye(len(s0))])
        res = minimize(
            fun, s0, method="Nelder-Mead", bounds=bounds if np.any(np.isfinite(lo) | np.isfinite(hi)) else None,
            callback=callback,
            options={"maxfev": max_evaluations, "xatol": xtol, "fatol": ftol, "initial_simplex": simplex},
        )
    return np.asarray(res.x, dtype=np.float64), int(res.get("nit", 0)), bool(res.success), str(res.message)


def bound_sides(s: NDArray[np.float64], lo: NDArray[np.float64], hi: NDArray[np.float64]) -> list[str | None]:
    """Per parameter, ``"lower"`` or ``"upper"`` if it sits on that bound (to rounding), else None."""
    tol = 1e-9 * (1.0 + np.abs(s))
    return ["lower" if s[i] - lo[i] <= tol[i] else "upper" if hi[i] - s[i] <= tol[i] else None for i in range(len(s))]


def uncertainty(
    names: list[str], theta: NDArray[np.float64], dts: NDArray[np.float64], r: NDArray[np.float64],
    J_s: NDArray[np.float64], n_data: int, at_bound: list[str | None] | None = None,
) -> Uncertainty:
    """Gauss-Newton uncertainty from the scaled Jacobian ``J_s = dr/ds`` (``dts = dtheta/ds``).

    The parameters on a bound (``at_bound``) are held there: the covariance is that of the free
    parameters alone (NaN in the rows of the others); the singular values and the worst
    determined direction are those of every parameter."""
    p = len(theta)
    sides = list(at_bound) if at_bound is not None else [None] * p
    bound = np.array([side is not None for side in sides], dtype=bool)
    free = ~bound
    dof = max(n_data - int(free.sum()), 1)
    sigma = float(np.sqrt(r[:n_data] @ r[:n_data] / dof))
    _, sv_all, vt_all = np.linalg.svd(J_s, full_matrices=False)
    cov_s = np.full((p, p), np.nan)
    weak = np.zeros(p, dtype=bool)
    if free.any():
        # The columns are in the optimiser's variables, which mix units (a log-space modulus is
        # per relative change, a sign-free coefficient per Pa): equilibrated to unit norm, the
        # rank test and the weak directions do not depend on those units.
        columns = J_s[:, free]
        norms = np.linalg.norm(columns, axis=0)
        scale = np.where(norms > 0, norms, 1.0)
        _, sv, vt = np.linalg.svd(columns / scale, full_matrices=False)
        null = sv <= 1e-6 * (sv[0] if sv.size and sv[0] > 0 else 1.0)
        if sv.size < norms.size:
            null = np.r_[null, np.ones(norms.size - sv.size, dtype=bool)]
            vt = np.vstack([vt, np.linalg.svd(columns / scale)[2][sv.size:]])
            sv = np.r_[sv, np.zeros(norms.size - sv.size)]
        good = ~null
        inv_sq = 1.0 / np.where(null, 1.0, sv) ** 2
        sub = np.einsum("ki,k,kj->ij", vt[good], inv_sq[good], vt[good]) * sigma**2 / np.outer(scale, scale)
        # Directions the data do not see: those parameters get an infinite variance.
        weak_free = np.any(np.abs(vt[null]) > 1e-2, axis=0) if null.any() else np.zeros(int(free.sum()), dtype=bool)
        sub[weak_free, :] = np.inf
        sub[:, weak_free] = np.inf
        cov_s[np.ix_(free, free)] = sub
        weak[free] = weak_free
    cov = cov_s * np.outer(dts, dts)
    with np.errstate(invalid="ignore", divide="ignore"):
        std = np.sqrt(np.abs(np.diag(cov)))
        rel = std / np.abs(theta)
        d = np.sqrt(np.diag(cov_s))
        corr = cov_s / np.outer(d, d)
    cond = float(sv_all[0] / sv_all[-1]) if sv_all.size and sv_all[-1] > 0 else math.inf
    ident = {n: bool(free[i] and rel[i] < 0.1 and not weak[i]) for i, n in enumerate(names)} if p == len(names) else {}
    sides_by_name = dict(zip(names, sides)) if p == len(names) else {}
    weakest = vt_all[-1] * np.sign(vt_all[-1][np.argmax(np.abs(vt_all[-1]))]) if sv_all.size else None
    return Uncertainty(names, sigma, cov, std, rel, np.nan_to_num(corr, nan=0.0, posinf=0.0, neginf=0.0), sv_all, cond,
                       ident, sides_by_name, weakest)
