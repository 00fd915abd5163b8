"""Targets: where parts of a body should be, as a residual of the node positions.

A :class:`Target` says what is observed (chosen nodes, marker points given in the rest
configuration, or a surface) and where it should be. Bound to a mesh
(:meth:`Target.bind`), it becomes a :class:`BoundTarget` with

* ``residual(positions) -> r``, shape ``(3 k,)`` in metres: for each of the ``k``
  observed points, its current position minus its goal, row-major ``(k, 3)`` flattened;
* ``jacobian(positions) -> J``, a ``scipy.sparse`` matrix ``(3 k, 3 n_nodes)``, ``dr/dx``
  with ``x`` the node positions flattened node-major (the barycentric weights of each
  observed point, one block ``w I_3`` per node).

Observed points are linear in the nodes: a point with rest position ``X`` inside tetrahedron
``e`` moves to ``sum_a w_a x_a``, ``w`` its barycentric coordinates in ``e`` at rest
(barycentric embedding). Against a goal point cloud (a surface whose topology differs
from the observed one) each observed point is compared with its nearest goal vertex; that
pairing is piecewise constant in ``x``, so ``J`` is the same weights matrix, exact wherever the
pairing does not switch.

A contact-force target (:meth:`Target.contact_force`) observes instead the total force an
obstacle exerts on the body; bound to the body, it is a :class:`BoundContactForce` with the same
methods, its residual in newtons.

The scalar misfit used by :func:`sorofem.estimate` and :func:`sorofem.control` is
``1/2 |r|^2`` (m^2); :meth:`BoundTarget.rms` is ``sqrt(|r|^2 / k)``, the root-mean-square
distance of the observed points from their goals (m).

Examples
--------
>>> import numpy as np
>>> import sorofem as sf
>>> mesh = sf.Mesh.box(size=(0.4, 0.1, 0.1), cells=(8, 2, 2))
>>> goal = mesh.points[[80]] + [0.0, 0.0, -0.1]
>>> bound = sf.Target.nodes([80], goal).bind(mesh)
>>> bound.residual(mesh.points).round(3).tolist()
[0.0, 0.0, 0.1]
>>> bound.jacobian(mesh.points).shape
(3, 243)
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from ._validate import as_finite, describe, positive_scalar, real
from .body import Body
from .errors import InputError, ShapeError
from .io import Surface, read_surface
from .mesh import Mesh
from .obstacles import Obstacle

__all__ = ["Target", "BoundTarget", "BoundContactForce", "Surface", "read_surface", "embed_points"]

#: Barycentric coordinates down to this (times the element's size) count as inside.
INSIDE_TOLERANCE = 1e-9
#: Candidate tetrahedra (nearest centroids) tried per point before the exhaustive search.
CANDIDATES = 24


# ---------------------------------------------------------------------------
# Surfaces


def _as_surface(value: Any, scale: float, name: str) -> Surface:
    if isinstance(value, Surface):
        return Surface(value.vertices * float(scale), value.faces)
    if isinstance(value, (str, os.PathLike)):
        return read_surface(value, scale)
    if isinstance(value, tuple) and len(value) == 2:
        try:
            v = np.asarray(value[0], dtype=np.float64)
            f = np.asarray(value[1], dtype=np.int64)
        except (TypeError, ValueError, OverflowError):
            raise ShapeError(f"{name}: expected (vertices (v, 3), faces (f, 3)), got {describe(value)}") from None
        if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3:
            raise ShapeError(f"{name}: expected (vertices (v, 3), faces (f, 3)), got shapes {v.shape}, {f.shape}")
        return Surface(v * float(scale), f)
    raise InputError(f"{name}: expected a file path, a Surface or (vertices, faces), got {type(value).__name__}")


# ---------------------------------------------------------------------------
# Barycentric embedding


def embed_points(mesh: Mesh, points: ArrayLike, outside: str = "error") -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Tetrahedron and barycentric weights of each rest point.

    Candidates are the tetrahedra with the nearest centroids (``scipy.spatial.cKDTree``);
    a point that none of them contains is searched among all tetrahedra.

    Parameters
    ----------
    mesh
        A :class:`sorofem.Mesh`.
    points
        Rest positions ``(k, 3)``, m.
    outside
        ``"error"``: a point outside the mesh (beyond a relative tolerance) raises;
        ``"nearest"``: it is attached to the tetrahedron it is least outside of, with its
        weights clamped to >= 0 and renormalised (so it moves with the nearest material).

    Returns
    -------
    tets, weights
        ``(k,)`` int64 and ``(k, 4)`` float64 (rows sum to 1).

    Raises
    ------
    InputError
        A point lies outside the mesh and ``outside="error"``.
    """
    from scipy.spatial import cKDTree

    if not isinstance(outside, str) or outside not in ("error", "nearest"):
        raise InputError(f"outside: expected 'error' or 'nearest', got {outside!r}")
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ShapeError(f"points: expected shape (k, 3), got shape {pts.shape}")
    rest = mesh.points[mesh.tets]  # (m, 4, 3)
    inv = _inverse_shape(rest)  # (m, 3, 3)
    tree = cKDTree(rest.mean(axis=1))
    k = min(CANDIDATES, mesh.n_tets)
    _, cand = tree.query(pts, k=k)
    cand = np.asarray(cand).reshape(len(pts), k)
    # Weights of every point in each of its candidates: (k_points, k, 4).
    w = _weights(inv[cand], rest[cand, 0], pts[:, None, :])
    score = w.min(axis=2)
    best = np.argmax(score, axis=1)
    tets = cand[np.arange(len(pts)), best]
    weights = w[np.arange(len(pts)), best]
    tol = -INSIDE_TOLERANCE
    for i in np.flatnonzero(score[np.arange(len(pts)), best] < tol):
        all_w = _weights(inv, rest[:, 0], pts[i][None, :])
        e = int(np.argmax(all_w.min(axis=1)))
        tets[i], weights[i] = e, all_w[e]
    lost = np.flatnonzero(weights.min(axis=1) < tol)
    if lost.size and outside == "error":
        i = int(lost[0])
        raise InputError(
            f"points: {lost.size} point(s) lie outside the mesh, first: point {i} at {pts[i].tolist()} "
            "(pass outside='nearest' to attach them to the nearest tetrahedron)"
        )
    weights = np.maximum(weights, 0.0)
    weights /= weights.sum(axis=1, keepdims=True)
    return tets.astype(np.int64), weights


def _inverse_shape(rest: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.linalg.inv(np.transpose(rest[:, 1:] - rest[:, :1], (0, 2, 1)))


def _weights(inv: NDArray[np.float64], origin: NDArray[np.float64], p: NDArray[np.float64]) -> NDArray[np.float64]:
    """Barycentric weights ``(..., 4)`` of points ``p`` in tets given by inverse shape
    matrices ``inv`` ``(..., 3, 3)`` and first vertices ``origin`` ``(..., 3)``."""
    lam = np.einsum("...ij,...j->...i", inv, p - origin)
    return np.concatenate([1.0 - lam.sum(axis=-1, keepdims=True), lam], axis=-1)


def _weights_matrix(n_nodes: int, nodes: NDArray[np.int64], weights: NDArray[np.float64]) -> sp.csr_matrix:
    """``(3 k, 3 n)`` sparse map from node positions to ``k`` embedded points: rows ``3 i + c``
    hold ``weights[i, a]`` at column ``3 nodes[i, a] + c``."""
    k, s = nodes.shape
    rows = (3 * np.arange(k)[:, None, None] + np.arange(3)[None, None, :]).repeat(s, axis=1)
    cols = 3 * nodes[:, :, None] + np.arange(3)[None, None, :]
    vals = np.broadcast_to(weights[:, :, None], (k, s, 3))
    return sp.csr_matrix((vals.ravel(), (rows.ravel(), cols.ravel())), shape=(3 * k, 3 * n_nodes))


# ---------------------------------------------------------------------------
# Targets


class BoundTarget:
    """A target bound to a mesh: residual ``W x - goal`` and its Jacobian ``W``.

    Attributes
    ----------
    weights
        ``(3 k, 3 n_nodes)`` sparse matrix mapping node positions (flattened) to the
        observed points (flattened).
    goal
        ``(k, 3)`` goal positions (for a point-cloud target: the goal cloud, ``(g, 3)``).
    mode
        ``"pointwise"`` (each observed point has its own goal) or ``"closest"`` (each
        observed point is compared with its nearest goal vertex).
    rest_points
        ``(k, 3)`` rest positions of the observed points.
    """

    def __init__(
        self,
        weights: sp.csr_matrix,
        goal: NDArray[np.float64],
        rest_points: NDArray[np.float64],
        mode: str = "pointwise",
        description: str = "",
    ) -> None:
        self.weights = weights.tocsr()
        self.goal = np.asarray(goal, dtype=np.float64)
        self.rest_points = rest_points
        self.mode = mode
        self.description = description
        self._tree: Any = None
        if mode == "closest":
            from scipy.spatial import cKDTree

            self._tree = cKDTree(self.goal)

    @property
    def n_points(self) -> int:
        """Number of observed points ``k``."""
        return self.weights.shape[0] // 3

    @property
    def n_residuals(self) -> int:
        """Length of the residual vector, ``3 k``."""
        return int(self.weights.shape[0])

    def points(self, positions: ArrayLike) -> NDArray[np.float64]:
        """Current positions ``(k, 3)`` of the observed points."""
        x = np.asarray(positions, dtype=np.float64).reshape(-1)
        if x.size != self.weights.shape[1]:
            raise ShapeError(f"positions: expected shape ({self.weights.shape[1] // 3}, 3), got {x.size} values")
        return (self.weights @ x).reshape(-1, 3)

    def matched_goal(self, positions: ArrayLike) -> NDArray[np.float64]:
        """The goal of each observed point ``(k, 3)`` (its nearest goal vertex in "closest" mode)."""
        if self.mode == "closest":
            _, idx = self._tree.query(self.points(positions))
            return self.goal[idx]
        return self.goal

    def residual(self, positions: ArrayLike) -> NDArray[np.float64]:
        """``r = observed - goal``, ``(3 k,)`` m."""
        p = self.points(positions)
        return (p - self.matched_goal(positions)).reshape(-1)

    def jacobian(self, positions: ArrayLike | None = None) -> sp.csr_matrix:
        """``dr/dx``, ``(3 k, 3 n_nodes)`` sparse (constant: the barycentric weights)."""
        return self.weights

    def rms(self, positions: ArrayLike) -> float:
        """Root-mean-square distance of the observed points from their goals, m."""
        r = self.residual(positions)
        return float(np.sqrt(r @ r / max(self.n_points, 1)))

    def max_distance(self, positions: ArrayLike) -> float:
        """Largest distance of an observed point from its goal, m."""
        return float(np.linalg.norm(self.residual(positions).reshape(-1, 3), axis=1).max(initial=0.0))

    def misfit(self, positions: ArrayLike) -> tuple[float, NDArray[np.float64]]:
        """``(1/2 |r|^2, d/dx)`` with the gradient shaped ``(n_nodes, 3)``: an objective for
        :func:`sorofem.gradient`."""
        r = self.residual(positions)
        return 0.5 * float(r @ r), (self.weights.T @ r).reshape(-1, 3)

    def __repr__(self) -> str:
        return f"BoundTarget({self.description or self.mode}, points={self.n_points})"


class BoundContactForce:
    """A contact-force target bound to a body: the residual is the total force ``F_k(x)`` that
    obstacle ``k`` exerts on the body (N) minus its goal: ``F_k - goal`` ``(3,)`` for a goal
    vector, ``|F_k| - goal`` ``(1,)`` for a goal magnitude.

    ``F_k`` is evaluated by the body's compiled model at the given positions (the obstacles
    where they are, the barrier stiffness and the friction of its last solve); its Jacobian
    ``dr/dx`` (``(n_residuals, 3 n_nodes)``, N/m) is the derivative of the barrier forces at the
    model's last static solution, so :meth:`jacobian` is valid at the positions just solved for
    (what the inverse functions ask for). It is exact for frictionless contact; friction's
    lagged normal forces and directions count as constants.

    The compiled model does not pickle: a bound target sent to another process (a Dask worker)
    travels as its body, obstacle index and goal, and is bound again to that body there.
    """

    mode = "contact_force"

    def __init__(self, body: Body, obstacle: int, goal: NDArray[np.float64], description: str) -> None:
        self.body = body
        self.model = body.core_model()
        self.obstacle = obstacle
        self.goal = goal
        self.n_nodes = body.mesh.n_nodes
        self.description = description

    def __reduce__(self) -> tuple[Any, ...]:
        return _bind_contact_force, (self.body, self.obstacle, self.goal, self.description)

    @property
    def n_points(self) -> int:
        """One observed quantity, the force."""
        return 1

    @property
    def n_residuals(self) -> int:
        """3 for a goal vector, 1 for a goal magnitude."""
        return int(self.goal.size)

    def force(self, positions: ArrayLike) -> NDArray[np.float64]:
        """The obstacle's total force on the body at ``positions`` ``(n_nodes, 3)``, ``(3,)`` N."""
        x = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
        if x.shape[0] != self.n_nodes:
            raise ShapeError(f"positions: expected shape ({self.n_nodes}, 3), got {x.size} values")
        return np.asarray(self.model.contact_forces(x)["obstacle_forces"][self.obstacle], dtype=np.float64)

    def points(self, positions: ArrayLike) -> NDArray[np.float64]:
        """The force as one row ``(1, 3)``, N (what plots and reports show as the observed value)."""
        return self.force(positions).reshape(1, 3)

    def matched_goal(self, positions: ArrayLike) -> NDArray[np.float64]:
        """The goal as a force ``(1, 3)``, N (a goal magnitude along the current force)."""
        if self.goal.size == 3:
            return self.goal.reshape(1, 3)
        f = self.force(positions)
        norm = float(np.linalg.norm(f))
        return (self.goal[0] * f / norm if norm > 0 else np.zeros(3)).reshape(1, 3)

    def residual(self, positions: ArrayLike) -> NDArray[np.float64]:
        """``F_k - goal`` ``(3,)`` or ``|F_k| - goal`` ``(1,)``, N."""
        f = self.force(positions)
        if self.goal.size == 3:
            return f - self.goal
        return np.array([np.linalg.norm(f) - self.goal[0]])

    def jacobian(self, positions: ArrayLike | None = None) -> sp.csr_matrix:
        """``dr/dx`` ``(n_residuals, 3 n_nodes)``, N/m, at the model's last static solution
        (a magnitude's along the force there; zero without contact)."""
        if self.goal.size == 3:
            weights = list(np.eye(3))
        else:
            f = self.force(positions) if positions is not None else np.zeros(3)
            norm = float(np.linalg.norm(f))
            weights = [f / norm if norm > 0 else np.zeros(3)]
        rows = [np.asarray(self.model.contact_force_gradient(self.obstacle, w), dtype=np.float64).reshape(-1)
                for w in weights]
        return sp.csr_matrix(np.vstack(rows))

    def rms(self, positions: ArrayLike) -> float:
        """``|r|``, N: how far the force is from its goal."""
        r = self.residual(positions)
        return float(np.sqrt(r @ r))

    max_distance = rms

    def misfit(self, positions: ArrayLike) -> tuple[float, NDArray[np.float64]]:
        """``(1/2 |r|^2, d/dx)`` (N^2, N^2/m) with the gradient shaped ``(n_nodes, 3)``, at the
        model's last static solution."""
        r = self.residual(positions)
        return 0.5 * float(r @ r), (self.jacobian(positions).T @ r).reshape(-1, 3)

    def __repr__(self) -> str:
        return f"BoundContactForce({self.description})"


class Target:
    """Where observed parts of a body should be, or what force an obstacle should exert on it.
    Build with :meth:`nodes`, :meth:`points`, :meth:`surface` or :meth:`contact_force`;
    :meth:`bind` it to a mesh (a body, for a contact force) for residuals and Jacobians (the
    inverse functions do this themselves).

    Examples
    --------
    >>> import sorofem as sf
    >>> mesh = sf.Mesh.box(size=(0.4, 0.1, 0.1), cells=(8, 2, 2))
    >>> t = sf.Target.points([[0.4, 0.05, 0.05]], [[0.35, 0.05, -0.15]])
    >>> round(t.bind(mesh).rms(mesh.points), 4)
    0.2062
    """

    def __init__(self, kind: str, **data: Any) -> None:
        self.kind = kind
        self._data = data

    # -- constructors ---------------------------------------------------------------------

    @classmethod
    def nodes(cls, node_ids: ArrayLike, positions: ArrayLike) -> "Target":
        """Goal positions ``(k, 3)`` (m) of mesh nodes ``node_ids`` ``(k,)``."""
        try:
            ids = np.asarray(node_ids)
        except (TypeError, ValueError, OverflowError):
            raise ShapeError(f"node_ids: expected a 1-D integer array, got {describe(node_ids)}") from None
        if ids.ndim != 1 or not np.issubdtype(ids.dtype, np.integer):
            raise ShapeError(f"node_ids: expected a 1-D integer array, got shape {ids.shape} dtype {ids.dtype}")
        pos = _points_array(positions, "positions", len(ids))
        return cls("nodes", node_ids=ids.astype(np.int64), positions=pos)

    @classmethod
    def points(cls, rest_points: ArrayLike, positions: ArrayLike, outside: str = "error") -> "Target":
        """Goal positions ``(k, 3)`` of marker points given at rest ``(k, 3)`` (m), embedded
        barycentrically in the mesh (``outside``: see :func:`embed_points`)."""
        rest = _points_array(rest_points, "rest_points", None)
        pos = _points_array(positions, "positions", len(rest))
        return cls("points", rest_points=rest, positions=pos, outside=outside)

    @classmethod
    def surface(
        cls,
        goal: Any,
        scale: float = 1.0,
        *,
        rest: Any = None,
        rest_scale: float | None = None,
        match: str = "auto",
        outside: str = "nearest",
    ) -> "Target":
        """A goal surface (file path, :class:`Surface` or ``(vertices, faces)``).

        Parameters
        ----------
        goal
            The surface the body should take (e.g. a scan). ``scale`` multiplies its
            coordinates (0.01 for centimetres).
        rest
            The body's own surface at rest (a visual mesh), embedded barycentrically; default:
            the volume mesh's boundary. ``rest_scale`` defaults to ``scale``.
        match
            ``"vertices"``: compare vertex ``i`` with goal vertex ``i`` (needs the same
            topology); ``"closest"``: each rest vertex with its nearest goal vertex;
            ``"auto"`` (default): ``"vertices"`` when the topologies match, else ``"closest"``.
        outside
            What to do with rest vertices outside the volume mesh, see :func:`embed_points`.

        Examples
        --------
        >>> t = sf.Target.surface("hammer_target.obj", scale=0.01, rest="hammerbot_fine.obj")  # doctest: +SKIP
        """
        if not isinstance(match, str) or match not in ("auto", "vertices", "closest"):
            raise InputError(f"match: expected 'auto', 'vertices' or 'closest', got {describe(match)}")
        scale = positive_scalar(scale, "scale")
        rest_scale = None if rest_scale is None else positive_scalar(rest_scale, "rest_scale")
        goal_surface = _as_surface(goal, scale, "goal")
        rest_surface = None if rest is None else _as_surface(rest, scale if rest_scale is None else rest_scale, "rest")
        return cls("surface", goal=goal_surface, rest=rest_surface, match=match, outside=outside)

    @classmethod
    def contact_force(cls, obstacle: Obstacle | int, force: float | ArrayLike) -> "Target":
        """The total force an obstacle exerts on the body, N: a vector ``(3,)``, or a magnitude
        (a number >= 0: ``|F|``, whatever its direction).

        In :func:`sorofem.control` the cables then press the body on the obstacle with that
        force; the residual is in newtons (and ``tolerance`` with it). Its sensitivities are
        exact for frictionless contact.

        Parameters
        ----------
        obstacle
            An obstacle of the body (the :class:`~sorofem.Obstacle` given to
            :meth:`sorofem.Body.add_obstacle`) or its index.
        force
            The goal, N.

        Examples
        --------
        >>> import sorofem as sf
        >>> ball = sf.Sphere(center=(0.2, 0.0, 0.1), radius=0.05)
        >>> sf.Target.contact_force(ball, 0.05)
        Target.contact_force(Sphere(center=[0.2, 0.0, 0.1], radius=0.05), |F| = 0.05 N)
        """
        if not isinstance(obstacle, Obstacle) and (isinstance(obstacle, bool) or not isinstance(obstacle, (int, np.integer))):
            raise InputError(f"obstacle: expected an obstacle of the body or its index, got {describe(obstacle)}")
        if np.ndim(force) == 0:
            goal = np.array([real(force, "force", minimum=0.0, strict=False)])
        else:
            goal = as_finite(force, "force", (3,))
        return cls("contact_force", obstacle=obstacle, force=goal)

    # -- binding --------------------------------------------------------------------------

    def bind(self, mesh: Mesh, body: Body | None = None) -> BoundTarget | BoundContactForce:
        """The target's residual and Jacobian on ``mesh`` (a :class:`sorofem.Mesh`); a contact
        force is bound to ``body`` (a :class:`sorofem.Body` with the obstacle), whose compiled
        model evaluates it.

        Raises
        ------
        InputError
            Node ids out of range, points outside the mesh, ``match="vertices"`` with
            surfaces of different topology, a contact force without a body or with an obstacle
            the body does not have.
        """
        n = mesh.n_nodes
        d = self._data
        if self.kind == "contact_force":
            return self._bind_contact_force(body)
        if self.kind == "nodes":
            ids = d["node_ids"]
            if ids.size and (ids.min() < 0 or ids.max() >= n):
                raise InputError(f"node_ids: node indices must be in [0, {n}), got {int(ids[(ids < 0) | (ids >= n)][0])}")
            w = _weights_matrix(n, ids[:, None], np.ones((len(ids), 1)))
            return BoundTarget(w, d["positions"], mesh.points[ids], "pointwise", f"{len(ids)} nodes")
        if self.kind == "points":
            tets, weights = embed_points(mesh, d["rest_points"], d["outside"])
            w = _weights_matrix(n, mesh.tets[tets], weights)
            return BoundTarget(w, d["positions"], d["rest_points"], "pointwise", f"{len(tets)} points")
        goal: Surface = d["goal"]
        rest: Surface | None = d["rest"]
        if rest is None:
            faces = mesh.boundary_faces()
            used, inverse = np.unique(faces, return_inverse=True)
            rest = Surface(mesh.points[used], inverse.reshape(-1, 3).astype(np.int64))
        mode = d["match"]
        if mode == "auto":
            mode = "vertices" if rest.same_topology(goal) else "closest"
        elif mode == "vertices" and not rest.same_topology(goal):
            raise InputError(
                f"match='vertices': the rest surface ({len(rest.vertices)} vertices, {len(rest.faces)} faces) and the "
                f"goal ({len(goal.vertices)} vertices, {len(goal.faces)} faces) differ in topology; use match='closest'"
            )
        tets, weights = embed_points(mesh, rest.vertices, d["outside"])
        w = _weights_matrix(n, mesh.tets[tets], weights)
        if mode == "vertices":
            return BoundTarget(w, goal.vertices, rest.vertices, "pointwise", f"surface, {len(goal.vertices)} vertices matched")
        return BoundTarget(w, goal.vertices, rest.vertices, "closest", f"surface, {len(rest.vertices)} vertices to closest goal vertex")

    def _bind_contact_force(self, body: Body | None) -> BoundContactForce:
        if not isinstance(body, Body):
            raise InputError(f"body: a contact-force target is bound to the body with the obstacle, got {describe(body)}")
        obstacle = self._data["obstacle"]
        placements = body.obstacles
        if isinstance(obstacle, Obstacle):
            found = [k for k, p in enumerate(placements) if p.obstacle is obstacle]
            if not found:
                raise InputError(f"obstacle: {obstacle!r} is not an obstacle of the body (add it with body.add_obstacle)")
            index = found[0]
        else:
            index = int(obstacle)
            if not 0 <= index < len(placements):
                raise InputError(f"obstacle: expected an index in [0, {len(placements)}) (the body's obstacles), got {index}")
        goal = self._data["force"]
        what = f"|F| = {goal[0]:g} N" if goal.size == 1 else f"F = {goal.tolist()} N"
        return BoundContactForce(body, index, goal, f"obstacle {index}, {what}")

    def __repr__(self) -> str:
        if self.kind == "contact_force":
            goal = self._data["force"]
            what = f"|F| = {goal[0]:g} N" if goal.size == 1 else f"F = {goal.tolist()} N"
            return f"Target.contact_force({self._data['obstacle']!r}, {what})"
        return f"Target.{self.kind}(...)"


def _bind_contact_force(body: Body, obstacle: int, goal: NDArray[np.float64], description: str) -> BoundContactForce:
    """A contact-force target bound again where it is unpickled (see :class:`BoundContactForce`)."""
    return BoundContactForce(body, obstacle, goal, description)


def _points_array(value: ArrayLike, name: str, k: int | None) -> NDArray[np.float64]:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise ShapeError(f"{name}: expected points of shape (k, 3), got {describe(value)}") from None
    if arr.ndim == 1 and arr.size == 3:
        arr = arr.reshape(1, 3)
    if arr.ndim != 2 or arr.shape[1] != 3 or (k is not None and arr.shape[0] != k):
        expected = f"({k if k is not None else 'k'}, 3)"
        raise ShapeError(f"{name}: expected shape {expected}, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{name}: expected finite coordinates")
    return arr
