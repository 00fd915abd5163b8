"""What the inverse functions return: :class:`GradientResult`, :class:`FitResult` (with its
:class:`Uncertainty` and :class:`Profile`) and :class:`ControlResult`."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import math

import numpy as np
from numpy.typing import NDArray

from .._text import plural
from ..fitting import format_uncertain
from ..materials import Material

__all__ = ["GradientResult", "Uncertainty", "Profile", "FitResult", "ControlResult", "NOT_IDENTIFIABLE"]

#: What :meth:`Uncertainty.to_dict` (and ``summary.json``) says for a standard deviation the
#: data do not bound.
NOT_IDENTIFIABLE = "not identifiable"


@dataclass
class GradientResult:
    """Value and gradient of an objective at the equilibrium.

    Attributes
    ----------
    value
        O(x) at the equilibrium.
    gradient
        name -> dO/dtheta (float for scalar parameters, arrays for fields, gravity, cables),
        in units of O per unit of the parameter.
    core
        The extension's raw adjoint by key: dO/d(each material parameter per element under its
        core name, "mu", "lambda" or "c10", "mu:0", ...; "density"; "gravity"; the cable
        values), with the aliases "lam" and "rho".
    result
        The :class:`~sorofem.StaticResult` the gradient was taken at.
    """

    value: float
    gradient: dict[str, Any]
    core: dict[str, NDArray[np.float64]]
    result: Any

    @property
    def vector(self) -> NDArray[np.float64]:
        """All gradient entries concatenated in the order of ``params``."""
        return np.concatenate([np.atleast_1d(np.asarray(v, dtype=np.float64)) for v in self.gradient.values()])


@dataclass
class Uncertainty:
    """Gauss-Newton uncertainty at a least-squares optimum.

    A parameter on an active bound (the data push it past the bound) is no interior estimate:
    it gets no standard error (NaN, ``at_bound`` says which bound), and the others' covariance
    is the one with it held at its bound (the columns of the free parameters only).

    Attributes
    ----------
    sigma
        Residual standard deviation, m: ``sqrt(|r|^2 / (N - p))``.
    covariance
        ``sigma^2 (J^T J)^-1`` in the original parameter units (``J = dr/dtheta``, free
        parameters only); infinite along directions the data do not determine, NaN in the rows
        and columns of parameters at a bound.
    std, relative_std
        Standard deviation of each parameter, absolute and over its value (NaN at a bound).
    correlation
        Correlation matrix (0 in the rows of parameters at a bound).
    singular_values
        Of the scaled Jacobian ``dr/ds`` of every parameter, bound or not (``s``: log theta, or
        the logit of the Poisson ratio; m per unit relative change), descending: a small one
        means a combination of parameters the data hardly see.
    condition
        Ratio of the largest to the smallest singular value.
    identifiable
        name -> whether the parameter is pinned by the data: not at a bound, its relative std
        below 10 % and a weight above 1 % in no near-null direction (singular value below 1e-6
        of the largest).
    at_bound
        name -> ``"lower"`` or ``"upper"`` for a parameter that ended on that bound, else None.
    weak_direction
        ``(p,)`` unit vector in ``s``: the combination of parameters the data determine worst
        (right singular vector of the smallest singular value).
    material_std
        Standard deviation of every parameter of the fitted material in each of its forms
        (``youngs_modulus``, ``poisson_ratio`` and ``shear_modulus``, ``lame_lambda``), by
        linear propagation of ``covariance`` (parameters at a bound held there); empty when
        the fit has region, field or non-material parameters.
    """

    names: list[str]
    sigma: float
    covariance: NDArray[np.float64]
    std: NDArray[np.float64]
    relative_std: NDArray[np.float64]
    correlation: NDArray[np.float64]
    singular_values: NDArray[np.float64]
    condition: float
    identifiable: dict[str, bool]
    at_bound: dict[str, str | None] = field(default_factory=dict)
    weak_direction: NDArray[np.float64] | None = None
    material_std: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """Plain data for JSON: a standard deviation the data do not bound (infinite, or undefined)
        is the string ``"not identifiable"``, an infinite condition number ``"infinite"``; that
        of a parameter held at a bound stays NaN (``null`` in ``summary.json``; ``at_bound``
        says which bound)."""

        def bounded(values: NDArray[np.float64]) -> dict[str, Any]:
            return {n: float(v) if np.isfinite(v) or self.at_bound.get(n) else NOT_IDENTIFIABLE
                    for n, v in zip(self.names, values)}

        return {
            "sigma": float(self.sigma) if np.isfinite(self.sigma) else NOT_IDENTIFIABLE,
            "std": bounded(self.std),
            "relative_std": bounded(self.relative_std),
            "correlation": np.nan_to_num(self.correlation, nan=0.0, posinf=0.0, neginf=0.0).tolist(),
            "singular_values": self.singular_values.tolist(),
            "condition": float(self.condition) if np.isfinite(self.condition) else "infinite",
            "identifiable": {n: bool(self.identifiable.get(n, False)) and bool(np.isfinite(s))
                             for n, s in zip(self.names, self.std)},
            "at_bound": self.at_bound,
            "weak_direction": None if self.weak_direction is None else dict(zip(self.names, map(float, self.weak_direction))),
            "material_std": {k: float(v) if np.isfinite(v) else NOT_IDENTIFIABLE
                             for k, v in dict(self.material_std).items()},
        }


@dataclass
class Profile:
    """Profile of the misfit along one parameter: at each of its values the other parameters
    are fitted again (profile likelihood).

    Along a poorly determined direction the Gauss-Newton standard error (a local, linear
    statement) says little; the profile shows the valley itself. The interval is the
    likelihood-ratio one: the values where ``|r|^2`` exceeds its minimum by at most
    ``chi2_1(confidence) sigma^2`` (``sigma^2 = |r|^2 / (N - p)`` at the optimum), i.e. the
    loss ``1/2 |r|^2`` by at most :attr:`threshold`. It assumes independent residuals of equal
    variance; where the misfit is model error rather than noise the interval is optimistic,
    and the RMS range along the profile is the plainer statement.

    Attributes
    ----------
    name
        The profiled parameter.
    values
        ``(k,)`` its values, ascending, in its units.
    loss, rms
        ``(k,)`` ``1/2 |r|^2`` (m^2) and the RMS distance of the observed points from their
        goals (m), with the other parameters re-fitted; NaN where no equilibrium was found.
    params
        name -> ``(k,)`` the re-fitted value of every other parameter along the profile.
    threshold
        Largest loss increase inside the interval, m^2: ``chi2_1(confidence) sigma^2 / 2``.
    interval
        ``(lo, hi)``: the values whose loss is within :attr:`threshold` of the smallest,
        interpolated between the points in the optimiser's scaling.
    closed
        Whether the loss crosses the threshold at each end of :attr:`interval`; False: the
        interval reaches the end of the profiled range (a bound, or as far as it was profiled)
        and may go on beyond it.
    confidence
        Of the interval.
    forward_solves
        Static solves spent on the profile.
    log_scale
        Whether the parameter is optimised in log space (then its values are best shown on a
        log axis).
    """

    name: str
    values: NDArray[np.float64]
    loss: NDArray[np.float64]
    rms: NDArray[np.float64]
    params: dict[str, NDArray[np.float64]]
    threshold: float
    interval: tuple[float, float]
    closed: tuple[bool, bool]
    confidence: float = 0.95
    forward_solves: int = 0
    log_scale: bool = False

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "values": self.values.tolist(),
            "loss": self.loss.tolist(),
            "rms": self.rms.tolist(),
            "params": {k: v.tolist() for k, v in self.params.items()},
            "threshold": self.threshold,
            "interval": list(self.interval),
            "closed": list(self.closed),
            "confidence": self.confidence,
            "forward_solves": self.forward_solves,
        }

    def summary(self, symbol: Any = None) -> str:
        """One line: the range profiled, how the other parameters move along it, the RMS misfit
        along it and the interval. ``symbol(name) -> (symbol, units)`` names the parameters."""
        sym = symbol or (lambda n: (n, ""))
        name, units = sym(self.name)
        ok = np.isfinite(self.rms)
        if not ok.any():
            return f"profile of {name}: no equilibrium at any of its points"
        moved = []
        for other, values in self.params.items():
            o_name, o_units = sym(other)
            v = values[ok]
            moved.append(f"{o_name} {number(v.min())}..{number(v.max())}{_units(o_units)}")
        lo, hi = self.interval
        open_end = " (end of the profile)"
        return (
            f"profile of {name} over {number(self.values[0])}..{number(self.values[-1])}{_units(units)}"
            + (f" ({', '.join(moved)} re-fitted)" if moved else "")
            + f": rms misfit {number(self.rms[ok].min() * 1e3)}..{number(self.rms[ok].max() * 1e3)} mm; "
            f"{100 * self.confidence:g} % likelihood interval {number(lo)}{'' if self.closed[0] else open_end}.."
            f"{number(hi)}{'' if self.closed[1] else open_end}{_units(units)} (if the misfit were independent noise)"
        )


def number(value: float, digits: int = 4) -> str:
    """``digits`` significant digits, without an exponent from 1e-3 to 1e7 (51390, 0.4999)."""
    if not math.isfinite(value) or value == 0:
        return f"{value:g}"
    top = math.floor(math.log10(abs(value)))
    if -3 <= top < 7:
        decimals = digits - 1 - top
        return f"{round(value, decimals):.{max(decimals, 0)}f}"
    return f"{value:.{digits - 1}e}"


def _markers(targets: list[tuple[str, Any]], results: list[Any]) -> list[tuple[NDArray[np.float64], NDArray[np.float64], str]]:
    return [(t.points(r.positions), t.matched_goal(r.positions), name) for (name, t), r in zip(targets, results)]


def _units(units: str) -> str:
    return f" {units}" if units else ""


@dataclass
class FitResult:
    """Outcome of :func:`estimate`.

    Attributes
    ----------
    params
        name -> fitted value (float, or an array for fields and cables).
    material
        The fitted :class:`~sorofem.NeoHookean` (per-element arrays when regions or fields).
    loss
        ``1/2 |r|^2`` at the optimum, m^2 (regularisation included).
    residual
        Root-mean-square distance of the observed points from their goals, m.
    forward_solves
        Static solves, all starts and the profile together (warm-started; failed attempts
        included); for a fit to motion, simulated trajectories.
    newton_iterations
        Newton iterations over those solves.
    iterations
        Optimiser iterations of the best start.
    history
        Per iteration: ``{"start", "iteration", "params", "loss", "rms", "forward_solves", "time"}``.
    uncertainty
        :class:`Uncertainty` (None for fields: too many parameters to invert).
    profile
        :class:`Profile` of the misfit along the worst determined parameter, or None (see
        ``profile=`` of :func:`sorofem.estimate`).
    starts
        Per start: its initial point, final params, loss and forward solves.
    results
        One :class:`~sorofem.StaticResult` per scenario at the optimum (empty for a fit to
        motion).
    trajectory
        A fit to motion (``estimate(..., dynamics=...)``): the :class:`~sorofem.Trajectory` at
        the optimum, else None.
    """

    params: dict[str, Any]
    material: Any
    loss: float
    residual: float
    forward_solves: int
    newton_iterations: int
    iterations: int
    method: str
    converged: bool
    message: str
    time: float
    history: list[dict[str, Any]] = field(default_factory=list)
    uncertainty: Uncertainty | None = None
    starts: list[dict[str, Any]] = field(default_factory=list)
    results: list[Any] = field(default_factory=list)
    profile: Profile | None = None
    #: ``(name, BoundTarget)`` of each scenario, in the order of :attr:`results`; for a fit to
    #: motion ``(time (s), BoundTarget)`` of each marker track.
    targets: list[tuple[Any, Any]] = field(default_factory=list)
    trajectory: Any = None

    def markers(self) -> list[tuple[NDArray[np.float64], NDArray[np.float64], str]]:
        """Per scenario: where the fitted model puts the observed points ``(k, 3)``, their goals
        ``(k, 3)`` (m) and the scenario's name (what ``fit.png`` shows); for a fit to motion one
        entry, every track's points at its frame stacked."""
        if self.trajectory is None:
            return _markers(self.targets, self.results)
        times, positions = self.trajectory.times, self.trajectory.positions
        frames = [positions[int(np.argmin(np.abs(times - t)))] for t, _ in self.targets]
        model = [target.points(x) for (_, target), x in zip(self.targets, frames)]
        goal = [target.matched_goal(x) for (_, target), x in zip(self.targets, frames)]
        return [(np.vstack(model), np.vstack(goal), "marker tracks")] if model else []

    @property
    def youngs_modulus(self) -> Any:
        """E of the fitted material, Pa."""
        return self.material.youngs_modulus

    @property
    def poisson_ratio(self) -> Any:
        """nu of the fitted material."""
        return self.material.poisson_ratio

    @property
    def shear_modulus(self) -> Any:
        return self.material.shear_modulus

    @property
    def lame_lambda(self) -> Any:
        return self.material.lame_lambda

    @property
    def result(self) -> Any:
        """The first scenario's equilibrium at the optimum."""
        return self.results[0] if self.results else None

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON summary."""
        plain = lambda v: v.tolist() if isinstance(v, np.ndarray) else v  # noqa: E731
        return {
            "params": {k: plain(v) for k, v in self.params.items()},
            "material": self.material.to_dict(),
            "loss": self.loss,
            "residual_rms": self.residual,
            "forward_solves": self.forward_solves,
            "newton_iterations": self.newton_iterations,
            "iterations": self.iterations,
            "method": self.method,
            "converged": self.converged,
            "message": self.message,
            "time": self.time,
            "uncertainty": None if self.uncertainty is None else self.uncertainty.to_dict(),
            "profile": None if self.profile is None else self.profile.to_dict(),
            "starts": [{k: plain(v) for k, v in s.items()} for s in self.starts],
        }

    def symbol(self, name: str) -> tuple[str, str]:
        """``(symbol, units)`` of a parameter name (``"mu"``, ``"Pa"`` for ``"shear_modulus"``;
        a region keeps its suffix: ``"mu:tip"``)."""
        kind, _, region = name.partition(":")
        model = self.material.model
        try:
            p = model.parameter(kind)
        except KeyError:
            return name, {"cable_stiffness": "N/m", "mass_damping": "1/s", "stiffness_damping": "s",
                         "cable_damping": "N s/m"}.get(kind, "")
        return p.symbol + (f":{region}" if region else ""), p.units

    def summary(self) -> str:
        """A readable report: each fitted parameter with its standard error (rounded to two
        significant digits of it), or "at bound", the material in its other forms, the misfit,
        the conditioning and, when computed, the profile along the worst determined direction."""
        unc = self.uncertainty
        lines = [f"fitted {', '.join(self.params)} ({self.method}): "
                 f"{'converged' if self.converged else 'NOT converged'}, {self.message}"]
        width = max(len(self.symbol(n)[0]) for n in self.params)
        for i, (name, value) in enumerate(self.params.items()):
            sym, units = self.symbol(name)
            if np.ndim(value) > 0:
                text = f"{number(np.min(value))}..{number(np.max(value))}{_units(units)} ({np.size(value)} values)"
            elif unc is None:
                text = f"{number(value)}{_units(units)} (no uncertainty computed)"
            elif unc.at_bound.get(name):
                text = (f"{number(value)}{_units(units)} at its {unc.at_bound[name]} bound (no standard error: the "
                        "data push it past the bound)")
            else:
                text = format_uncertain(value, float(unc.std[i]), units)
            lines.append(f"  {sym:<{width}} = {text}")
        material_line = self._material_line()
        if material_line:
            lines.append(material_line)
        lines.append(f"  residual {self.residual:.3g} m rms; {plural(self.forward_solves, 'forward solve')}, "
                     f"{self.time:.3g} s")
        if unc is not None and unc.singular_values.size > 1:
            weak = ""
            if unc.weak_direction is not None:
                terms = " ".join(f"{c:+.2f} {self.symbol(n)[0]}" for n, c in zip(self.params, unc.weak_direction)
                                 if abs(c) >= 0.01)
                weak = f"; worst determined direction (in the optimiser's log/logit scaling): {terms}"
            cond = f"{unc.condition:.2g}" if math.isfinite(unc.condition) else "inf (singular)"
            lines.append(f"  condition number {cond}{weak}")
        if self.profile is not None:
            lines.append("  " + self.profile.summary(self.symbol))
        return "\n".join(lines)

    def _material_line(self) -> str:
        """The fitted material in every form, with standard errors where propagated."""
        m = self.material
        if not isinstance(m, Material) or any(np.ndim(m.value(n)) for f in m.model.forms for n in f.names):
            return ""
        unc = self.uncertainty
        std = unc.material_std if unc is not None else {}
        held = [n for n, side in (unc.at_bound.items() if unc is not None else ()) if side]
        parts = []
        for form in m.model.forms:
            for name in form.names:
                p = m.model.parameter(name)
                value = float(m.value(name))
                s = std.get(name)
                if name in held:
                    text = f"{number(value)}{_units(p.units)} (at its bound)"
                elif s is None or s == 0:  # not fitted, or fitted without an uncertainty
                    text = f"{number(value)}{_units(p.units)}" + (" (fixed)" if s == 0 else "")
                else:
                    text = format_uncertain(value, s, p.units)
                parts.append(f"{p.symbol} = {text}")
        note = f"; errors with {', '.join(self.symbol(n)[0] for n in held)} held there" if held and std else ""
        return "  material: " + "; ".join(parts) + note


@dataclass
class ControlResult:
    """Outcome of :func:`control`.

    Attributes
    ----------
    actuation
        ``(c,)`` command of each controlled cable (in the order of ``cables``): the alpha of
        a spring cable, the pull (m) or tension (N) of a tendon.
    distance
        Root-mean-square distance of the target's points from their goals, m.
    max_distance
        Largest distance of a target point from its goal, m.
    reachable
        ``distance <= tolerance``.
    tolerance
        The distance counted as reached, m.
    points
        ``(k, 3)`` where the target's points end up (the closest reachable configuration).
    result
        The :class:`~sorofem.StaticResult` at ``actuation``.
    message
        What happened, including "not reachable" and which bounds are active.
    """

    actuation: NDArray[np.float64]
    distance: float
    max_distance: float
    reachable: bool
    tolerance: float
    points: NDArray[np.float64]
    result: Any
    forward_solves: int
    iterations: int
    message: str
    time: float
    active_bounds: list[str] = field(default_factory=list)
    history: list[dict[str, Any]] = field(default_factory=list)
    #: ``(name, BoundTarget)`` of the target.
    targets: list[tuple[str, Any]] = field(default_factory=list)

    def markers(self) -> list[tuple[NDArray[np.float64], NDArray[np.float64], str]]:
        """Where the actuated model puts the target's points ``(k, 3)``, their goals ``(k, 3)``
        (m) and the target's name (what ``fit.png`` shows)."""
        return _markers(self.targets, [self.result])

    def to_dict(self) -> dict[str, Any]:
        return {
            "actuation": self.actuation.tolist(),
            "distance": self.distance,
            "max_distance": self.max_distance,
            "reachable": self.reachable,
            "tolerance": self.tolerance,
            "points": self.points.tolist(),
            "forward_solves": self.forward_solves,
            "iterations": self.iterations,
            "message": self.message,
            "time": self.time,
            "active_bounds": self.active_bounds,
        }
