"""Independent NumPy recomputations the physics tests compare the solver with.

Each function rebuilds one quantity from the mesh and the solver's positions alone, without
calling the code under test, so that a test built on it checks the solver rather than repeats it.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

import sorofem as sf


def lumped_weight(mesh: sf.Mesh, density: ArrayLike, gravity: ArrayLike) -> NDArray[np.float64]:
    """``rho_e V_e g / 4`` per tet and node, ``(n_nodes, 3)``, N (``density`` per tet or one value)."""
    rho = np.broadcast_to(np.asarray(density, dtype=np.float64), (mesh.n_tets,))
    forces = np.zeros((mesh.n_nodes, 3))
    for a in range(4):
        np.add.at(forces, mesh.tets[:, a], (rho * mesh.volumes / 4.0)[:, None] * np.asarray(gravity, dtype=np.float64))
    return forces


def barycentric(mesh: sf.Mesh, point: ArrayLike) -> tuple[int, NDArray[np.float64]]:
    """A tet that contains ``point`` (rest configuration) and the point's barycentric weights in it."""
    p = np.asarray(point, dtype=np.float64)
    x = mesh.points[mesh.tets]  # (m, 4, 3)
    edges = np.transpose(x[:, 1:] - x[:, :1], (0, 2, 1))  # columns x_a - x_0, (m, 3, 3)
    local = np.linalg.solve(edges, (p - x[:, 0])[:, :, None])[:, :, 0]
    weights = np.column_stack([1.0 - local.sum(axis=1), local])
    inside = np.flatnonzero(weights.min(axis=1) >= -1e-12)
    if inside.size == 0:
        raise ValueError(f"point {p.tolist()} lies outside the mesh")
    return int(inside[0]), weights[inside[0]]


def material_point_positions(mesh: sf.Mesh, rest_points: ArrayLike, positions: ArrayLike) -> NDArray[np.float64]:
    """Where material points at ``rest_points`` ``(k, 3)`` are when the nodes are at
    ``positions`` ``(n_nodes, 3)``: the linear interpolation inside each point's tet."""
    x = np.asarray(positions, dtype=np.float64)
    out = []
    for p in np.asarray(rest_points, dtype=np.float64).reshape(-1, 3):
        tet, w = barycentric(mesh, p)
        out.append(w @ x[mesh.tets[tet]])
    return np.array(out)
