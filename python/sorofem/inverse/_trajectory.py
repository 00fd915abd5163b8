"""The gradient of an objective of a whole simulated trajectory: :func:`trajectory_gradient`.

The discrete adjoint of the implicit Euler steps of :func:`sorofem.simulate` (docs/theory.md,
"Trajectory adjoint"), computed by the extension: the forward pass solves every step by
modified Newton to the tolerance (by default :func:`sorofem.simulate`'s: the same run), keeps
every state (or, for runs too long for that, every ``checkpoint_every``-th state, recomputing
the others segment by segment in the backward sweep), one factorisation of the step's Hessian
per step. Cable dashpots and frictionless contact (obstacles, self-contact) are differentiated;
friction is refused.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._extension import core
from .._validate import MAX_TIME_STEPS, as_finite, describe, non_negative, positive_int, positive_scalar
from ..body import Body, set_cable_values
from ..cables import cable_index
from ..dynamics import DEFAULT_STEP_TOLERANCE, Keyframes, Trajectory, evaluate_schedule
from ..errors import InputError, ParameterError
from ..static import StaticResult, check_magnitudes
from ..targets import BoundTarget, Target
from ._parameters import COMMAND_PARAMETERS, Parameters, core_sensitivities
from ._problem import bind

__all__ = ["trajectory_gradient", "TrajectoryGradientResult", "TRAJECTORY_PARAMETERS"]

#: Names :func:`trajectory_gradient` takes besides those of :func:`sorofem.gradient` (the
#: material's, ``density``, ``gravity``, ``cable_stiffness``): the Rayleigh coefficients, each
#: spring cable's dashpot ``cable_damping`` (N s/m, :class:`sorofem.Cable`'s ``damping``), the
#: whole schedule, and ``"keyframes:<cable>"`` for a cable whose schedule is a
#: :class:`sorofem.dynamics.Keyframes` (the gradient by each keyframe's value).
TRAJECTORY_PARAMETERS = ("mass_damping", "stiffness_damping", "cable_damping", "actuation", "keyframes:<cable>")

#: Newton's relative tolerance of every step when none is given: :func:`sorofem.simulate`'s, so
#: that the gradient is taken along the very trajectory the simulation returns. The adjoint
#: differentiates the converged step equations, so the residual left in the states perturbs the
#: gradient: by 3e-10 relative at this tolerance on the hammerbot's swing (BENCHMARKS.md,
#: "Trajectory gradient"); a tighter one makes it smaller.
DEFAULT_TOLERANCE = DEFAULT_STEP_TOLERANCE


@dataclass
class TrajectoryGradientResult:
    """Value and gradient of a trajectory objective.

    Attributes
    ----------
    value
        J of the trajectory.
    gradient
        name -> dJ/dtheta in units of J per unit of the parameter: floats for scalar
        parameters, ``(steps, n_cables)`` for ``"actuation"`` (per step, each cable's alpha,
        pull (m) or tension (N)), ``(k,)`` for ``"keyframes:<cable>"``, one per spring cable
        (in the body's order, as ``"cable_stiffness"``) for ``"cable_damping"``.
    positions
        ``(steps + 1, n_nodes, 3)`` node positions (m) of the trajectory the gradient was taken
        along (``times[i] = i dt``).
    iterations
        Newton iterations of every step.
    balanced_stiffness_steps
        Steps whose barrier stiffness IPC balanced inside its bounds at their start (in
        contact there): the gradient follows its change with the parameters and the states.
    split_steps
        Steps the run halved as :func:`sorofem.simulate` does (where Newton failed or a moving
        obstacle would have run into the body), differentiated through their halves: the
        gradient is that of the simulation wherever a small change of the parameters keeps
        those halvings (a central difference across a change of them jumps).
    """

    value: float
    gradient: dict[str, Any]
    positions: NDArray[np.float64]
    iterations: NDArray[np.int64]
    split_steps: int = 0
    balanced_stiffness_steps: int = 0

    @property
    def vector(self) -> NDArray[np.float64]:
        """All gradient entries concatenated in the order of ``params``."""
        return np.concatenate([np.ravel(np.asarray(v, dtype=np.float64)) for v in self.gradient.values()])


def _timed_targets(objective: Sequence[Any], mesh: Any, dt: float, steps: int) -> list[tuple[int, BoundTarget]]:
    """``[(time, Target), ...]`` as (frame, bound target); every time must be a frame's."""
    out = []
    for i, entry in enumerate(objective):
        if not isinstance(entry, (tuple, list)) or len(entry) != 2 or not isinstance(entry[1], (Target, BoundTarget)):
            raise InputError(f"objective[{i}]: expected a (time, sorofem.Target) pair, got {describe(entry)}")
        t = entry[0]
        if isinstance(t, bool) or not isinstance(t, numbers.Real) or not math.isfinite(float(t)):
            raise InputError(f"objective[{i}]: expected a finite time (s), got {describe(t)}")
        # A time far beyond the run (t / dt overflows) is out of range, not an OverflowError.
        ratio = float(t) / dt
        frame = round(ratio) if math.isfinite(ratio) and abs(ratio) <= steps + 1 else -1
        if not (0 <= frame <= steps and abs(frame * dt - float(t)) <= 1e-9 * max(1.0, abs(float(t)))):
            raise ParameterError(
                f"objective[{i}]: the time {float(t):g} s is not one of the frames 0, dt, ..., {steps} dt "
                f"(dt = {dt:g} s)", "objective")
        out.append((frame, bind(entry[1], mesh)))
    if not out:
        raise InputError("objective: expected at least one (time, Target) pair")
    return out


def _objective_function(objective: Any, mesh: Any, dt: float, steps: int) -> Any:
    """``positions (steps + 1, n, 3) -> (value, dJ/dx of the same shape)``, checked."""
    n = mesh.n_nodes
    shape = (steps + 1, n, 3)
    if isinstance(objective, (Target, BoundTarget)):
        objective = [(steps * dt, objective)]
    if isinstance(objective, (list, tuple)):
        timed = _timed_targets(objective, mesh, dt, steps)

        def misfits(positions: NDArray[np.float64]) -> tuple[float, NDArray[np.float64]]:
            value, dx = 0.0, np.zeros(shape)
            for frame, target in timed:
                v, d = target.misfit(positions[frame])
                value += v
                dx[frame] += d
            return value, dx

        return misfits
    if not callable(objective):
        raise InputError(f"objective: expected a callable, a Target or (time, Target) pairs, got {describe(objective)}")

    def checked(positions: NDArray[np.float64]) -> tuple[float, NDArray[np.float64]]:
        try:
            out = objective(positions.copy())
        except Exception as exc:  # noqa: BLE001 - the user's code may raise anything
            raise InputError(f"objective: the callable raised {type(exc).__name__}: {exc}") from None
        if not isinstance(out, (tuple, list)) or len(out) != 2:
            raise InputError(f"objective: expected the callable to return (value, d value / d positions), got {describe(out)}")
        value, dx = out
        if isinstance(value, bool) or not isinstance(value, numbers.Real) or not math.isfinite(float(value)):
            raise InputError(f"objective: expected a finite number as the value, got {describe(value)}")
        try:
            arr = np.asarray(dx, dtype=np.float64)
        except (TypeError, ValueError):
            raise InputError(f"objective: expected the derivative as an array of shape {shape}, got {describe(dx)}") from None
        if arr.shape != shape or not np.all(np.isfinite(arr)):
            what = f"shape {arr.shape}" if arr.shape != shape else "non-finite values"
            raise InputError(f"objective: expected the derivative as finite values of shape {shape}, got {what}")
        return float(value), arr

    return checked


def _keyframes_of(body: Body, actuation: Any, cable: int, name: str) -> Keyframes:
    """Cable ``cable``'s schedule entry, which must be a :class:`Keyframes`."""
    entry: Any = None
    if isinstance(actuation, Keyframes) and len(body.cables) == 1:
        entry = actuation
    elif isinstance(actuation, Mapping):
        entry = next((e for k, e in actuation.items() if cable_index(body, k) == cable), None)
    elif isinstance(actuation, Sequence) and not isinstance(actuation, str) and len(actuation) == len(body.cables):
        entry = actuation[cable]
    if not isinstance(entry, Keyframes):
        raise InputError(f"params: {name!r} needs cable {cable}'s schedule to be a sorofem.dynamics.Keyframes "
                         f"(actuation={{{cable}: Keyframes(...)}}), got {describe(entry)}")
    return entry


def _split_names(body: Body, params: str | Sequence[str]) -> tuple[list[str], list[str]]:
    """(names of the static parametrisation, names only a trajectory has), in the given order."""
    if isinstance(params, str):
        params = [params]
    if not isinstance(params, (list, tuple)) or not params:
        raise InputError(f"params: expected a list of parameter names, got {describe(params)}")
    static, dynamic = [], []
    for name in params:
        if not isinstance(name, str):
            raise InputError(f"params: expected parameter names (str), got {name!r}")
        if name in COMMAND_PARAMETERS:
            raise InputError(f"params: {name!r} is a command, which a trajectory schedules: use 'actuation' "
                             "(every step's value) or 'keyframes:<cable>'")
        if name in ("mass_damping", "stiffness_damping", "cable_damping", "actuation") or name.startswith("keyframes:"):
            dynamic.append(name)
        else:
            static.append(name)
    return static, dynamic


def trajectory_gradient(
    body: Body,
    objective: Any,
    params: str | Sequence[str] = ("shear_modulus", "lame_lambda"),
    *,
    dt: float,
    steps: int,
    actuation: Any = None,
    gravity: ArrayLike = (0.0, 0.0, 0.0),
    damping: tuple[float, float] = (0.0, 0.0),
    initial: "ArrayLike | StaticResult | Trajectory | None" = None,
    initial_velocity: ArrayLike | None = None,
    tolerance: float = DEFAULT_TOLERANCE,
    max_iterations: int = 50,
    checkpoint_every: int | None = None,
) -> TrajectoryGradientResult:
    """Value and adjoint gradient of an objective of the trajectory :func:`sorofem.simulate`
    integrates with the same arguments.

    Parameters
    ----------
    body
        The body at the parameter values where the gradient is wanted. Its cables' dashpots
        and its contact (obstacles, self-contact) are differentiated through time, contact
        without friction (an obstacle with ``friction > 0`` is refused): the barrier stiffness
        is taken as fixed at the value each step converged with (IPC balances it at every
        step's start; its change with the parameters is not differentiated, and is none with
        ``body.set_contact(adaptive_stiffness=False)``, which keeps it fixed in the simulation
        too: the gradient is then exact). A step that :func:`sorofem.simulate` splits (where
        Newton fails, or a moving obstacle would run into the body over it) is split alike, and
        differentiated through its halves.
    objective
        A callable ``J(positions (steps + 1, n_nodes, 3)) -> (value, dJ/dpositions (steps + 1,
        n_nodes, 3))`` (frame i at time ``i dt``); a :class:`~sorofem.Target` (``1/2 |r|^2`` at
        the last frame, m^2); or ``[(time, Target), ...]`` (marker tracks: the sum of their
        misfits, each time a multiple of ``dt``).
    params
        Names of :data:`sorofem.inverse.PARAMETERS` (material, ``density``, ``gravity``,
        ``cable_stiffness``) and of :data:`TRAJECTORY_PARAMETERS`: ``"mass_damping"`` (1/s),
        ``"stiffness_damping"`` (s), ``"cable_damping"`` (N s/m, each spring cable's dashpot),
        ``"actuation"`` (every step's command of every cable) and
        ``"keyframes:<cable>"`` (the cable's index; its schedule must be a
        :class:`~sorofem.dynamics.Keyframes`).
    dt, steps, actuation, gravity, damping, initial, initial_velocity, max_iterations
        As for :func:`sorofem.simulate`.
    tolerance
        Newton's relative tolerance of every step, by default :func:`sorofem.simulate`'s (1e-8):
        the forward pass is then the default simulation's, frame for frame. The adjoint is exact
        at converged states; the residual the tolerance leaves perturbs the gradient (by 3e-10
        relative on the hammerbot's swing at 1e-8), so a central-difference check wants a
        tighter one, such as 1e-11. Every step is solved by modified Newton (the factorisation
        kept across steps, as ``method="modified"``).
    checkpoint_every
        Keep every this many states: memory ``steps / k + k + 1`` states besides the positions
        the objective reads; the backward sweep recomputes the states between two kept ones
        (none with ``1``: the fastest, ``steps + 1`` states). Default: ``1`` while the
        ``steps + 1`` states (each the full DOFs and the free DOFs' velocities, float64) fit
        512 MiB, else ``ceil(sqrt(steps))``.

    Returns
    -------
    TrajectoryGradientResult

    Examples
    --------
    >>> tip = body.mesh.nodes_on_plane((0.4, 0, 0), (1, 0, 0))           # doctest: +SKIP
    >>> g = sf.trajectory_gradient(body, [(0.2, sf.Target.nodes(tip, goal))],
    ...                            ["mass_damping", "density"], dt=0.01, steps=20,
    ...                            gravity=(0, 0, -9.81), damping=(2.0, 0.0))  # doctest: +SKIP
    >>> g.gradient["mass_damping"]  # m^2 per 1/s                         # doctest: +SKIP
    """
    if not isinstance(body, Body):
        raise InputError(f"body: expected a sorofem.Body, got {describe(body)}")
    dt = positive_scalar(dt, "dt")
    steps = positive_int(steps, "steps", MAX_TIME_STEPS)
    tol = positive_scalar(tolerance, "tolerance")
    iters = positive_int(max_iterations, "max_iterations", 10_000)
    every = 0 if checkpoint_every is None else positive_int(checkpoint_every, "checkpoint_every", MAX_TIME_STEPS)
    if not isinstance(damping, (tuple, list)) or len(damping) != 2:
        raise ParameterError(f"damping: expected (alpha_M, beta_K), got {describe(damping)}", "damping")
    mass_damping = non_negative(damping[0], "damping[0] (alpha_M)")
    stiffness_damping = non_negative(damping[1], "damping[1] (beta_K)")
    g = as_finite(gravity, "gravity", (3,))
    static_names, dynamic_names = _split_names(body, params)
    p = Parameters(body, static_names) if static_names else None
    theta = p.current(g) if p is not None else np.zeros(0)
    keyframes = {}
    for name in dynamic_names:
        if name.startswith("keyframes:"):
            key = name.partition(":")[2]
            if not key.isdigit() or int(key) >= len(body.cables):
                raise InputError(f"params: {name!r} names no cable of the body: expected 'keyframes:<index>' "
                                 f"with an index below {len(body.cables)}")
            c = int(key)
            keyframes[name] = (c, _keyframes_of(body, actuation, c, name))
    springs = [c for c, (kind, _) in enumerate(body.commands) if kind == "actuation"]
    if "cable_damping" in dynamic_names and not springs:
        raise InputError("params: 'cable_damping' needs spring cables (a dashpot is a spring cable's); the body has none")
    _, _, rho = body.material.per_element(body.mesh.n_tets)
    if not np.all(rho > 0):
        raise ParameterError(f"density: dynamics needs a mass, density > 0 in every tet; got {float(rho.min())} kg/m^3", "density")
    n = body.mesh.n_nodes
    v0: Any = None
    if isinstance(initial, Trajectory):
        x0: Any = initial.final_positions
        v0 = initial.velocities
    elif isinstance(initial, StaticResult):
        x0 = initial.positions
    else:
        x0 = initial
    x0 = None if x0 is None else as_finite(x0, "initial", (n, 3))
    if initial_velocity is not None:
        v0 = as_finite(initial_velocity, "initial_velocity", (n, 3))
    alphas = evaluate_schedule(body, actuation, dt, steps)
    check_magnitudes(body, g)
    evaluate = _objective_function(objective, body.mesh, dt, steps)
    values: list[float] = []

    def derivative(positions: NDArray[np.float64]) -> NDArray[np.float64]:
        value, dx = evaluate(positions)
        values.append(value)
        return np.ascontiguousarray(dx, dtype=np.float64).reshape(-1)

    model = body.core_model()
    try:
        out = core().trajectory_gradient(
            model, g, body.forces.copy(), body.prescribed_displacement.copy(), dt, alphas, derivative,
            mass_damping, stiffness_damping, x0, v0, tol, iters, every,
        )
    finally:
        set_cable_values(model, body.commands, body.cable_stiffnesses, body.cable_dampings)
    gradient: dict[str, Any] = {}
    static_grad = p.as_dict(p.pullback(core_sensitivities(out["params"]), theta)) if p is not None else {}
    per_step = np.asarray(out["actuation"], dtype=np.float64).reshape(steps, len(body.cables))
    times = dt * np.arange(1, steps + 1)
    for name in params if not isinstance(params, str) else [params]:
        if name in static_grad:
            gradient[name] = static_grad[name]
        elif name in ("mass_damping", "stiffness_damping"):
            gradient[name] = float(out[name])
        elif name == "cable_damping":
            gradient[name] = np.asarray(out["cable_damping"], dtype=np.float64)[springs]
        elif name == "actuation":
            gradient[name] = per_step.copy()
        else:
            c, frames = keyframes[name]
            # The schedule is linear in the keyframes' values: d a(t) / d v_j is the hat function.
            hats = np.stack([np.interp(times, frames.times, np.eye(frames.values.size)[j])
                             for j in range(frames.values.size)])
            gradient[name] = hats @ per_step[:, c]
    return TrajectoryGradientResult(values[-1], gradient, np.asarray(out["positions"]), np.asarray(out["iterations"]),
                                    int(out["split_steps"]), int(out["balanced_stiffness_steps"]))
