"""The body: a mesh, a material, supports, nodal loads and cables, and the compiled model that
solves it.

Examples
--------
>>> import sorofem as sf
>>> mesh = sf.Mesh.box(size=(1.0, 0.1, 0.1), cells=(8, 2, 2))
>>> body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080))
>>> body.fix(mesh.nodes_in_box(min=(-1e-9, -1, -1), max=(1e-9, 1, 1)))
>>> body.fixed_nodes.size
9
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._extension import core
from ._validate import (
    as_finite, as_index_array, check_memory, choice, describe, positive_scalar, real, vector_per_node,
)
from .cables import Cable, CablePlacement, cable_index, check_actuation, check_pull, check_tension
from .errors import InputError, ParameterError
from .materials import Material
from .mesh import Mesh
from .obstacles import Obstacle

__all__ = [
    "Body", "ObstaclePlacement", "FORMULATIONS", "VOLUMETRIC_MEASURES", "PRESSURE_MASSES", "set_cable_values",
]

#: A lower bound of the bytes a model holds per node (sparse Hessian, its factorisation,
#: per-element data; measured 13-31 kB for the standard and 24 kB and up for the mixed
#: formulation on box meshes of 2.7k to 19k nodes, growing with the fill-in): a body whose
#: model would need more than the machine's memory is refused before it is built.
MODEL_BYTES_PER_NODE = {"standard": 10_000, "mixed": 20_000}

#: Formulations the solver accepts: displacement only, or displacement + nodal pressure.
FORMULATIONS: tuple[str, ...] = ("standard", "mixed")
#: Volumetric measures ``c(J)`` of the energy ``lambda/2 c(J)^2``: ``ln J`` or ``J - 1``.
VOLUMETRIC_MEASURES: tuple[str, ...] = ("log", "linear")
#: Pressure mass matrices of the mixed formulation.
PRESSURE_MASSES: tuple[str, ...] = ("consistent", "lumped")


@dataclass(frozen=True)
class ObstaclePlacement:
    """An obstacle of a body (see :meth:`Body.add_obstacle`): the obstacle, the Coulomb friction
    coefficient between it and the body, and its path (``(k, 4)`` rows ``[t, dx, dy, dz]``: a
    prescribed translation in s and m, piecewise linear, held outside the keyframes; ``None``
    when it stays put)."""

    obstacle: Obstacle
    friction: float = 0.0
    path: NDArray[np.float64] | None = None

    def to_core(self) -> dict[str, Any]:
        """The description the extension takes."""
        return self.obstacle.to_core() | {"friction": self.friction, "path": self.path}

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON types, for ``summary.json``."""
        return {**self.obstacle.to_dict(), "friction": self.friction,
                "path": None if self.path is None else self.path.tolist()}


#: Contact settings :meth:`Body.set_contact` takes, with their units ("" for the switches).
CONTACT_SETTINGS: dict[str, str] = {
    "dhat": "m", "stiffness": "J/m^4", "friction_slip": "m", "friction_velocity": "m/s", "self_contact": "",
    "adaptive_stiffness": "",
}
#: The contact settings that are switches, with their defaults.
CONTACT_SWITCHES: dict[str, bool] = {"self_contact": False, "adaptive_stiffness": True}


class Body:
    """A mesh, a material, boundary conditions, nodal loads, cables and obstacles.

    The material, the formulation and its options may be changed later (``body.formulation =
    "mixed"``): the new value is checked as in the constructor and the next solve uses it.
    :meth:`replace` gives a copy with other values instead.

    Parameters
    ----------
    mesh
        The rest configuration.
    material
        A :class:`~sorofem.NeoHookean`, :class:`~sorofem.MooneyRivlin`, :class:`~sorofem.Yeoh`
        or :class:`~sorofem.Ogden` (scalar or per-element parameters).
    formulation
        ``"standard"``: displacement-only linear tetrahedra; they lock (come out far too
        stiff) as nu -> 0.5. ``"mixed"``: linear displacement plus a continuous linear nodal
        pressure ``p`` (Pa), a perturbed-Lagrangian saddle point that does not lock; the
        volumetric energy ``lambda/2 c(J)^2`` becomes ``p c(J) - p^2 / (2 lambda)``, so
        ``p ~ lambda c(J)`` is positive in tension (the decoupled models: most of
        ``(J - 1)^2 / d1``, see :mod:`sorofem.materials.decoupled`). See :data:`FORMULATIONS`.
    volumetric
        Neo-Hookean only (the decoupled models' volumetric term is in ``J - 1`` by definition):
        ``"log"`` (default): ``c(J) = ln J``; ``"linear"``: ``c(J) = J - 1``, which makes the
        nearly incompressible limit preserve volume (rather than mean ``ln J``) exactly.
        Used by both formulations.
    pressure_mass
        Mixed only (ignored by ``"standard"``): the pressure mass matrix ``M_p`` of the
        compliance ``C = M_p / lambda``, ``"consistent"`` (default, exact P1) or
        ``"lumped"`` (diagonal).

    Raises
    ------
    InputError
        Unknown formulation, volumetric measure or pressure mass.
    ParameterError
        ``formulation="mixed"`` with ``lame_lambda = 0`` (``poisson_ratio = 0``) anywhere:
        the mixed form divides by lambda.

    Examples
    --------
    >>> import sorofem as sf
    >>> mesh = sf.Mesh.box(size=(1.0, 0.1, 0.1), cells=(8, 2, 2))
    >>> body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45))
    >>> body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    >>> body.add_force(mesh.nodes_on_plane((1, 0, 0), (1, 0, 0)), (0, 0, -0.01))
    >>> body.fixed_nodes.size
    9

    Nearly incompressible silicone, without locking:

    >>> silicone = sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.4999, density=1080)
    >>> body = sf.Body(mesh, silicone, formulation="mixed", volumetric="log", pressure_mass="consistent")
    >>> body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    >>> result = sf.solve_static(body, gravity=(0, 0, -9.81))
    >>> result.pressure.shape, abs(result.mean_log_j) < 1e-4
    ((81,), True)
    """

    def __init__(
        self,
        mesh: Mesh,
        material: Material,
        formulation: str = "standard",
        *,
        volumetric: str = "log",
        pressure_mass: str = "consistent",
    ) -> None:
        if not isinstance(mesh, Mesh):
            raise InputError(f"mesh: expected a sorofem.Mesh, got {describe(mesh)}")
        self._mesh = mesh
        self._formulation = choice(formulation, "formulation", FORMULATIONS)
        self._volumetric = choice(volumetric, "volumetric", VOLUMETRIC_MEASURES)
        self._pressure_mass = choice(pressure_mass, "pressure_mass", PRESSURE_MASSES)
        self._material = self._checked_material(material, self._formulation)
        self._fixed = np.zeros(0, dtype=np.int64)
        self._prescribed = np.zeros((0, 3), dtype=np.float64)
        self._forces = np.zeros((mesh.n_nodes, 3), dtype=np.float64)
        self._cables: list[Cable] = []
        # Per cable its command: ("actuation", alpha) for a spring chain, ("pull", m) or
        # ("tension", N) for a tendon; and a spring chain's segment stiffness and dashpot (NaN
        # for a tendon). Each solve hands them to the model, which is not rebuilt for them.
        self._commands: list[tuple[str, float]] = []
        self._stiffnesses: list[float] = []
        self._dampings: list[float] = []
        # The Cable objects' own (stiffness, damping) when last taken: a value changed on the
        # Cable after it was added is taken at the next solve, not ignored (the latest change,
        # on the Cable or through the body's setters, wins).
        self._cable_values_taken: list[tuple[float, float]] = []
        self._obstacles: list[ObstaclePlacement] = []
        self._contact: dict[str, float | bool | None] = dict.fromkeys(CONTACT_SETTINGS) | CONTACT_SWITCHES
        # The activation distance in force (from the core's check of the obstacles).
        self._dhat: float | None = None
        # What the extension's model was last given for contact (set again when it changes): a
        # cell shared with the bodies of replace(), which share the model.
        self._model_contact: list[Any] = [None]
        # The extension's Model and what it was built for: rebuilt when the supports, the cables
        # or the formulation change, since building it analyses the sparsity pattern.
        self._model: Any = None
        self._model_key: tuple[Any, ...] | None = None

    # -- what the body is made of ------------------------------------------------------

    @property
    def mesh(self) -> Mesh:
        """The rest configuration."""
        return self._mesh

    @property
    def material(self) -> Material:
        """The material; assigning another one checks it against the mesh and the formulation."""
        return self._material

    @material.setter
    def material(self, material: Material) -> None:
        self._material = self._checked_material(material, self._formulation)

    @property
    def formulation(self) -> str:
        """``"standard"`` or ``"mixed"``; assigning checks the value (and lambda > 0 for mixed)
        and the next solve rebuilds the model."""
        return self._formulation

    @formulation.setter
    def formulation(self, formulation: str) -> None:
        formulation = choice(formulation, "formulation", FORMULATIONS)
        self._checked_material(self._material, formulation)
        self._formulation = formulation

    @property
    def volumetric(self) -> str:
        """The volumetric measure, ``"log"`` or ``"linear"``; assigning takes effect at the next solve."""
        return self._volumetric

    @volumetric.setter
    def volumetric(self, volumetric: str) -> None:
        self._volumetric = choice(volumetric, "volumetric", VOLUMETRIC_MEASURES)

    @property
    def pressure_mass(self) -> str:
        """The mixed formulation's pressure mass, ``"consistent"`` or ``"lumped"``; assigning
        takes effect at the next solve."""
        return self._pressure_mass

    @pressure_mass.setter
    def pressure_mass(self, pressure_mass: str) -> None:
        self._pressure_mass = choice(pressure_mass, "pressure_mass", PRESSURE_MASSES)

    @property
    def formulation_options(self) -> dict[str, str]:
        """The options that apply to :attr:`formulation`: ``volumetric``, and
        ``pressure_mass`` when mixed."""
        options = {"volumetric": self._volumetric}
        if self._formulation == "mixed":
            options["pressure_mass"] = self._pressure_mass
        return options

    def _checked_material(self, material: Material, formulation: str) -> Material:
        if not isinstance(material, Material):
            raise InputError(
                f"material: expected a sorofem material (NeoHookean, MooneyRivlin, Yeoh, Ogden), got {describe(material)}"
            )
        # Fail now rather than at solve time if per-element arrays do not fit the mesh.
        material.per_element(self._mesh.n_tets)
        material.check_formulation(formulation, self._mesh.n_tets)
        return material

    def replace(
        self,
        *,
        material: Material | None = None,
        formulation: str | None = None,
        volumetric: str | None = None,
        pressure_mass: str | None = None,
    ) -> "Body":
        """A copy with another material or formulation: same mesh, supports, forces, cables,
        actuations and cable stiffnesses (copies: changing them on one body leaves the other
        alone).

        While the copy keeps the formulation, supports and cables it solves with the same
        compiled model as this body (each solve sets its own material and cable values on it),
        warm starts included.

        Raises
        ------
        InputError, ParameterError
            As the constructor, for the new values.

        Examples
        --------
        >>> mixed = body.replace(formulation="mixed")  # doctest: +SKIP
        """
        other = Body(
            self._mesh,
            self._material if material is None else material,
            self._formulation if formulation is None else formulation,
            volumetric=self._volumetric if volumetric is None else volumetric,
            pressure_mass=self._pressure_mass if pressure_mass is None else pressure_mass,
        )
        other._fixed = self._fixed.copy()
        other._prescribed = self._prescribed.copy()
        other._forces = self._forces.copy()
        other._cables = list(self._cables)
        other._commands = list(self._commands)
        other._stiffnesses = list(self._stiffnesses)
        other._dampings = list(self._dampings)
        other._cable_values_taken = list(self._cable_values_taken)
        other._obstacles = list(self._obstacles)
        other._contact = dict(self._contact)
        other._dhat = self._dhat
        other._model, other._model_key = self._model, self._model_key
        other._model_contact = self._model_contact
        return other

    # -- supports and loads -------------------------------------------------------------

    def fix(self, nodes: ArrayLike, displacement: ArrayLike | None = None) -> None:
        """Fix nodes, optionally at a prescribed displacement.

        Repeated calls accumulate; fixing a node again replaces its prescribed displacement.

        Parameters
        ----------
        nodes
            Node indices (1-D integers) or a boolean mask of shape ``(n_nodes,)``.
        displacement
            ``None`` (held in place), one ``(3,)`` vector for all nodes or ``(k, 3)``
            per node, in metres.
        """
        idx = as_index_array(nodes, "nodes", self._mesh.n_nodes)
        if displacement is None:
            disp = np.zeros((idx.size, 3))
        else:
            disp = vector_per_node(displacement, "displacement", idx.size)
        all_idx = np.concatenate([self._fixed, idx])
        all_disp = np.concatenate([self._prescribed, disp])
        # Last occurrence wins: unique() on the reversed arrays returns first hits.
        uniq, first = np.unique(all_idx[::-1], return_index=True)
        self._fixed = uniq
        self._prescribed = all_disp[::-1][first]

    def add_force(self, nodes: ArrayLike, force: ArrayLike) -> None:
        """Add point forces, in newtons per node; repeated calls accumulate.

        Parameters
        ----------
        nodes
            Node indices (1-D integers, repeats add up) or a boolean mask.
        force
            One ``(3,)`` vector applied to every node, or ``(k, 3)`` per node.
        """
        idx = as_index_array(nodes, "nodes", self._mesh.n_nodes)
        f = vector_per_node(force, "force", idx.size)
        np.add.at(self._forces, idx, f)

    @property
    def fixed_nodes(self) -> NDArray[np.int64]:
        """Sorted indices of the fixed nodes, ``(k,)``."""
        return self._fixed.copy()

    @property
    def prescribed_displacement(self) -> NDArray[np.float64]:
        """Prescribed displacement of each fixed node, ``(k, 3)``, aligned with :attr:`fixed_nodes`."""
        return self._prescribed.copy()

    @property
    def forces(self) -> NDArray[np.float64]:
        """Accumulated nodal forces, ``(n_nodes, 3)``, N."""
        return self._forces.copy()

    # -- cables -------------------------------------------------------------------------

    def add_cable(self, cable: Cable) -> int:
        """Add a :class:`sorofem.Cable`; returns its index. The model is rebuilt at the next
        solve (points are located in the mesh then; see :meth:`cable_placements`).

        Examples
        --------
        >>> import sorofem as sf
        >>> mesh = sf.Mesh.box(size=(0.4, 0.1, 0.1), cells=(8, 2, 2))
        >>> body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45))
        >>> body.add_cable(sf.Cable.line((0, 0.05, 0.01), (1, 0, 0), 0.4, 10, stiffness=1e5))
        0
        """
        if not isinstance(cable, Cable):
            raise InputError(f"cable: expected a sorofem.Cable, got {describe(cable)}")
        if any(c is cable for c in self._cables):
            raise InputError("cable: this Cable has already been added to the body")
        self._cables.append(cable)
        self._commands.append(cable.command)
        own = _spring_values(cable)
        self._stiffnesses.append(own[0])
        self._dampings.append(own[1])
        self._cable_values_taken.append(own)
        return len(self._cables) - 1

    def _spring_index(self, cable: Cable | int, what: str) -> int:
        index = cable_index(self, cable)
        if self._cables[index].is_tendon:
            raise InputError(
                f"cable: cable {index} is a tendon, which has no {what}: drive it with body.pull(cable, "
                "displacement=...) or body.pull(cable, tension=...)"
            )
        return index

    def set_actuation(self, cable: Cable | int, alpha: float) -> None:
        """Set the actuation alpha (> 0; 1 = rest length, < 1 = pulled) of a spring cable,
        given as the :class:`sorofem.Cable` or its index. Takes effect at the next solve
        without rebuilding the model. (A tendon is driven by :meth:`pull`.)"""
        index = self._spring_index(cable, "actuation alpha")
        self._commands[index] = ("actuation", check_actuation(alpha, "alpha"))

    def pull(self, cable: Cable | int, displacement: float | None = None, *, tension: float | None = None) -> None:
        """Drive a tendon (a :class:`sorofem.Cable` with ``model="tendon"``, or its index) as a
        motor does: by the pulled length ``displacement`` (m; the tendon is held at
        ``L <= L0 - displacement``, exactly: taut with the tension that takes, or slack;
        negative pays it out) or by its ``tension`` (N, >= 0). Exactly one of the two. Takes
        effect at the next solve without rebuilding the model; a solve warm-started from the
        previous one also starts from its tension.

        Raises
        ------
        InputError
            The cable is a spring chain (use :meth:`set_actuation`), or neither or both
            commands are given.
        ParameterError
            A non-finite pull or one not shorter than the tendon's rest length; a negative
            tension.

        Examples
        --------
        >>> import sorofem as sf
        >>> mesh = sf.Mesh.box(size=(0.4, 0.1, 0.1), cells=(8, 2, 2))
        >>> body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45))
        >>> body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
        >>> tendon = sf.Cable.line((0.01, 0.05, 0.09), (1, 0, 0), 0.38, 8, model="tendon")
        >>> body.add_cable(tendon)
        0
        >>> body.pull(tendon, displacement=0.01)
        >>> result = sf.solve_static(body)
        >>> round(result.cable_pull[0], 9), result.cable_tension[0] > 0
        (0.01, True)
        """
        index = cable_index(self, cable)
        if not self._cables[index].is_tendon:
            raise InputError(
                f"cable: cable {index} is a spring chain: set its actuation alpha with body.set_actuation(); "
                "body.pull() drives tendons (sorofem.Cable(..., model=\"tendon\"))"
            )
        if (displacement is None) == (tension is None):
            raise InputError("pull: expected exactly one of displacement (m) and tension (N)")
        if displacement is not None:
            self._commands[index] = ("pull", check_pull(displacement, "displacement", self._cables[index].length))
        else:
            self._commands[index] = ("tension", check_tension(tension))

    def set_cable_stiffness(self, cable: Cable | int, stiffness: float) -> None:
        """Set the segment stiffness (N/m, > 0) of a spring cable of this body, given as the
        :class:`sorofem.Cable` or its index (the :class:`~sorofem.Cable` object keeps its own
        ``stiffness``). Takes effect at the next solve without rebuilding the model."""
        index = self._spring_index(cable, "stiffness")
        self._take_cable_values()
        self._stiffnesses[index] = positive_scalar(stiffness, "stiffness")

    def set_cable_damping(self, cable: Cable | int, damping: float) -> None:
        """Set the dashpot coefficient (N s/m, >= 0) of a spring cable of this body, given as
        the :class:`sorofem.Cable` or its index: a damping force ``c dL/dt`` along each segment
        in a simulation (statics do not see it). Takes effect at the next solve without
        rebuilding the model; the :class:`~sorofem.Cable` object keeps its own ``damping``."""
        index = self._spring_index(cable, "damping")
        self._take_cable_values()
        self._dampings[index] = real(damping, "damping", minimum=0.0, strict=False)

    def _take_cable_values(self) -> None:
        """Adopt each Cable's own stiffness or damping where it changed since last taken."""
        for i, cable in enumerate(self._cables):
            own, taken = _spring_values(cable), self._cable_values_taken[i]
            if own == taken or cable.is_tendon:
                continue
            if own[0] != taken[0]:
                self._stiffnesses[i] = own[0]
            if own[1] != taken[1]:
                self._dampings[i] = own[1]
            self._cable_values_taken[i] = own

    @property
    def cables(self) -> tuple[Cable, ...]:
        """The cables added to the body, in index order."""
        return tuple(self._cables)

    @property
    def actuations(self) -> list[float]:
        """Current command value of each cable: the actuation alpha of a spring chain, the
        pull (m) or tension (N) of a tendon (:attr:`commands` says which)."""
        return [value for _, value in self._commands]

    @property
    def commands(self) -> list[tuple[str, float]]:
        """Current command of each cable: ``("actuation", alpha)`` for a spring chain,
        ``("pull", m)`` or ``("tension", N)`` for a tendon."""
        return list(self._commands)

    @property
    def cable_stiffnesses(self) -> list[float]:
        """Current segment stiffness of each cable, N/m (see :meth:`set_cable_stiffness`;
        NaN for a tendon)."""
        self._take_cable_values()
        return list(self._stiffnesses)

    @property
    def cable_dampings(self) -> list[float]:
        """Current dashpot coefficient of each cable, N s/m (see :meth:`set_cable_damping`;
        NaN for a tendon)."""
        self._take_cable_values()
        return list(self._dampings)

    def cable_placements(self) -> list[list[CablePlacement]]:
        """Where each cable point ended up: per cable, one :class:`sorofem.cables.CablePlacement`
        per point (``kind`` "embedded", "snapped", "free" or "anchor").

        Raises
        ------
        ParameterError
            A point lies outside the mesh and its cable has ``outside="error"``.
        """
        return [[CablePlacement.from_core(p) for p in cable] for cable in self._built_model().cable_placements()]

    def attached_rest_lengths(self, cable: Cable | int) -> NDArray[np.float64]:
        """Rest length of each segment of a cable as the solver sees it, ``(k - 1,)`` m: measured
        between the material points its points are attached to (a snapped point sits on the mesh)."""
        index = cable_index(self, cable)
        return np.asarray(self._built_model().cable_rest_lengths()[index], dtype=np.float64)

    # -- obstacles ----------------------------------------------------------------------

    def add_obstacle(self, obstacle: Obstacle, friction: float = 0.0, *, path: ArrayLike | None = None) -> int:
        """Add a rigid obstacle the body must not pass through; returns its index.

        Parameters
        ----------
        obstacle
            A :class:`sorofem.Plane`, :class:`sorofem.Sphere`, :class:`sorofem.Box` or
            :meth:`sorofem.Obstacle.mesh`.
        friction
            Coulomb friction coefficient between the obstacle and the body, >= 0 (0:
            frictionless). Static solves lag it at each load step's start and again at the
            equilibrium; dynamics at each time step's start.
        path
            Keyframes ``[[t, dx, dy, dz], ...]`` (s, m) of a prescribed translation followed
            in :func:`sorofem.simulate` (piecewise linear, held before the first and after the
            last); static solves use the translation at ``t = 0``. ``None``: it stays put.

        Raises
        ------
        ParameterError
            The obstacle touches or intersects the body at rest (the message names it, the
            first node or triangle and its distance), ``friction < 0``, bad keyframes.

        Examples
        --------
        >>> import sorofem as sf
        >>> mesh = sf.Mesh.box(size=(0.1, 0.1, 0.1), cells=(2, 2, 2), origin=(0, 0, 1e-4))
        >>> body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080))
        >>> body.add_obstacle(sf.Plane((0, 0, 0), (0, 0, 1)), friction=0.5)
        0
        """
        if not isinstance(obstacle, Obstacle):
            raise InputError(f"obstacle: expected a sorofem obstacle (Plane, Sphere, Box, Obstacle.mesh), "
                             f"got {describe(obstacle)}")
        friction = real(friction, "friction", minimum=0.0, strict=False)
        keyframes = None
        if path is not None:
            keyframes = as_finite(path, "path", (None, 4))
            if len(keyframes) == 0:
                raise ParameterError("path: expected at least one [t, dx, dy, dz] keyframe", "path")
            if np.any(np.diff(keyframes[:, 0]) < 0):
                raise ParameterError(f"path: keyframe times must not decrease, got {keyframes[:, 0].tolist()}", "path")
        placement = ObstaclePlacement(obstacle, friction, keyframes)
        self._check_contact(self._obstacles + [placement], self._contact)
        self._obstacles.append(placement)
        return len(self._obstacles) - 1

    def set_contact(self, **settings: float | bool | None) -> None:
        """Change contact settings, given as keywords (``None`` restores a default); the
        settings not given keep their values.

        Other Parameters
        ----------------
        dhat : float or None
            Activation distance of the barrier, m: the body feels an obstacle closer than
            this and rests a fraction of it away. Default: 1 % of the mean boundary edge.
        stiffness : float or None
            Reference barrier stiffness, J/m^4. Default: fixed at the first solve from the
            material, so that a node pushed with ``mu h^2`` (shear modulus, mean boundary edge)
            rests at ``dhat / 10``.
        friction_slip : float or None
            Static solves: the slip over a load step below which friction sticks (smoothed), m.
            Default ``dhat / 10``.
        friction_velocity : float or None
            Dynamics: the sliding speed below which friction sticks (smoothed), m/s. Default
            1e-3 (IPC's).
        self_contact : bool or None
            Whether the body's boundary surface may touch itself (frictionless; vertex-triangle
            and edge-edge pairs of the surface that share no vertex). Default ``False``. The
            self-contact forces are part of ``result.contact_forces`` (they sum to zero) and
            its active pairs of ``result.active_contacts``.
        adaptive_stiffness : bool or None
            Whether the barrier stiffness adapts as in IPC (balanced against the other forces at
            each time step's start and doubled while gaps keep shrinking, within ``[stiffness,
            100 stiffness]``) or stays at ``stiffness``. Default ``True``. Trajectory
            derivatives (:func:`sorofem.trajectory_gradient`) are exact with both: they follow
            the adaptive stiffness's balance. Without ``stiffness`` the reference is the
            default one, taken from the material at the body's first solve: a constant of the
            body, which the derivatives hold, as the body's later solves do.

        Raises
        ------
        InputError
            An unknown setting.
        ParameterError
            A value that is not finite and > 0, a ``self_contact`` or ``adaptive_stiffness``
            that is not a bool, or a body whose surface touches itself at rest (with
            self-contact).

        Examples
        --------
        >>> import sorofem as sf
        >>> mesh = sf.Mesh.box(size=(0.1, 0.02, 0.02), cells=(5, 1, 1))
        >>> body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=1e5, poisson_ratio=0.45))
        >>> body.set_contact(self_contact=True)
        >>> body.contact_settings["self_contact"]
        True
        """
        merged = dict(self._contact)
        for name, value in settings.items():
            if name not in CONTACT_SETTINGS:
                raise InputError(f"set_contact: unknown setting {name!r}; expected one of {list(CONTACT_SETTINGS)}")
            if name in CONTACT_SWITCHES:
                if value is not None and not isinstance(value, (bool, np.bool_)):
                    raise ParameterError(f"{name}: expected True or False, got {value!r}", name)
                merged[name] = CONTACT_SWITCHES[name] if value is None else bool(value)
            else:
                merged[name] = None if value is None else positive_scalar(value, name)
        self._check_contact(self._obstacles, merged)
        self._contact = merged

    def _check_contact(self, obstacles: list[ObstaclePlacement], settings: dict[str, float | bool | None]) -> None:
        """The core's check of the obstacles (and the surface, with self-contact) against the
        rest mesh; keeps the dhat in force."""
        if not obstacles and not settings["self_contact"]:
            self._dhat = None
            return
        checked = core().check_contact(self._mesh.points, self._mesh.tets, [o.to_core() for o in obstacles],
                                       settings["dhat"], bool(settings["self_contact"]))
        self._dhat = float(checked["dhat"])

    @property
    def obstacles(self) -> tuple[ObstaclePlacement, ...]:
        """The obstacles added to the body, in index order."""
        return tuple(self._obstacles)

    @property
    def contact_settings(self) -> dict[str, float | bool | None]:
        """The contact settings given (``None``: default); see :meth:`set_contact`."""
        return dict(self._contact)

    @property
    def dhat(self) -> float | None:
        """The barrier's activation distance in force, m (``None`` without obstacles)."""
        return self._dhat

    # -- the compiled model ---------------------------------------------------------------

    def core_model(self) -> Any:
        """The extension's ``Model`` of this body, holding its material, cable actuations and
        cable stiffnesses, ready to solve.

        Internal interface of :func:`sorofem.solve_static`, :func:`sorofem.simulate` and the
        inverse problems (which then set their own values on it); not for user code. The model
        is built on first use and again when the supports, the cables or the formulation
        change: building it analyses the sparsity pattern, which is worth reusing across
        solves.
        """
        model = self._built_model()
        model.set_material_model(*self._material.core_material(self._mesh.n_tets))
        contact = (tuple(id(o) for o in self._obstacles), tuple(self._contact.items()))
        if self._model_contact[0] != contact:
            model.set_contact([o.to_core() for o in self._obstacles], **self._contact)
            self._model_contact[0] = contact
        self._take_cable_values()
        set_cable_values(model, self._commands, self._stiffnesses, self._dampings)
        return model

    #: Old private name of :meth:`core_model` (the benchmarks call it).
    _core_model = core_model

    def _built_model(self) -> Any:
        key = (self._fixed.tobytes(), tuple(_cable_definition(c) for c in self._cables), self._formulation,
               tuple(self.formulation_options.items()))
        if self._model is None or self._model_key != key:
            per_node = MODEL_BYTES_PER_NODE.get(self._formulation, max(MODEL_BYTES_PER_NODE.values()))
            check_memory(per_node * self._mesh.n_nodes,
                         f"the {self._formulation} model of a mesh of {self._mesh.n_nodes} nodes", "mesh")
            cables = [c.to_core() for c in self._cables]
            self._model = core().Model(
                self._mesh.points, self._mesh.tets, self._fixed.copy(), self._formulation, self.formulation_options,
                cables=cables or None,
            )
            self._model_key = key
            self._model_contact = [None]
        return self._model

    def __getstate__(self) -> dict[str, Any]:
        # The compiled model does not pickle; a body sent to another process (a Dask worker)
        # travels without it and builds its own on first use. The barrier stiffness its model
        # fixed at its first solve travels as a setting: the copy must solve as the original
        # does, not fix its own from whatever material it first solves with.
        state = {**self.__dict__, "_model": None, "_model_key": None}
        if self._model is not None and self._contact["stiffness"] is None:
            fixed = (self._model.contact_settings() or {}).get("stiffness")
            if fixed is not None:
                state["_contact"] = {**self._contact, "stiffness": float(fixed)}
        return state

    def __repr__(self) -> str:
        options = "".join(f", {k}={v!r}" for k, v in self.formulation_options.items())
        return (
            f"Body({self._mesh!r}, {self._material!r}, formulation={self._formulation!r}{options}, "
            f"fixed={self._fixed.size} nodes)"
        )


def _cable_definition(cable: Cable) -> tuple[Any, ...]:
    """What the compiled model holds of ``cable`` (its points and routing, not the command,
    stiffness or dashpot a solve sets): a cable changed after a solve rebuilds the model
    instead of solving with the old one."""
    settings = cable.to_core()
    points = settings.pop("points")
    for per_solve in ("actuation", "stiffness", "damping", "pull", "tension"):
        settings.pop(per_solve, None)
    return (np.asarray(points).tobytes(), *sorted(settings.items()))


def _spring_values(cable: Cable) -> tuple[float, float]:
    """A spring cable's own (stiffness N/m, damping N s/m); NaN for a tendon."""
    if cable.is_tendon:
        return math.nan, math.nan
    return float(cable.stiffness), float(cable.damping)  # type: ignore[arg-type]


def set_cable_values(model: Any, commands: Sequence[tuple[str, float]], stiffnesses: Sequence[float],
                     dampings: Sequence[float] | None = None) -> None:
    """Give the extension's ``model`` each cable's command (``("actuation", alpha)``,
    ``("pull", m)`` or ``("tension", N)``, as :attr:`Body.commands`) and each spring chain's
    stiffness (N/m) and, when given, dashpot (N s/m). Internal interface of :class:`Body` and
    the inverse problems."""
    for c, ((kind, value), stiffness) in enumerate(zip(commands, stiffnesses)):
        if kind == "actuation":
            model.set_actuation(c, float(value))
            model.set_cable_stiffness(c, float(stiffness))
            if dampings is not None:
                model.set_cable_damping(c, float(dampings[c]))
        else:
            model.set_tendon_command(c, kind, float(value))
