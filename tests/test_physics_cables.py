"""The force a cable exerts on the body, against balances and beam theory.

A cable anchored in the world at its first point (the motor) exerts on the body the pull of its
first segment, ``-T_0 e_0`` (``e_0`` the unit vector from the anchor to the first embedded
point): every other segment pulls its two ends together, equal and opposite. The body's
supports must then supply ``T_0 e_0`` and, about any point ``c``, the moment
``(y_0 - c) x T_0 e_0`` of that pull acting along the first segment through the anchor ``y_0``.

An anchored cable parallel to the axis of a cantilever at a distance ``e`` from it bends the
beam with the moment ``M = T e`` wherever its tension ``T`` is uniform: Euler-Bernoulli gives the
curvature ``kappa = T e / (E I)``, exact for the uniform moment away from the ends (Saint-Venant).
"""

from __future__ import annotations

import numpy as np
import pytest

import sorofem as sf
from independent import material_point_positions

E, NU = 1e5, 0.3  # Pa; compressible, so linear tets bend without volumetric locking
SECTION = 0.1  # m, square cross-section side


def anchored_cantilever(length: float, cells: tuple[int, int, int], offset: float, divisions: int) -> tuple[sf.Body, sf.Cable]:
    """A cantilever clamped at x = 0 with a cable from an anchor on the clamp face, parallel to
    the axis at height ``SECTION / 2 + offset``, to the free end."""
    mesh = sf.Mesh.box(size=(length, SECTION, SECTION), cells=cells)
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=E, poisson_ratio=NU))
    body.fix(mesh.nodes_on_plane((0.0, 0.0, 0.0), (1.0, 0.0, 0.0)))
    start = (0.0, SECTION / 2, SECTION / 2 + offset)
    cable = sf.Cable.line(start, (1.0, 0.0, 0.0), length, divisions, stiffness=1e4, actuation=0.999, anchor_first=True)
    body.add_cable(cable)
    return body, cable


def first_segment_pull(result: sf.StaticResult) -> tuple[np.ndarray, np.ndarray]:
    """The anchor ``y_0`` and the force ``T_0 e_0`` the supports must supply."""
    y = result.cable_points[0]
    e0 = (y[1] - y[0]) / np.linalg.norm(y[1] - y[0])
    return y[0], result.cable_tensions[0][0] * e0


@pytest.mark.parametrize("offset", [0.0, 0.03])
def test_supports_carry_the_pull_of_an_anchored_cable(offset):
    body, cable = anchored_cantilever(0.4, (8, 2, 2), offset, 8)
    result = sf.solve_static(body, tolerance=1e-10)
    anchor, pull = first_segment_pull(result)
    assert pull[0] > 0.01  # a real pull, N
    scale = np.linalg.norm(pull)
    np.testing.assert_allclose(result.reactions.sum(axis=0), pull, rtol=0, atol=1e-9 * scale)
    np.testing.assert_allclose(result.anchor_reactions[0], -pull, rtol=0, atol=1e-12 * scale)
    centre = np.array([0.0, SECTION / 2, SECTION / 2])
    moment = np.cross(result.positions[body.fixed_nodes] - centre, result.reactions).sum(axis=0)
    np.testing.assert_allclose(moment, np.cross(anchor - centre, pull), rtol=0, atol=1e-9 * scale * SECTION)


def test_offset_cable_bends_the_beam_as_euler_bernoulli():
    """A 0.6 m cantilever and a cable 3 cm above its axis, pulled by 0.1 %: small strains. The
    curvature between x = 0.15 and 0.3 m (more than a section height from the clamp and ahead of
    the region near the free end where the bonded cable hands its load to the beam), from the
    second difference of the mean deflection of three sections, is compared with
    ``T e / (E I)``, T the mean tension of the segments there (uniform to 0.1 %). Linear tets
    are stiff in bending (about -15 % and -4 % with 4 and 8 cells across): the two meshes'
    ratios, extrapolated as ``O(h^2)``, must be within 1 % of 1."""
    length, offset, sections = 0.6, 0.03, (0.15, 0.225, 0.3)
    ratios = []
    for n in (4, 8):
        body, cable = anchored_cantilever(length, (6 * n, n, n), offset, 24)
        result = sf.solve_static(body, tolerance=1e-10)
        mesh = body.mesh
        w = [result.displacement[mesh.nodes_on_plane((x, 0.0, 0.0), (1.0, 0.0, 0.0)), 2].mean() for x in sections]
        spacing = sections[1] - sections[0]
        curvature = (w[0] - 2 * w[1] + w[2]) / spacing**2
        crossing = slice(int(sections[0] / cable.rest_lengths[0]), int(sections[2] / cable.rest_lengths[0]))
        tension = result.cable_tensions[0][crossing]
        assert np.ptp(tension) < 2e-3 * tension.mean()
        ratios.append(curvature / (tension.mean() * offset / (E * SECTION**4 / 12)))
    extrapolated = ratios[1] + (ratios[1] - ratios[0]) / 3
    assert 0.8 < ratios[0] < ratios[1] < 1.0, ratios  # converging from below
    assert extrapolated == pytest.approx(1.0, abs=0.01), (ratios, extrapolated)


def test_cable_points_move_with_the_material():
    """Every embedded cable point is the deformed position of its material point: the linear
    interpolation of the node positions in its tet, computed here in NumPy."""
    body, cable = anchored_cantilever(0.4, (8, 2, 2), 0.03, 8)
    body.add_cable(sf.Cable([[0.05, 0.02, 0.01], [0.2, 0.07, 0.05], [0.37, 0.03, 0.09]], 1e4, 0.9))
    result = sf.solve_static(body, gravity=(0.0, 0.0, -9.81), tolerance=1e-10)
    assert result.max_displacement > 0.01
    embedded = cable.points[1:]  # the first point is the anchor
    np.testing.assert_allclose(
        result.cable_points[0][1:], material_point_positions(body.mesh, embedded, result.positions), rtol=0, atol=1e-12
    )
    np.testing.assert_allclose(result.cable_points[0][0], cable.points[0], rtol=0, atol=0)
    second = body.cables[1]
    np.testing.assert_allclose(
        result.cable_points[1], material_point_positions(body.mesh, second.points, result.positions), rtol=0, atol=1e-12
    )
