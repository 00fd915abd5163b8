"""The static solve: :func:`solve_static`, its :class:`StaticResult`, and quasi-static actuation
of cables by continuation (:func:`actuate`).

Examples
--------
>>> import sorofem as sf
>>> mesh = sf.Mesh.box(size=(1.0, 0.1, 0.1), cells=(8, 2, 2))
>>> body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080))
>>> body.fix(mesh.nodes_in_box(min=(-1e-9, -1, -1), max=(1e-9, 1, 1)))
>>> result = sf.solve_static(body, gravity=(0, 0, -9.81))
>>> result.displacement.shape
(81, 3)
>>> result.report.converged
True
"""

from __future__ import annotations

import math
import numbers
from functools import cached_property
from typing import Any, Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._text import plural
from ._validate import MAX_LOAD_STEPS, MAX_MAGNITUDE, as_finite, describe, real
from .body import Body
from .cables import (
    DEFAULT_ALPHA_STEP,
    MAX_HALVINGS,
    Cable,
    cable_index,
    check_actuation,
    check_pull,
    check_tension,
    placement_counts,
)
from .errors import ConvergenceError, InputError, Interrupted, ParameterError, SolverError
from .io import result_mesh
from .progress import Progress
from .solver import SolveOptions, SolveReport

__all__ = ["StaticResult", "ContactState", "solve_static", "actuate", "check_magnitudes", "check_finite_solution"]


def _norm(values: ArrayLike) -> float:
    """The 2-norm without overflow in the squares (a norm above 1.8e308 is still inf)."""
    arr = np.abs(np.asarray(values, dtype=np.float64)).reshape(-1)
    top = float(arr.max(initial=0.0))
    if top == 0.0 or not math.isfinite(top):
        return top
    with np.errstate(over="ignore"):
        return top * float(np.linalg.norm(arr / top))


def check_magnitudes(body: Body, gravity: ArrayLike) -> None:
    """Refuse, before any work, loads and stiffnesses so large that the solver's residual norm
    would overflow float64: the total load (nodal forces and weight, N), each modulus times
    the mesh size (N), each cable stiffness times the mesh size (N) and the stiffness times
    the largest prescribed displacement (N) must each be at most
    :data:`~sorofem._validate.MAX_MAGNITUDE` (1e150).

    Raises
    ------
    ParameterError
        Naming the input (``gravity``, ``forces``, the material parameter, ``stiffness``,
        ``displacement``), its value and the limit.
    """
    mesh = body.mesh
    size = mesh.size
    model = body.material.model
    values = body.material.per_element(mesh.n_tets)
    names = (*model.core_form.names, "density")

    def refuse(name: str, what: str, value: float) -> None:
        raise ParameterError(
            f"{name}: {what} is {value:.3g}, above the limit {MAX_MAGNITUDE:g} (a documented limit: the solver's "
            "residual norm would overflow float64); check the value and its units", name)

    stiffness = 0.0
    for name, value in zip(names[:-1], values[:-1]):
        if model.parameter(name).units == "Pa":
            scale = float(np.max(np.abs(value))) * size
            stiffness = max(stiffness, scale)
            if not scale <= MAX_MAGNITUDE:
                refuse(name, "the modulus times the mesh size (N)", scale)
    # A tendon has no stiffness (its entry is NaN): it is inextensible.
    for k in (k for k, cable in zip(body.cable_stiffnesses, body.cables) if not cable.is_tendon):
        stiffness = max(stiffness, k * size)
        if not k * size <= MAX_MAGNITUDE:
            refuse("stiffness", "a cable's stiffness times the mesh size (N)", k * size)
    weight = float(np.sum(values[-1] * mesh.volumes)) * _norm(gravity)
    if not weight <= MAX_MAGNITUDE:
        refuse("gravity", "the weight of the body (N)", weight)
    forces = _norm(body.forces)
    if not forces <= MAX_MAGNITUDE:
        refuse("forces", "the norm of the nodal forces (N)", forces)
    prescribed = float(np.max(np.abs(body.prescribed_displacement), initial=0.0)) / size * stiffness
    if not prescribed <= MAX_MAGNITUDE:
        refuse("displacement", "the stiffness times the largest prescribed displacement (N)", prescribed)


#: What a solve returns besides its report, each checked for finite values.
_RESULT_KEYS = ("positions", "pressure", "reactions", "cable_points", "cable_tensions", "velocities", "kinetic_energy")


def check_finite_solution(
    out: Mapping[str, Any], report: SolveReport | None, what: str = "the solve", keys: Sequence[str] = _RESULT_KEYS
) -> None:
    """Never a converged result with non-finite numbers: a residual norm that overflowed means
    the input overflows (:class:`InputError`); positions, pressures, reactions or cable values
    that are not finite mean the solve failed (:class:`SolverError`)."""
    history = [] if report is None else report.residual_history
    if report is not None and not (math.isfinite(report.reference_norm) and all(math.isfinite(r) for r in history)):
        raise InputError(
            f"{what}: the residual norm is not finite (reference norm {report.reference_norm:g} N): the loads or "
            "stiffnesses overflow float64; reduce them (see the documented limit on magnitudes)"
        )
    for key in keys:
        value = out.get(key)
        if value is None:
            continue
        arrays = value if isinstance(value, (list, tuple)) else [value]
        for arr in arrays:
            if not _all_finite(arr):
                raise SolverError(f"{what} produced non-finite {key.replace('_', ' ')}; no result is returned")


def _all_finite(value: Any) -> bool:
    try:
        return bool(np.all(np.isfinite(np.asarray(value, dtype=np.float64))))
    except ValueError:  # ragged: a trajectory's frames hold one array per cable, of each cable's length
        return all(_all_finite(v) for v in value)


class ContactState:
    """The contact between a body and its obstacles at a solved state.

    Attributes
    ----------
    forces
        Force the obstacles (and the body's own surface, with self-contact) exert on each node,
        ``(n_nodes, 3)``, N (barrier and friction).
    obstacle_forces
        Total force of each obstacle on the body, ``(n_obstacles, 3)``, N.
    min_distances
        Smallest distance between the body and each obstacle, ``(n_obstacles,)``, m; NaN where
        nothing of the body is near it (farther than a twentieth of the scene's size).
    active
        Number of contact stencils closer than ``dhat`` per obstacle, ``(n_obstacles,)``.
    self_active
        Self-contact stencils closer than ``dhat`` (0 without self-contact).
    self_min_distance
        Smallest distance between surface primitives of the body that share no vertex, m;
        ``None`` without self-contact or when none are near.
    dhat
        The barrier's activation distance, m.
    stiffness
        The barrier stiffness the solve ended with, J/m^4.
    iterate_min_distances
        Minimum distance at every accepted Newton iterate (``inf``: nothing within ``dhat``):
        all > 0, as no accepted iterate touches an obstacle.
    """

    def __init__(self, data: Mapping[str, Any]) -> None:
        self.forces = np.asarray(data["forces"], dtype=np.float64).reshape(-1, 3)
        self.obstacle_forces = np.asarray(data["obstacle_forces"], dtype=np.float64).reshape(-1, 3)
        self.min_distances = np.asarray(data["min_distance"], dtype=np.float64).reshape(-1)
        self.active = np.asarray(data["active"], dtype=np.int64).reshape(-1)
        self.self_active = int(data.get("self_active", 0))
        self_distance = float(data.get("self_min_distance", math.nan))
        self.self_min_distance = self_distance if math.isfinite(self_distance) else None
        self.dhat = float(data.get("dhat", math.nan))
        self.stiffness = float(data.get("stiffness", math.nan))
        self.iterate_min_distances = np.asarray(data.get("iterate_min_distances", []), dtype=np.float64)

    @property
    def min_distance(self) -> float | None:
        """The smallest of :attr:`min_distances` (m), ``None`` when nothing is near."""
        near = self.min_distances[np.isfinite(self.min_distances)]
        return float(near.min()) if near.size else None

    @property
    def active_contacts(self) -> int:
        """Contact stencils closer than ``dhat``, over all obstacles and self-contact."""
        return int(self.active.sum()) + self.self_active

    def to_dict(self, obstacles: Sequence[Any] = ()) -> dict[str, Any]:
        """Plain JSON types for ``summary.json``; ``obstacles`` (the body's placements) add each
        obstacle's description."""
        described = [o.to_dict() for o in obstacles] + [{}] * len(self.obstacle_forces)
        return {
            "dhat": self.dhat,
            "stiffness": self.stiffness,
            "total_force": self.obstacle_forces.sum(axis=0).tolist(),
            "min_distance": self.min_distance,
            "active_contacts": self.active_contacts,
            "self_contact": {"active_contacts": self.self_active, "min_distance": self.self_min_distance},
            "obstacles": [
                {**described[k], "force": self.obstacle_forces[k].tolist(),
                 "min_distance": float(d) if math.isfinite(d) else None, "active_contacts": int(self.active[k])}
                for k, d in enumerate(self.min_distances)
            ],
        }


class StaticResult:
    """Equilibrium of a body, returned by :func:`solve_static`.

    Attributes
    ----------
    mesh
        The body's mesh (rest configuration).
    positions
        Deformed node positions, ``(n_nodes, 3)``, m.
    displacement
        ``positions - mesh.points``, ``(n_nodes, 3)``, m.
    pressure
        Nodal pressure ``(n_nodes,)`` in Pa for mixed formulations, ``None`` for ``"standard"``.
        It is the multiplier of the volume constraint, ``p ~ lambda c(J)``: positive where
        the material is stretched in volume (the mean Cauchy stress is ``p / J``).
        Equal-order P1-P1 is not inf-sup stable: as nu -> 0.5 the nodal pressure can
        oscillate (on coarse meshes even flip sign across a bent beam) while the
        displacement stays accurate; judge pressures on refined meshes.
    report
        The :class:`SolveReport`.

    The element fields :attr:`J` and :attr:`von_mises` are computed when the result is made,
    from the model that just solved: reading them later never touches that model (which may
    have solved for another material meanwhile).

    Volume bookkeeping (both formulations): :attr:`J` per tetrahedron,
    :attr:`deformed_volumes`, :attr:`volume_change` and :attr:`mean_log_j`.
    """

    def __init__(
        self,
        body: Body,
        positions: NDArray[np.float64],
        pressure: NDArray[np.float64] | None,
        report: SolveReport,
        reactions: NDArray[np.float64] | None = None,
        cable_points: Sequence[ArrayLike] | None = None,
        cable_tensions: Sequence[ArrayLike] | None = None,
        element_fields: Mapping[str, ArrayLike] | None = None,
        tendon_tensions: Sequence[float | None] | None = None,
        tendon_pulls: Sequence[float | None] | None = None,
        contact: Mapping[str, Any] | None = None,
    ) -> None:
        self.body = body
        #: The contact with the body's obstacles (:class:`ContactState`), ``None`` without any.
        self.contact = None if contact is None else ContactState(contact)
        #: Current position of every cable point, one ``(k, 3)`` array per cable (m).
        self.cable_points = [np.asarray(p, dtype=np.float64).reshape(-1, 3) for p in cable_points or []]
        #: Tension of every cable segment, one ``(k - 1,)`` array per cable (N, >= 0; a tendon's
        #: segments all carry its one tension).
        self.cable_tensions = [np.asarray(t, dtype=np.float64).reshape(-1) for t in cable_tensions or []]
        #: Per cable, a tendon's tension (N, >= 0; whichever its command) or ``None`` for a spring
        #: chain (whose tension varies along it: :attr:`cable_tensions`).
        self.cable_tension: list[float | None] = [None if t is None else float(t) for t in tendon_tensions or []]
        #: Per cable, the pulled length ``L0 - L`` (m): rest length minus current length along the
        #: points (a tendon's, whichever its command; a spring chain's between its attached points).
        self.cable_pull: list[float] = [
            float(p) if p is not None else float(body.attached_rest_lengths(c).sum() - _polyline_length(points))
            for c, (p, points) in enumerate(zip(tendon_pulls or [None] * len(self.cable_points), self.cable_points))
        ]
        #: The command value of each cable at this solve: alpha, pull (m) or tension (N), as
        #: :attr:`commands` says.
        self.actuations = body.actuations
        #: The command of each cable at this solve (see :attr:`sorofem.Body.commands`).
        self.commands = body.commands
        #: The segment stiffness of each cable at this solve, N/m.
        self.stiffnesses = body.cable_stiffnesses
        #: Support reactions ``(n_fixed, 3)`` in N, one row per entry of ``body.fixed_nodes``:
        #: the force each support exerts on the body (they balance the applied loads).
        self.reactions = None if reactions is None else np.asarray(reactions, dtype=np.float64)
        self.mesh = body.mesh
        self.positions = np.asarray(positions, dtype=np.float64)
        self.displacement = self.positions - self.mesh.points
        self.pressure = None if pressure is None else np.asarray(pressure, dtype=np.float64)
        self.report = report
        #: The body's formulation, its options and its material at this solve (the body may change later).
        self.formulation = body.formulation
        self.formulation_options = body.formulation_options
        self.material = body.material
        if element_fields is None:
            # Only the model that just solved holds this solve's material for sure.
            element_fields = body.core_model().element_fields(self.positions)
        self._fields = {k: np.asarray(v, dtype=np.float64) for k, v in element_fields.items()}

    @property
    def J(self) -> NDArray[np.float64]:  # noqa: N802 - the standard symbol
        """Volume ratio ``det F`` per tetrahedron, ``(n_tets,)``."""
        return self._fields["J"]

    @property
    def von_mises(self) -> NDArray[np.float64]:
        """Von Mises equivalent of the Cauchy stress per tetrahedron, ``(n_tets,)``, Pa."""
        return self._fields["von_mises"]

    @cached_property
    def deformed_volumes(self) -> NDArray[np.float64]:
        """Signed volume of each deformed tetrahedron, ``(n_tets,)``, m^3 (from the positions)."""
        x = self.positions[self.mesh.tets]
        edges = x[:, 1:] - x[:, :1]
        return np.einsum("ij,ij->i", edges[:, 0], np.cross(edges[:, 1], edges[:, 2])) / 6.0

    @property
    def volume_change(self) -> float:
        """Relative change of the total volume, ``(V_deformed - V_rest) / V_rest``."""
        rest = self.mesh.volumes
        return float((self.deformed_volumes - rest).sum() / rest.sum())

    @property
    def mean_log_j(self) -> float:
        """Volume-weighted mean of ``ln J``, ``sum_e V_e ln J_e / V`` (rest volumes): the
        quantity the ``"log"`` volumetric measure keeps near 0 as nu -> 0.5."""
        rest = self.mesh.volumes
        with np.errstate(divide="ignore", invalid="ignore"):
            log_j = np.log(self.deformed_volumes / rest)
        return float((rest * log_j).sum() / rest.sum())

    @property
    def anchor_reactions(self) -> list[NDArray[np.float64] | None]:
        """Per cable, the force ``(3,)`` in N that its world anchor (``anchor_first=True``: the
        motor) exerts on the cable, ``-T_0 (y_1 - y_0) / |y_1 - y_0|`` with ``T_0`` the first
        segment's tension; ``None`` for a cable without an anchor. With the support
        ``reactions`` and the applied loads it closes the body's force balance."""
        out: list[NDArray[np.float64] | None] = []
        for cable, points, tensions in zip(self.body.cables, self.cable_points, self.cable_tensions):
            if not cable.anchor_first:
                out.append(None)
                continue
            direction = points[1] - points[0]
            length = float(np.linalg.norm(direction))
            out.append(-tensions[0] * direction / length if length > 0 else np.zeros(3))
        return out

    @property
    def contact_forces(self) -> NDArray[np.float64]:
        """Force the obstacles exert on each node, ``(n_nodes, 3)``, N (zeros without obstacles)."""
        if self.contact is None:
            return np.zeros((self.mesh.n_nodes, 3))
        return self.contact.forces

    @property
    def obstacle_forces(self) -> NDArray[np.float64]:
        """Total force of each obstacle on the body, ``(n_obstacles, 3)``, N."""
        return np.zeros((0, 3)) if self.contact is None else self.contact.obstacle_forces

    @property
    def min_distance(self) -> float | None:
        """Smallest distance between the body and its obstacles, m (``None``: none near)."""
        return None if self.contact is None else self.contact.min_distance

    @property
    def active_contacts(self) -> int:
        """Contact stencils closer than ``dhat``, over all obstacles and self-contact."""
        return 0 if self.contact is None else self.contact.active_contacts

    @property
    def max_displacement(self) -> float:
        """Largest nodal displacement magnitude, m."""
        return float(np.linalg.norm(self.displacement, axis=1).max(initial=0.0))

    def to_dict(self) -> dict[str, Any]:
        """Summary for ``summary.json``: plain JSON types only."""
        return {
            "converged": self.report.converged,
            "newton_iterations": self.report.iterations,
            "residual_norm": self.report.residual_norm,
            "max_displacement": self.max_displacement,
            "timings": dict(self.report.timings),
            "n_nodes": self.mesh.n_nodes,
            "n_tets": self.mesh.n_tets,
            "formulation": self.formulation,
            "formulation_options": self.formulation_options,
            "material": self.material.to_dict(),
            "min_J": float(self.J.min()),
            "max_J": float(self.J.max()),
            "volume_change": self.volume_change,
            "mean_log_j": self.mean_log_j,
            "min_pressure": None if self.pressure is None else float(self.pressure.min()),
            "max_pressure": None if self.pressure is None else float(self.pressure.max()),
            "max_von_mises": float(self.von_mises.max()),
            **self._cables_dict(),
            **({} if self.contact is None else {"contact": self.contact.to_dict(self.body.obstacles)}),
            "report": self.report.to_dict(),
        }

    def to_meshio(self, points: str = "rest") -> Any:
        """The result as a :class:`meshio.Mesh` (what ``result.vtu`` holds): the rest points
        (``points="deformed"``: the deformed ones), point data ``displacement`` (m) and
        ``pressure`` (Pa, mixed formulation), cell data ``J`` and ``von_mises`` (Pa).

        Examples
        --------
        >>> mesh = result.to_meshio()                                 # doctest: +SKIP
        >>> mesh.write("result.xdmf")                                 # doctest: +SKIP
        """
        return result_mesh(self, points=points)

    def to_pyvista(self, points: str = "rest") -> Any:
        """The result as a :class:`pyvista.UnstructuredGrid` (through :meth:`to_meshio`), for
        plotting in Python; ``grid.warp_by_vector("displacement")`` gives the deformed body.
        PyVista is optional: ``pip install pyvista`` (or the extra: ``pip install ".[pyvista]"``).

        Raises
        ------
        ImportError
            PyVista is not installed (the message says how to install it).

        Examples
        --------
        >>> grid = result.to_pyvista()                                # doctest: +SKIP
        >>> grid.warp_by_vector("displacement").plot(scalars="von_mises")   # doctest: +SKIP
        """
        try:
            import pyvista
        except ModuleNotFoundError as exc:
            if exc.name != "pyvista":
                raise
            raise ImportError("StaticResult.to_pyvista needs PyVista, which is not installed: pip install pyvista "
                              "(or use StaticResult.to_meshio(), which needs nothing more)") from None
        return pyvista.from_meshio(self.to_meshio(points))

    def _cables_dict(self) -> dict[str, Any]:
        """``{"cables": [...]}`` (tensions, actuation, point placements) when the body has cables."""
        if not self.body.cables:
            return {}
        placements = self.body.cable_placements()
        anchors = self.anchor_reactions + [None] * len(self.body.cables)
        return {
            "cables": [
                {
                    "model": cable.model,
                    "command": list(self.commands[c]),
                    "actuation": alpha,
                    "stiffness": None if cable.is_tendon else stiffness,
                    "tension": self.cable_tension[c] if c < len(self.cable_tension) else None,
                    "pull": self.cable_pull[c] if c < len(self.cable_pull) else None,
                    "rest_length": cable.length,
                    "tensions": self.cable_tensions[c].tolist() if c < len(self.cable_tensions) else None,
                    "max_tension": float(self.cable_tensions[c].max()) if c < len(self.cable_tensions) else None,
                    "anchor_reaction": None if anchors[c] is None else anchors[c].tolist(),
                    "placements": [p.kind for p in placements[c]],
                    "placement_counts": placement_counts(placements[c]),
                }
                for c, (cable, alpha, stiffness) in enumerate(zip(self.body.cables, self.actuations, self.stiffnesses))
            ]
        }

    def __repr__(self) -> str:
        return (
            f"StaticResult(converged={self.report.converged}, iterations={self.report.iterations}, "
            f"max_displacement={self.max_displacement:.4g})"
        )


def solve_static(
    body: Body,
    gravity: ArrayLike = (0.0, 0.0, 0.0),
    *,
    tolerance: float = 1e-8,
    max_iterations: int = 50,
    load_steps: int = 1,
    initial: ArrayLike | StaticResult | None = None,
    progress: bool | None = None,
    options: SolveOptions | None = None,
) -> StaticResult:
    """Static equilibrium of a body under gravity, nodal forces and prescribed displacements.

    Newton's method with a line search minimises the total potential energy; loads are
    applied in ``load_steps`` equal increments (the solver may cut a step back).

    Parameters
    ----------
    body
        The body, with its boundary conditions and forces.
    gravity
        Acceleration ``(3,)``, m/s^2.
    tolerance
        Relative residual norm at which Newton stops.
    max_iterations
        Newton iterations allowed per load step.
    load_steps
        Number of load increments.
    options
        The three options above as one :class:`SolveOptions` (what a scene passes); when given,
        it replaces ``tolerance``, ``max_iterations`` and ``load_steps``.
    initial
        Initial guess of the deformed **positions** ``(n_nodes, 3)`` (or a previous
        :class:`StaticResult`); default: the rest shape.
    progress
        A line on stderr with the elapsed time while the solve runs (``None``: only on a
        terminal and only for solves longer than half a second; see :mod:`sorofem.progress`),
        then the iterations and load steps it took.

    Returns
    -------
    StaticResult

    Raises
    ------
    ConvergenceError
        Newton did not converge; ``err.report`` is a :class:`SolveReport`.
    Interrupted
        Ctrl-C during the solve: it stops before its next Newton iteration; ``err.report`` is
        the :class:`SolveReport` of the iterations done (``None`` when the solve had ended).

    Examples
    --------
    >>> import sorofem as sf
    >>> mesh = sf.Mesh.box(size=(1.0, 0.1, 0.1), cells=(8, 2, 2))
    >>> body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080))
    >>> body.fix(mesh.nodes_in_box(min=(-1e-9, -1, -1), max=(1e-9, 1, 1)))
    >>> result = sf.solve_static(body, gravity=(0, 0, -9.81))
    >>> bool(result.displacement[:, 2].min() < 0)
    True
    """
    if not isinstance(body, Body):
        raise InputError(f"body: expected a sorofem.Body, got {describe(body)}")
    g = as_finite(gravity, "gravity", (3,))
    if options is None:
        options = SolveOptions(tolerance, max_iterations, load_steps)
    elif not isinstance(options, SolveOptions):
        raise InputError(f"options: expected a sorofem.solver.SolveOptions, got {describe(options)}")
    n = body.mesh.n_nodes
    if isinstance(initial, StaticResult):
        initial = initial.positions
    x0 = None if initial is None else as_finite(initial, "initial", (n, 3))

    check_magnitudes(body, g)
    model = body.core_model()
    # The core solves in one call (the GIL released): the line can only show the elapsed time.
    with Progress(total=1, desc="static solve", unit="solve", enabled=progress) as bar:
        try:
            out = model.solve(g, body.forces, body.prescribed_displacement, x0, options=options.to_core())
        except ConvergenceError as err:
            if isinstance(err.report, dict):
                err.report = SolveReport.from_dict(err.report, body.formulation)
            raise
        except KeyboardInterrupt as stop:
            raise _interrupted("solve_static", stop, body) from None
        report = SolveReport.from_dict(out, body.formulation)
        check_finite_solution(out, report)
        bar.set(1, postfix=f"{plural(report.iterations, 'Newton iteration')}, {plural(report.load_steps, 'load step')}, "
                           f"{plural(report.cutbacks, 'cutback')}")
    positions = out["positions"]
    fields = model.element_fields(positions)
    check_finite_solution(fields, report, "the solve", keys=tuple(fields))
    return StaticResult(
        body, positions, out.get("pressure"), report, reactions=out.get("reactions"),
        cable_points=out.get("cable_points"), cable_tensions=out.get("cable_tensions"),
        element_fields=fields, tendon_tensions=out.get("tendon_tensions"),
        tendon_pulls=out.get("tendon_pulls"), contact=out.get("contact"),
    )


def _interrupted(function: str, stop: KeyboardInterrupt, body: Body) -> Interrupted:
    """The :class:`Interrupted` of ``function`` stopped by ``stop`` (the extension's, saying how
    far the solve got, or Python's own KeyboardInterrupt), its report a :class:`SolveReport`."""
    message = str(stop) if isinstance(stop, Interrupted) else "interrupted"
    error = Interrupted(f"{function}: {message}", getattr(stop, "result", None), getattr(stop, "signal", "SIGINT"))
    report = getattr(stop, "report", None)
    error.report = SolveReport.from_dict(report, body.formulation) if isinstance(report, dict) else report
    return error


def _polyline_length(points: NDArray[np.float64]) -> float:
    return float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())


def actuate(
    body: Body,
    cable: Cable | int,
    alphas: float | Sequence[float],
    gravity: ArrayLike = (0.0, 0.0, 0.0),
    *,
    max_step: float | None = None,
    initial: ArrayLike | StaticResult | None = None,
    tolerance: float = 1e-8,
    max_iterations: int = 50,
) -> list[StaticResult]:
    """Pull (or release) a cable quasi-statically by continuation in its command: the
    actuation alpha of a spring chain, the pull (m) or tension (N) of a tendon (whichever it
    is driven by, :attr:`Body.commands`).

    Each alpha of the path is solved with :func:`sorofem.solve_static`, warm-started from the
    previous equilibrium. A step that does not converge is halved (up to
    :data:`sorofem.cables.MAX_HALVINGS` times) and the intermediate equilibria are kept in the path.

    Parameters
    ----------
    body
        The body; ``cable`` must have been added to it.
    cable
        A :class:`Cable` of the body or its index.
    alphas
        The path: a sequence of commands (alphas, pulls or tensions) solved in turn, or a
        single target, reached in equal steps of at most ``max_step`` from the cable's current
        command.
    gravity
        ``(3,)``, m/s^2.
    max_step
        Largest increment of a path built from a single target: default 0.05 in alpha, 5 % of
        a tendon's rest length in pull, and the whole way in tension.
    initial
        Starting positions ``(n_nodes, 3)`` or a :class:`StaticResult` for the first solve
        (default: the rest shape).
    tolerance, max_iterations
        Passed to :func:`sorofem.solve_static`.

    Returns
    -------
    list of StaticResult
        One per solved alpha (``result.actuations`` records them), the target last. The
        body's actuation is left at the last alpha.

    Raises
    ------
    ConvergenceError
        A step failed even after halving; ``err.results`` holds the equilibria reached.
    Interrupted
        Ctrl-C during a solve (it stops before its next Newton iteration); ``err.result`` holds
        the equilibria reached, and the body's command is left at the last of them.

    Examples
    --------
    >>> results = sf.actuate(body, cable, 0.5, gravity=(0, 0, -9.81))  # doctest: +SKIP
    >>> results[-1].cable_tensions[0]                                  # doctest: +SKIP
    >>> results = sf.actuate(body, tendon, 0.02)  # pull a tendon 2 cm in 5 % steps  # doctest: +SKIP
    """
    index = cable_index(body, cable)
    kind = body.commands[index][0]
    check = {"actuation": check_actuation, "tension": check_tension,
             "pull": lambda v, name: check_pull(v, name, body.cables[index].length)}[kind]
    if isinstance(alphas, numbers.Real) and not isinstance(alphas, bool):
        target = check(alphas, "alphas")
        start = body.actuations[index]
        if max_step is None:
            default = {"actuation": DEFAULT_ALPHA_STEP, "pull": 0.05 * body.cables[index].length,
                       "tension": math.inf}[kind]
            step = default if math.isfinite(default) else max(abs(target - start), 1.0)
        else:
            step = real(max_step, "max_step", minimum=0.0, strict=True)
        solves = abs(target - start) / step
        if not solves <= MAX_LOAD_STEPS:
            raise ParameterError(f"max_step: reaching {target:g} from {start:g} in steps of {step:g} takes "
                                 f"{solves:.3g} solves, more than the documented limit {MAX_LOAD_STEPS}", "max_step")
        n = max(1, math.ceil(solves - 1e-12))
        path = [start + (target - start) * (i + 1) / n for i in range(n)]
    else:
        try:
            path = [check(a, f"alphas[{i}]") for i, a in enumerate(alphas)]  # type: ignore[union-attr]
        except TypeError:
            raise ParameterError(f"alphas: expected a number or a sequence of numbers, got {describe(alphas)}", "alphas") from None
        if not path:
            raise ParameterError("alphas: expected at least one alpha", "alphas")

    def command(value: float) -> None:
        if kind == "actuation":
            body.set_actuation(index, value)
        elif kind == "pull":
            body.pull(index, displacement=value)
        else:
            body.pull(index, tension=value)

    results: list[StaticResult] = []
    previous: Any = initial.positions if isinstance(initial, StaticResult) else initial
    current = body.actuations[index]
    for target in path:
        halvings = 0
        while True:
            # Retry from the last equilibrium with half the increment until it converges.
            trial = target if halvings == 0 else current + (target - current) / 2**halvings
            command(trial)
            try:
                result = solve_static(
                    body, gravity, tolerance=tolerance, max_iterations=max_iterations, initial=previous
                )
            except ConvergenceError as err:
                halvings += 1
                if halvings > MAX_HALVINGS:
                    command(current)
                    err.results = results  # type: ignore[attr-defined]
                    raise ConvergenceError(
                        f"actuate: no equilibrium at {kind} = {trial:g} after halving the step from "
                        f"{kind} = {current:g} {MAX_HALVINGS} times: {err}",
                        err.report,
                    ) from err
                continue
            except KeyboardInterrupt as stop:
                command(current)
                error = _interrupted("actuate", stop, body)
                reached = plural(len(results), "equilibrium", "equilibria")
                error.args = (f"{error.args[0]} ({kind} = {trial:g}, after {reached} of the path)",)
                error.result = results
                raise error from None
            results.append(result)
            previous, current = result.positions, trial
            if trial == target:
                break
            halvings = max(0, halvings - 1)
    return results
