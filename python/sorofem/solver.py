"""What is asked of the nonlinear solver and what it reports: :class:`SolveOptions` and
:class:`SolveReport`.

The options travel as one object from a scene file's ``[solver]`` table (or the command line)
to the solve call; the scene's ``[solver]`` keys are generated from the fields of
:class:`SolveOptions` (their defaults, ranges and descriptions), so a new solver option is one
field here.

Examples
--------
>>> from sorofem.solver import SolveOptions
>>> options = SolveOptions(tolerance=1e-10)
>>> options.max_iterations, options.replace(load_steps=4).load_steps
(50, 4)
"""

from __future__ import annotations

import math
import numbers
import warnings
from dataclasses import asdict, dataclass, field, fields, replace
from typing import Any

from ._extension import core
from ._text import plural
from ._validate import MAX_CUTBACKS, MAX_LOAD_STEPS, MAX_NEWTON_ITERATIONS, Range, count, describe
from .errors import ParameterError

__all__ = ["SolveOptions", "SolveReport", "MERITS"]

#: What Newton's line search decreases, by formulation: the potential energy (standard) or half
#: the squared residual (mixed, whose energy has a saddle point in the pressure).
MERITS: dict[str, str] = {"standard": "energy", "mixed": "residual"}


def _option(default: Any, doc: str, valid: Range, integer: bool = False, maximum: int | None = None) -> Any:
    """A field of :class:`SolveOptions` with what the scene's ``[solver]`` table shows of it
    (``maximum``: the documented limit of an integer option)."""
    return field(default=default, metadata={"doc": doc, "range": valid, "integer": integer, "maximum": maximum})


@dataclass(frozen=True)
class SolveOptions:
    """Options of Newton's method for a static solve.

    Attributes
    ----------
    tolerance
        Relative residual norm (residual over load norm) at which Newton stops, > 0.
    max_iterations
        Newton iterations allowed per load step, from 1 to 10000 (a documented limit).
    load_steps
        Equal load increments, from 1 to 10000 (a documented limit; the solver may cut a step
        back).
    max_cutbacks
        How many times a failed load step may be halved before the solve gives up, from 0 to 60
        (a documented limit).

    Raises
    ------
    ParameterError
        A value out of range (the error names it).
    """

    tolerance: float = _option(
        1e-8, "Newton stops when the residual norm over the load norm is below this", Range(gt=0)
    )
    max_iterations: int = _option(50, "Newton iterations per load step", Range(ge=1), integer=True,
                                  maximum=MAX_NEWTON_ITERATIONS)
    load_steps: int = _option(
        1, "equal load increments (the solver may cut a step back)", Range(ge=1), integer=True, maximum=MAX_LOAD_STEPS
    )
    max_cutbacks: int = _option(
        8, "times a failed load step may be halved before the solve gives up", Range(ge=0), integer=True,
        maximum=MAX_CUTBACKS,
    )

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if f.metadata["integer"]:
                value = count(value, f.name, int(f.metadata["range"].ge), f.metadata["maximum"])
            else:
                if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(value):
                    raise ParameterError(f"{f.name}: expected a finite number, got {describe(value)}", f.name)
                value = float(value)
            f.metadata["range"].check(value, f.name)
            object.__setattr__(self, f.name, value)

    def to_core(self) -> Any:
        """The same options as the core's ``sorofem._core.SolveOptions`` (what a solve passes)."""
        return core().SolveOptions(**asdict(self))

    def replace(self, **changes: Any) -> "SolveOptions":
        """A copy with some options changed (checked again)."""
        return replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """``{"tolerance": ..., "max_iterations": ..., "load_steps": ..., "max_cutbacks": ...}``:
        the scene's ``[solver]`` table."""
        return asdict(self)


@dataclass
class SolveReport:
    """What the nonlinear solver did.

    Attributes
    ----------
    converged
        Whether the relative residual reached the tolerance.
    iterations
        Newton iterations over all load steps.
    residual_history
        Relative residual norm after each iteration.
    merit
        What Newton's line search decreases (:data:`MERITS`): ``"energy"``, the total potential
        energy (standard formulation), or ``"residual"``, half the squared norm of the
        residual (mixed formulation: the pressure makes the energy a saddle point, which has
        no minimum to descend to).
    merit_history
        That quantity after each iteration: J for ``"energy"``; N^2 for ``"residual"`` (the
        volume-constraint rows scaled to forces by the pressure weight). Formerly
        ``energy_history``.
    load_steps
        Accepted load steps (including those added by cutbacks).
    cutbacks
        How many times a load step failed and was halved.
    projected_steps
        Newton iterations that used the projected (positive semi-definite) Hessian.
    factorizations
        Numeric factorisations of the Hessian (one per iteration, plus one for every exact
        Hessian that turned out indefinite).
    failed_factorizations
        Those of them that gave no usable direction (matrix not positive definite).
    single_precision_factorizations
        Those of them computed in single precision (only the kept factorisations of dynamics'
        modified Newton; static solves factor in double precision).
    step_lengths
        Line-search step length of each iteration.
    timings
        Seconds per phase: ``assembly``, ``factorization`` (of which ``failed_factorization``
        in the failed ones), ``solve``, ``line_search``, ``total``.
    absolute_residual_norm
        Final residual (gradient) norm, N.
    reference_norm
        The norm the residual is divided by to make it relative, N.
    message
        The solver's own one-line account (empty if none).
    """

    converged: bool = False
    iterations: int = 0
    residual_history: list[float] = field(default_factory=list)
    merit_history: list[float] = field(default_factory=list)
    load_steps: int = 0
    cutbacks: int = 0
    projected_steps: int = 0
    factorizations: int = 0
    failed_factorizations: int = 0
    single_precision_factorizations: int = 0
    step_lengths: list[float] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    absolute_residual_norm: float = math.nan
    reference_norm: float = math.nan
    message: str = ""
    merit: str = "energy"

    @classmethod
    def from_dict(cls, data: dict[str, Any], formulation: str = "standard") -> "SolveReport":
        """Build from the extension's report dict (unknown keys ignored) of a solve in
        ``formulation``."""
        return cls(
            converged=bool(data.get("converged", False)),
            iterations=int(data.get("iterations", 0)),
            residual_history=[float(r) for r in data.get("residual_history", [])],
            # The extension calls the merit "energy_history" whatever it is.
            merit_history=[float(e) for e in data.get("energy_history", [])],
            load_steps=int(data.get("load_steps", 0)),
            cutbacks=int(data.get("cutbacks", 0)),
            projected_steps=int(data.get("projected_steps", 0)),
            factorizations=int(data.get("factorizations", 0)),
            failed_factorizations=int(data.get("failed_factorizations", 0)),
            single_precision_factorizations=int(data.get("single_precision_factorizations", 0)),
            step_lengths=[float(t) for t in data.get("step_lengths", [])],
            timings={str(k): float(v) for k, v in dict(data.get("timings", {})).items()},
            # The extension's "residual_norm" is absolute; ours (a property) is relative.
            absolute_residual_norm=float(data.get("residual_norm", math.nan)),
            reference_norm=float(data.get("reference_norm", math.nan)),
            message=str(data.get("message", "")),
            merit=MERITS.get(formulation, "energy"),
        )

    @property
    def energy_history(self) -> list[float]:
        """Deprecated: :attr:`merit_history` (an energy only in the standard formulation)."""
        warnings.warn(
            "SolveReport.energy_history is deprecated: use merit_history (the potential energy in J for the "
            "standard formulation, half the squared residual in N^2 for the mixed one; see SolveReport.merit)",
            DeprecationWarning,
            stacklevel=2,
        )
        return self.merit_history

    @property
    def residual_norm(self) -> float:
        """Final **relative** residual norm (NaN if no iterate was recorded)."""
        return self.residual_history[-1] if self.residual_history else math.nan

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def summary(self) -> str:
        """A few human-readable lines."""
        status = "converged" if self.converged else "did NOT converge"
        lines = [
            f"Newton {status} in {plural(self.iterations, 'iteration')} "
            f"({plural(self.load_steps, 'load step')}, {plural(self.cutbacks, 'cutback')}), "
            f"relative residual {self.residual_norm:.3e}"
        ]
        if self.timings:
            parts = ", ".join(f"{k} {v:.3f}" for k, v in self.timings.items())
            lines.append(f"time [s]: {parts}")
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.summary()
