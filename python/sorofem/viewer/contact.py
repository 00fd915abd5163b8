"""Obstacles and contact in the viewer: the triangles each obstacle is drawn with (a plane as a
finite quad around the body, a sphere as a UV sphere, boxes and triangle surfaces as they are)
and where a moving one is at each frame of a playback, the contact forces as arrows and the side
panel's totals per obstacle.

Plain functions of a body and a result: no viser here, so they are tested without a server.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ..body import Body
from ..obstacles import obstacle_surface
from ..static import StaticResult
from .commands import nice_ceiling
from .style import ARROW_LENGTH, ARROW_THRESHOLD, PLANE_EXTENT

__all__ = ["obstacle_meshes", "obstacle_offsets", "ContactArrows", "contact_arrows", "obstacle_lines"]


def obstacle_meshes(body: Body, moved: bool = True) -> list[tuple[NDArray[np.float64], NDArray[np.int64]]]:
    """Per obstacle of ``body``, the ``(vertices (n, 3) m, triangles (m, 3))`` to draw it with,
    where it is at ``t = 0`` (static solves hold a moving obstacle there; ``moved=False``: where
    it is before its path's translation, for a playback that moves it frame by frame, see
    :func:`obstacle_offsets`). A plane is the quad of half-sizes ``PLANE_EXTENT`` times the
    body's extents around the body's centre, projected on the plane."""
    lo, hi = body.mesh.bounds
    centre, extent = 0.5 * (lo + hi), PLANE_EXTENT * (hi - lo)
    offsets = obstacle_offsets(body, np.zeros(1))[0]
    out = []
    for k, placement in enumerate(body.obstacles):
        vertices, triangles = obstacle_surface(placement.obstacle, extent, centre)
        if moved:
            vertices = vertices + offsets[k]
        out.append((np.asarray(vertices, dtype=np.float64), np.asarray(triangles, dtype=np.int64)))
    return out


def obstacle_offsets(body: Body, times: NDArray[np.float64]) -> NDArray[np.float64]:
    """The translation of each obstacle of ``body`` along its path at each of ``times`` (s),
    ``(len(times), n_obstacles, 3)`` m: its keyframes interpolated linearly and held outside
    them, as the solver moves it; zero for an obstacle that stays put."""
    times = np.asarray(times, dtype=np.float64).reshape(-1)
    out = np.zeros((times.size, len(body.obstacles), 3))
    for k, placement in enumerate(body.obstacles):
        if placement.path is not None:
            out[:, k] = np.stack([np.interp(times, placement.path[:, 0], placement.path[:, c]) for c in (1, 2, 3)],
                                 axis=1)
    return out


class ContactArrows:
    """The contact forces of a result as arrows: each loaded node gets one that ends at the node,
    pointing along the force the obstacle exerts (the obstacle pushes the body), so that it
    stands outside the body.

    Attributes
    ----------
    segments
        ``(k, 2, 3)`` tail and tip of each arrow, m (empty without contact).
    scale
        Arrow length per newton, m/N (0 without contact): the largest nodal force is drawn at
        most ``ARROW_LENGTH`` times the body's size, rounded so that 1 N is a round length.
    nodes
        The nodes with an arrow (their force above ``ARROW_THRESHOLD`` of the largest).
    largest
        The largest nodal contact force, N.
    """

    def __init__(self, segments: NDArray[np.float64], scale: float, nodes: NDArray[np.int64], largest: float) -> None:
        self.segments, self.scale, self.nodes, self.largest = segments, scale, nodes, largest

    @property
    def legend(self) -> str:
        """The scale in words, for the side panel."""
        if not self.nodes.size:
            return "contact forces: none"
        return (f"contact force arrows: 1 N = {self.scale * 1e3:.3g} mm ({self.nodes.size} nodes, largest "
                f"{self.largest:.3g} N)")


def contact_arrows(result: StaticResult, size: float) -> ContactArrows:
    """The arrows of ``result.contact_forces`` for a body of size ``size`` (m, the diagonal of
    its bounding box)."""
    forces = result.contact_forces
    magnitude = np.linalg.norm(forces, axis=1)
    largest = float(magnitude.max(initial=0.0))
    if not largest > 0.0:
        return ContactArrows(np.zeros((0, 2, 3)), 0.0, np.zeros(0, dtype=np.int64), 0.0)
    # A round number of newtons per millimetre, so that the legend reads well.
    scale = 1e-3 / nice_ceiling(largest / (ARROW_LENGTH * size * 1e3))
    nodes = np.flatnonzero(magnitude > ARROW_THRESHOLD * largest)
    tips = result.positions[nodes]
    return ContactArrows(np.stack([tips - scale * forces[nodes], tips], axis=1), scale, nodes, largest)


def obstacle_lines(result: StaticResult) -> list[str]:
    """One line per obstacle for the side panel: what it is, the total force it exerts on the
    body (N, vector and magnitude), its active contacts and the smallest distance to it (mm)."""
    contact = result.contact
    if contact is None:
        return []
    lines = []
    for k, placement in enumerate(result.body.obstacles):
        force = contact.obstacle_forces[k]
        distance = contact.min_distances[k]
        text = (f"obstacle {k} ({placement.obstacle.kind}): force ({force[0]:.3g}, {force[1]:.3g}, {force[2]:.3g}) N, "
                f"|F| = {np.linalg.norm(force):.4g} N, {int(contact.active[k])} contacts")
        text += f", min distance {distance * 1e3:.3g} mm" if math.isfinite(distance) else ", nothing near"
        lines.append(text)
    return lines
