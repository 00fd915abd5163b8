"""Type stubs of the compiled extension ``sorofem._core`` (crates/sorofem-py).

Internal API: users go through :mod:`sorofem`. Units SI, float64, node-major DOF
ordering, index arrays int64. Errors are the classes of :mod:`sorofem.errors`.
"""

from typing import Any, Callable, NotRequired, TypedDict

import numpy as np
from numpy.typing import NDArray

_F = NDArray[np.float64]
_I = NDArray[np.int64]

class InternalError(Exception):
    """A bug in the core (a panic caught at the boundary); subclass of
    sorofem.errors.SolverError, so a SorofemError and a RuntimeError."""

class _Timings(TypedDict):
    assembly: float
    factorization: float
    solve: float
    line_search: float
    failed_factorization: float  # the part of `factorization` spent in failed ones
    contact: float  # the part of `assembly` and `line_search` spent on contact
    step_bound: float  # the line search's collision detection, part of `line_search`
    total: float

class _Report(TypedDict):
    converged: bool
    iterations: int  # Newton iterations over all load steps
    residual_history: list[float]  # relative residual norms
    energy_history: list[float]  # J
    load_steps: int  # accepted load steps
    cutbacks: int
    projected_steps: int
    factorizations: int  # numeric factorisations, failed ones included
    failed_factorizations: int  # not positive definite, or no descent direction
    single_precision_factorizations: int  # of them, in single precision
    residual_norm: float  # final absolute residual, N
    reference_norm: float  # N
    message: str
    timings: _Timings

class _SolveOutput(_Report):
    positions: _F  # (n, 3)
    pressure: _F | None  # (n,) for mixed formulations, else None
    reactions: _F  # (n_fixed, 3), N
    cable_points: list[_F]  # per cable (k, 3), m
    cable_tensions: list[_F]  # per cable (k - 1,), N
    tendon_tensions: list[float | None]  # per cable: a tendon's tension, N; None for springs
    tendon_pulls: list[float | None]  # per cable: a tendon's pull L0 - L, m; None for springs
    contact: _Contact | None  # with obstacles

class _ContactForces(TypedDict):
    forces: _F  # (n, 3) N, the obstacles' force on each node
    obstacle_forces: _F  # (k, 3) N, per obstacle, on the body
    min_distance: _F  # (k,) m; NaN: nothing within the report radius
    active: _I  # (k,) stencils closer than dhat
    self_active: int  # self-contact stencils closer than dhat
    self_min_distance: float  # m; NaN: no self-contact or nothing within the report radius

class _Contact(_ContactForces):
    stiffness: float  # barrier stiffness in force, J/m^4
    dhat: float  # m
    iterate_min_distances: list[float]  # m, at every accepted Newton iterate

class _ContactSettings(TypedDict):
    dhat: float  # m
    stiffness: float | None  # J/m^4; None before the first solve
    adaptive_stiffness: bool
    n_obstacles: int

class _TrajectoryContact(TypedDict):
    forces: _F  # (frames, n, 3) N
    obstacle_forces: _F  # (frames, k, 3) N
    translations: _F  # (frames, k, 3) m, from each obstacle's place at t = 0
    min_distance: _F  # (frames, k) m
    active: _I  # (frames, k)
    iterate_min_distances: list[float]  # m

class _Cable(TypedDict, total=False):
    points: _F  # (k, 3), m; required
    model: str  # "springs" (default) | "tendon"
    stiffness: float  # N/m per segment; required for springs
    pull: float  # tendon: pulled length, m (default 0 unless tension is given)
    tension: float  # tendon: tension, N >= 0 (not with pull)
    actuation: float  # alpha > 0, default 1
    transition: float  # fraction of the segment rest length, default 1e-3
    anchor_first: bool  # default False
    snap_tolerance: float  # m, default 0
    outside: str  # "error" (default) | "free"
    free_node_mass: float  # kg, default 0
    damping: float  # N s/m per segment (dynamics only), default 0

class _Trajectory(TypedDict):
    times: _F  # (frames,), s
    positions: _F  # (frames, n, 3), m
    velocities: _F  # (n, 3) final, m/s
    cable_points: list[list[_F]]  # per frame, per cable (k, 3)
    tendon_tensions: list[list[float | None]]  # per frame, per cable: tendon tension, N
    tendon_pulls: list[list[float | None]]  # per frame, per cable: tendon pull, m
    kinetic_energy: _F  # (frames,), J
    iterations: list[int]  # Newton iterations per step
    factorizations: list[int]  # numeric factorisations per step
    residuals: list[float]  # relative residual each step ended with
    cutbacks: int
    single_precision_factorizations: int  # of all steps' factorisations
    contact: NotRequired[_TrajectoryContact]  # with obstacles only
    timings: dict[str, float]  # seconds per phase, all steps

class _ParamGradient(TypedDict, total=False):
    material: dict[str, _F]  # per material parameter name (Model.material_param_names), (m,)
    density: _F  # (m,)
    gravity: _F  # (3,)
    cable_actuation: _F  # (n_cables,)
    cable_stiffness: _F  # (n_cables,)
    cable_pull: _F  # (n_cables,): displacement-controlled tendons
    cable_tension: _F  # (n_cables,): force-controlled tendons
    mu: _F  # aliases of the original API: material["mu"] (Neo-Hookean)
    lam: _F  # material["lambda"] (Neo-Hookean)
    rho: _F  # density

class _ElementFields(TypedDict):
    J: _F  # (m,)
    von_mises: _F  # (m,) Cauchy von Mises stress, Pa

def box_mesh(size: _F, cells: _I, origin: _F) -> tuple[_F, _I]:
    """Hex grid split into 6 tets per hex; node (i, j, k) -> i + (nx+1)*(j + (ny+1)*k).

    Returns points (n, 3) and tets (m, 4)."""

def check_mesh(points: _F, tets: _I, orientation: str = "reorient") -> tuple[_I, _I]:
    """Validate a mesh (raises MeshError); orientation "reorient" | "reject".

    Returns the (possibly reoriented) tets (m, 4) and the reoriented tet indices (r,)."""

def rest_volumes(points: _F, tets: _I) -> _F:
    """Rest volume per tet, (m,), m^3."""

def boundary_faces(points: _F, tets: _I) -> _I:
    """Outward-oriented boundary triangles, (k, 3)."""

def check_obstacle(obstacle: dict[str, Any]) -> dict[str, Any]:
    """Check an obstacle description ("kind": "plane" | "sphere" | "box" | "mesh" and its
    geometry, optional "friction" and "path"); {"closed": bool} (+ "vertices" (n, 3),
    "triangles" (m, 3) for boxes and meshes). Raises ParameterError / MeshError."""

def check_contact(
    points: _F, tets: _I, obstacles: list[dict[str, Any]], dhat: float | None = None, self_contact: bool = False
) -> dict[str, Any]:
    """Check obstacles (and the surface against itself, with self_contact) against a body at rest
    (the error names the obstacle, the first node or triangle and its distance) and dhat (> 0);
    {"dhat": the activation distance in force, m}."""

def _contact_reference(x: _F, dhat: float) -> dict[str, Any]:
    """Test hook: distances, mollifier and barrier at four points (4, 3) for the ipctk comparison."""

def material_param_names(model: str, options: dict[str, Any] | None = None) -> list[str]:
    """Parameter names of a material model ("neo_hookean": ["mu", "lambda"]), in the order
    the core stores them. Raises ParameterError for an unknown model or option."""

class _TrajectoryGradient(TypedDict):
    positions: _F
    iterations: list[int]
    balanced_stiffness_steps: int
    split_steps: int
    params: _ParamGradient
    actuation: list[list[float]]
    mass_damping: float
    stiffness_damping: float
    cable_damping: list[float]

def trajectory_gradient(
    model: Model,
    gravity: _F,
    forces: Any,
    prescribed: Any,
    dt: float,
    actuation: _F,
    objective: Callable[[_F], _F],
    mass_damping: float = 0.0,
    stiffness_damping: float = 0.0,
    initial_positions: _F | None = None,
    initial_velocities: _F | None = None,
    tolerance: float | None = None,
    max_iterations: int | None = None,
    checkpoint_every: int = 0,
) -> _TrajectoryGradient:
    """The core's trajectory adjoint; ``objective(positions (steps + 1, n, 3))`` returns the
    flat ``(steps + 1) 3 n`` derivative."""

class _TrajectorySensitivity(TypedDict):
    positions: _F
    iterations: list[int]
    balanced_stiffness_steps: int
    split_steps: int
    dx: _F

def trajectory_sensitivity(
    model: Model,
    gravity: _F,
    forces: Any,
    prescribed: Any,
    dt: float,
    actuation: _F,
    directions: list[dict[str, Any]],
    mass_damping: float = 0.0,
    stiffness_damping: float = 0.0,
    initial_positions: _F | None = None,
    initial_velocities: _F | None = None,
    tolerance: float | None = None,
    max_iterations: int | None = None,
) -> _TrajectorySensitivity:
    """The core's forward trajectory sensitivities: per direction (``Model.forward``'s keys,
    ``"mass_damping"``, ``"stiffness_damping"``, ``"cable_damping"`` (one per cable)) the change of every frame, ``dx`` of shape
    ``(directions, steps + 1, n, 3)``."""

class SolveOptions:
    """Newton settings, validated once (ParameterError naming the bad one).

    load_steps and max_cutbacks apply to static solves; a dynamic step that fails is halved,
    up to six times."""

    def __init__(
        self,
        tolerance: float = 1e-8,
        max_iterations: int = 50,
        load_steps: int = 1,
        max_cutbacks: int = 8,
        pressure_iterates: bool = True,
    ) -> None: ...
    @property
    def tolerance(self) -> float:
        """Relative residual at which Newton stops (> 0)."""
    @property
    def max_iterations(self) -> int:
        """Newton iterations per load step (>= 1)."""
    @property
    def load_steps(self) -> int:
        """Initial number of equal load increments (>= 1)."""
    @property
    def max_cutbacks(self) -> int:
        """How many times in total a load increment may be halved after a failure."""
    @property
    def pressure_iterates(self) -> bool:
        """Standard formulation: Hessians at element pressure iterates (same solution, fewer
        iterations under large rotations)."""
    def to_dict(self) -> dict[str, Any]:
        """The settings as the constructor's keyword arguments."""

class Mesh:
    """A tetrahedral mesh validated once (finite points, indices in range, no degenerate tet;
    inverted tets reoriented or rejected). Models built with Model.from_mesh share it.

    Example: ``m = Mesh.box(np.array([1.0, 0.1, 0.1]), np.array([8, 2, 2]), np.zeros(3));
    m.nodes_on_plane(np.array([1.0, 0, 0]), np.array([1.0, 0, 0])).size == 9``."""

    def __init__(self, points: _F, tets: _I, orientation: str = "reorient") -> None:
        """points (n, 3) m, tets (m, 4); orientation "reorient" | "reject". Raises ShapeError,
        InputError (non-finite, index out of range) or MeshError (degenerate, inverted)."""
    @staticmethod
    def box(size: _F, cells: _I, origin: _F) -> Mesh:
        """Hex grid [origin, origin + size] split into 6 tets per hex (see box_mesh)."""
    @property
    def points(self) -> _F:
        """Rest coordinates (n, 3), m (a copy)."""
    @property
    def tets(self) -> _I:
        """Tetrahedra (m, 4), positively oriented (a copy)."""
    @property
    def volumes(self) -> _F:
        """Rest volume per tet (m,), m^3."""
    @property
    def reoriented(self) -> _I:
        """Indices of the tets that were inverted in the input and reoriented."""
    @property
    def n_nodes(self) -> int: ...
    @property
    def n_tets(self) -> int: ...
    @property
    def diameter(self) -> float:
        """Bounding-box diagonal, m: the scale of relative tolerances."""
    def boundary_faces(self) -> tuple[_I, _I]:
        """Outward-oriented boundary triangles (k, 3), sorted, and the tet owning each (k,)."""
    def nodes_in_box(self, min: _F, max: _F) -> _I:
        """Sorted indices of the nodes in the closed box [min, max] (each (3,), m)."""
    def nodes_on_plane(self, point: _F, normal: _F, tol: float = 1e-9) -> _I:
        """Sorted indices of the nodes within tol * diameter of the plane through point with
        normal (any non-zero length): tol is relative to the mesh size."""
    def locate(self, points: _F, search_radius: float = 0.0) -> tuple[_I, _F, _F]:
        """For points (k, 3): the tet containing each (or the closest within search_radius m;
        -1 when none) (k,), barycentric weights in it (k, 4; NaN when none) and the distance
        to the located point (k,), m (0 inside, inf when none)."""

class Model:
    """Discrete model of one body with a fixed node set; caches the sparsity pattern and
    the symbolic factorisation."""

    def __init__(
        self,
        points: _F,
        tets: _I,
        fixed: _I,
        formulation: str = "standard",
        options: dict[str, Any] | None = None,
        cables: list[_Cable] | None = None,
        terms: dict[str, Any] | None = None,
    ) -> None:
        """formulation "standard" | "mixed"; options: "volumetric" ("log": c = ln J, default |
        "linear": c = J - 1; both formulations), "pressure_mass" ("consistent", default |
        "lumped"; mixed only, ignored otherwise). terms: the inputs of the optional energy
        terms by name: "cables" (the same list as `cables`, not both). The mixed unknowns are the free
        displacements and one pressure per node (Pa), fixed nodes included. The unknowns are
        ordered: 3 n node displacements, then 3 per free cable node, then (mixed) n pressures."""
    @staticmethod
    def from_mesh(
        mesh: Mesh,
        fixed: _I,
        formulation: str = "standard",
        options: dict[str, Any] | None = None,
        cables: list[_Cable] | None = None,
        terms: dict[str, Any] | None = None,
    ) -> Model:
        """A model of a validated Mesh (shared, not copied); arguments as for the constructor."""
    @property
    def mesh(self) -> Mesh:
        """The model's mesh (shared)."""
    @property
    def n_free(self) -> int:
        """Number of free degrees of freedom."""
    def set_material(self, mu: _F, lam: _F, rho: _F) -> None:
        """Neo-Hookean: per-element shear modulus, Lame lambda (Pa) and density (kg/m^3), each
        (m,). Raises ParameterError for mu <= 0, lam < 0 (lam <= 0 when mixed) or rho < 0."""
    def set_material_model(
        self,
        model: str,
        params: dict[str, _F],
        density: _F,
        options: dict[str, Any] | None = None,
    ) -> None:
        """Any material model by name ("neo_hookean", "mooney_rivlin", "yeoh", "ogden"), its
        parameters by name (each (m,), every name of material_param_names(model) exactly once),
        density (m,) kg/m^3 and options ("neo_hookean": "volumetric" "log" | "linear", default
        the constructor's; "ogden": "terms" 1 to 3). Raises ParameterError naming the parameter
        (and the tet) that is out of range."""
    @property
    def material_model(self) -> str:
        """The material model's name."""
    @property
    def material_param_names(self) -> list[str]:
        """The material's parameter names, in storage order (the keys of "material")."""
    def solve(
        self,
        gravity: _F,
        forces: _F,
        prescribed: _F,
        initial: _F | None = None,
        tolerance: float | None = None,
        max_iterations: int | None = None,
        load_steps: int | None = None,
        *,
        options: SolveOptions | None = None,
    ) -> _SolveOutput:
        """Static equilibrium. gravity (3,), forces (n, 3), prescribed (k, 3) aligned with
        `fixed`, initial positions (n, 3) or None. Newton settings: options, or the keyword
        arguments (defaults 1e-8, 50 per load step, 1), not both.
        Raises ConvergenceError whose `.report` is a _Report; Ctrl-C (in the main thread)
        stops it before its next Newton iteration with sorofem.errors.Interrupted, `.report`
        the _Report so far (None if the solve had ended)."""
    def set_contact(
        self,
        obstacles: list[dict[str, Any]],
        dhat: float | None = None,
        stiffness: float | None = None,
        friction_slip: float | None = None,
        friction_velocity: float | None = None,
        self_contact: bool = False,
        adaptive_stiffness: bool = True,
    ) -> None:
        """Set (replace) the obstacles (see check_obstacle) and the contact settings: dhat (m),
        reference barrier stiffness (J/m^4), static friction slip (m), dynamic friction velocity
        (m/s), self-contact of the surface, whether the barrier stiffness adapts (IPC) or stays
        at the reference; None takes the default. An empty list without self-contact removes
        contact."""
    def contact_settings(self) -> _ContactSettings | None: ...
    def contact_forces(self, positions: _F) -> _ContactForces | None:
        """Contact forces at node positions (n, 3); None without obstacles."""
    def contact_force_gradient(self, obstacle: int, weights: _F) -> _F:
        """d(w . F_obstacle)/dx (n, 3) at the last equilibrium."""
    def set_contact_audit(self, on: bool) -> None:
        """Check every accepted Newton iterate for intersections in full (a test diagnostic)."""
    def element_fields(self, positions: _F) -> _ElementFields:
        """Per-element J and von Mises stress at the given positions (n, 3)."""
    def set_actuation(self, cable: int, actuation: float) -> None:
        """Cable `cable`'s alpha (> 0; 1 = rest, < 1 = pulled)."""
    def set_cable_stiffness(self, cable: int, stiffness: float) -> None:
        """Cable `cable`'s segment stiffness, N/m (> 0)."""
    def set_cable_damping(self, cable: int, damping: float) -> None:
        """Spring cable `cable`'s dashpot coefficient, N s/m (>= 0)."""
    def time_factorization(self, repeats: int) -> list[float]:
        """Seconds of each of `repeats` bare numeric factorisations of the Hessian at the last
        equilibrium (the rest state before any solve): a benchmark diagnostic."""
    def adjoint(self, d_objective_d_positions: _F) -> _ParamGradient:
        """Adjoint gradient of a scalar objective of the last equilibrium's positions:
        dO/dx (n, 3) -> dO/dtheta: "material" {name: (m,)}, "density" (m,), "gravity" (3,),
        "cable_actuation", "cable_stiffness" (n_cables,), and the original keys "mu", "lam",
        "rho". Needs a static solve with the current parameters (raises ParameterError
        otherwise)."""
    def forward(self, direction: dict[str, Any]) -> dict[str, Any]:
        """Forward sensitivity along a parameter direction (any of the adjoint's keys, the
        material's also inside "material"; missing ones are zero):
        {"dx": (n, 3) m per unit, "dp": (n,) Pa per unit or None, "dtension": per cable the
        tendon's tension change, N per unit, or None for a spring cable}."""
    def set_tendon_command(self, cable: int, kind: str, value: float) -> None:
        """Tendon `cable`'s command: kind "pull" (m, shorter than its rest length) or
        "tension" (N, >= 0)."""
    def strain_energy(self, positions: _F) -> float:
        """Strain energy (J) of the body at positions (n, 3): the elastic term alone."""
    def cable_rest_lengths(self) -> list[list[float]]: ...
    def cable_placements(self) -> list[list[tuple[str, int, float]]]:
        """Per cable and point: ("embedded", tet, distance m) | ("free", index, 0.0) | ("anchor", -1, 0.0)."""
    def simulate(
        self,
        gravity: _F,
        forces: _F,
        prescribed: _F,
        dt: float,
        steps: int,
        actuation: _F,
        mass_damping: float = 0.0,
        stiffness_damping: float = 0.0,
        initial_positions: _F | None = None,
        initial_velocities: _F | None = None,
        tolerance: float | None = None,
        max_iterations: int | None = None,
        save_every: int = 1,
        *,
        options: SolveOptions | None = None,
        method: str = "modified",
    ) -> _Trajectory:
        """Implicit Euler with lumped mass and Rayleigh damping (alpha_M 1/s, beta_K s);
        actuation (steps, n_cables) per step: alphas (springs), pulls or tensions (tendons);
        Newton settings per step as for solve (load_steps and max_cutbacks do not apply); method
        "modified", "newton" or "linearly_implicit". Raises ConvergenceError when a step fails
        even after halving it six times; Interrupted on Ctrl-C, as solve."""
