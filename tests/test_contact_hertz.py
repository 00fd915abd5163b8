"""Hertz contact (issue 17, Verification): an elastic block pressed against a rigid sphere.

A block 16 x 16 x 8 mm (E = 100 kPa, nu = 0.3, standard linear tetrahedra, frictionless), its
base fixed and lifted by a prescribed displacement, is pressed up against a fixed
``sf.Sphere`` of radius R = 10 mm (``dhat`` = 1 um). Under a small load (contact radius
a = 0.6-0.8 mm, a / R < 0.1, a / 8 mm < 0.1) it behaves as an elastic half-space indented by a
rigid sphere, for which Hertz gives ``F = 4/3 E* R^(1/2) d^(3/2)``, ``E* = E / (1 - nu^2)``,
``a = sqrt(R d)``.

The indentation ``d`` is the approach of distant points of the half-space; a finite block with
a fixed base has none, so it is measured locally: the sinking of the contact centre below a
ring of the top surface (radius 1.6-2.2 mm, outside the contact), ``u(ring) - u(0) = d -
w_H(ring; d)``, with ``w_H(r; d)`` Hertz's surface displacement outside the contact (Johnson,
Contact Mechanics, eq. 3.42b), solved for ``d``. The finite block's own compliance varies
little over that ring, so it cancels (rings farther out, where it does not, read 1-2 % more).

The mesh is a structured box graded away from the contact: uniform cells of size ``h`` over
the contact (a uniform facet size keeps the gap that flat facets need around a sphere, h^2 /
8R, the same everywhere in the contact, so it does not distort the indenter), then growing
geometrically to the sides and the base. Linear tetrahedra come out stiff by O(h): the force
exceeds Hertz's by less than 10 % at h = 0.25 mm (the fast test) and by less than 5 % at
h = 0.12 mm (the ``bench`` test, a few minutes).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import brentq

import sorofem as sf

RADIUS = 0.01  # m
YOUNGS_MODULUS, POISSON_RATIO = 100e3, 0.3
HALF_SIZE = 0.008  # m: half-width and depth of the block
FINE_ZONE = 1.08e-3  # m: uniform cells out to this distance from the contact centre
GAP = 2e-5  # m: between the sphere and the block at rest
DHAT = 1e-6  # m
RING = (1.6e-3, 2.2e-3)  # m
E_STAR = YOUNGS_MODULUS / (1.0 - POISSON_RATIO**2)


def half_axis(cell: float, growing: int) -> np.ndarray:
    """Coordinates 0 .. HALF_SIZE: uniform cells of ``cell`` over FINE_ZONE, then ``growing``
    cells growing by a common ratio."""
    fine = cell * np.arange(round(FINE_ZONE / cell) + 1)
    rest = HALF_SIZE - fine[-1]
    ratio = brentq(lambda q: cell * q * (q**growing - 1.0) / (q - 1.0) - rest, 1.0 + 1e-9, 10.0)
    return np.r_[fine, fine[-1] + cell * np.cumsum(ratio ** np.arange(1, growing + 1))]


def graded_block(cell: float, growing: int) -> sf.Mesh:
    """The block [-H, H]^2 x [-H, 0] on the graded grid (top face z = 0)."""
    half = half_axis(cell, growing)
    across = np.r_[-half[::-1], half[1:]]
    down = -half[::-1]
    n = (len(across) - 1, len(across) - 1, len(down) - 1)
    grid = sf.Mesh.box(size=n, cells=n)
    index = np.rint(grid.points).astype(int)
    return sf.Mesh(np.c_[across[index[:, 0]], across[index[:, 1]], down[index[:, 2]]], grid.tets)


def hertz_surface_sinking(r: np.ndarray, d: float) -> np.ndarray:
    """Hertz's downward surface displacement at radii ``r`` >= a (m) for the indentation ``d``."""
    a = np.sqrt(RADIUS * d)
    return d / np.pi * ((2.0 - r**2 / a**2) * np.arcsin(a / r) + r / a * np.sqrt(1.0 - a**2 / r**2))


def hertz_force(d: float) -> float:
    return 4.0 / 3.0 * E_STAR * np.sqrt(RADIUS) * d**1.5


def indent(cell: float, growing: int, lifts: list[float]) -> list[tuple[float, float]]:
    """``(F, d)`` for each base lift (m) in turn: the sphere's force on the block (N) and the
    indentation measured against the ring (m)."""
    mesh = graded_block(cell, growing)
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=YOUNGS_MODULUS, poisson_ratio=POISSON_RATIO))
    base = mesh.nodes_on_plane((0.0, 0.0, -HALF_SIZE), (0.0, 0.0, 1.0), tol=1e-12)
    body.set_contact(dhat=DHAT)
    body.add_obstacle(sf.Sphere((0.0, 0.0, RADIUS + GAP), RADIUS))
    top = np.flatnonzero(np.abs(mesh.points[:, 2]) < 1e-12)
    r = np.hypot(mesh.points[top, 0], mesh.points[top, 1])
    centre = top[np.argmin(r)]
    ring, ring_r = top[(r > RING[0]) & (r < RING[1])], r[(r > RING[0]) & (r < RING[1])]
    out, previous = [], None
    for lift in lifts:
        body.fix(base, displacement=(0.0, 0.0, lift))
        result = sf.solve_static(body, tolerance=1e-10, initial=previous)
        previous = result
        assert result.min_distance is not None and 0.0 < result.min_distance < DHAT
        np.testing.assert_allclose(result.obstacle_forces[0][:2], 0.0, atol=1e-9 * abs(result.obstacle_forces[0][2]))
        sinking = float(result.displacement[ring, 2].mean() - result.displacement[centre, 2])
        d = brentq(lambda d: d - hertz_surface_sinking(ring_r, d).mean() - sinking, 1e-9, RING[0] ** 2 / RADIUS)
        out.append((float(-result.obstacle_forces[0][2]), d))
    return out


def test_the_ring_formula_is_hertz():
    """At the contact edge Hertz's surface has sunk by d / 2; far away as a point load's (1/r)."""
    d = 4e-5
    a = np.sqrt(RADIUS * d)
    assert hertz_surface_sinking(np.array([a]), d)[0] == pytest.approx(d / 2, rel=1e-12)
    far = 1e3 * a
    boussinesq = hertz_force(d) / (np.pi * E_STAR * far)
    assert hertz_surface_sinking(np.array([far]), d)[0] == pytest.approx(boussinesq, rel=1e-5)


def test_a_block_pressed_on_a_sphere_follows_hertz():
    """h = 0.25 mm (about a / 3, 17k tetrahedra): within 10 % of Hertz (linear tetrahedra are
    stiff by O(h))."""
    [(force, d)] = indent(2.5e-4, 5, [GAP + 6e-5])
    # A small load: the contact (radius a) inside the uniform cells, a / R < 0.1.
    assert 0.7e-3 < np.sqrt(RADIUS * d) < 0.9e-3
    assert abs(force / hertz_force(d) - 1.0) < 0.10, (force, hertz_force(d), d)


@pytest.mark.bench
def test_a_block_pressed_on_a_sphere_follows_hertz_within_5_percent():
    """h = 0.12 mm (a / 5 to a / 7, 81k tetrahedra): within 5 % of Hertz at both loads."""
    for force, d in indent(1.2e-4, 6, [GAP + 3e-5, GAP + 6e-5]):
        assert abs(force / hertz_force(d) - 1.0) < 0.05, (force, hertz_force(d), d)
