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
GRAVITY = (0.0, 0.0, -9.81)
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


def test_tension_law_in_its_three_regimes():
    """Every node prescribed (x -> x + u(x), u = 0, -1, 1, 8 cm on the planes x = 0, 0.1, 0.2,
    0.3 m), a cable through the planes with a wide transition (w = 0.5 l = 5 cm): its segments
    are stretched by s = -1, 2 and 7 cm, i.e. slack, in the transition and taut. The unilateral
    spring's tension ``k psi'(s)`` is 0, ``k s^2 / (2 w)`` and ``k (s - w / 2)``; the solver's
    tensions and the NumPy ``segment_tensions`` must both give it."""
    mesh = sf.Mesh.box(size=(0.3, 0.1, 0.1), cells=(3, 1, 1))
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=E, poisson_ratio=NU))
    planes, shifts = [0.0, 0.1, 0.2, 0.3], [0.0, -0.01, 0.01, 0.08]
    displacement = np.zeros((mesh.n_nodes, 3))
    displacement[:, 0] = np.interp(mesh.points[:, 0], planes, shifts)
    body.fix(np.arange(mesh.n_nodes), displacement=displacement)
    k, w = 1e3, 0.05
    cable = sf.Cable([[x, 0.05, 0.05] for x in planes], k, 1.0, transition=0.5)
    body.add_cable(cable)
    result = sf.solve_static(body)
    s = np.diff(shifts)
    expected = [0.0, k * s[1] ** 2 / (2 * w), k * (s[2] - w / 2)]
    np.testing.assert_allclose(result.cable_tensions[0], expected, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(sf.cables.segment_tensions(cable, result.cable_points[0]), expected, rtol=1e-12, atol=1e-12)


def test_a_default_cable_is_at_rest_and_undamped():
    """The documented defaults: alpha = 1 (rest), no dashpot, massless free nodes."""
    cable = sf.Cable([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0]], 1e3)
    assert (cable.actuation, cable.damping, cable.free_node_mass) == (1.0, 0.0, 0.0)


def continuation_body() -> tuple[sf.Body, sf.Cable]:
    mesh = sf.Mesh.box(size=(0.4, 0.1, 0.1), cells=(8, 2, 2))
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080))
    body.fix(mesh.nodes_on_plane((0.0, 0.0, 0.0), (1.0, 0.0, 0.0)))
    cable = sf.Cable.line((0.0, 0.01, 0.01), (1.0, 0.0, 0.0), 0.4, 10, stiffness=1e5)
    body.add_cable(cable)
    return body, cable


def test_continuation_halves_failed_steps_and_reaches_the_same_equilibrium():
    """One jump from alpha = 1 to 0.6 with at most 5 Newton iterations per solve fails; the
    continuation halves it until solves converge, then works its way to 0.6. The elastic
    equilibrium does not depend on the path: the default path of small steps gives the same
    positions (1e-8 of the largest displacement)."""
    body, cable = continuation_body()
    path = sf.actuate(body, cable, [0.6], gravity=GRAVITY, max_iterations=5)
    alphas = [r.actuations[0] for r in path]
    assert len(path) > 2 and alphas[-1] == 0.6 and np.all(np.diff([1.0, *alphas]) < 0), alphas
    halvings = np.log2(0.4 / (1.0 - alphas[0]))  # the first alpha is 1 + (0.6 - 1) / 2^k
    assert halvings > 0.5 and abs(halvings - round(halvings)) < 1e-9, alphas
    reference_body, reference_cable = continuation_body()
    reference = sf.actuate(reference_body, reference_cable, 0.6, gravity=GRAVITY, tolerance=1e-10)[-1]
    error = np.abs(path[-1].positions - reference.positions).max()
    assert error < 1e-8 * reference.max_displacement
    # Without a gravity argument the path is solved without gravity, like solve_static's default.
    body, cable = continuation_body()
    pulled = sf.actuate(body, cable, [0.9])[-1]
    np.testing.assert_allclose(pulled.positions, sf.solve_static(body).positions, rtol=0, atol=1e-9)
    # Too few iterations for any step: an error that keeps the body at its last equilibrium.
    body, cable = continuation_body()
    with pytest.raises(sf.ConvergenceError, match="after halving") as info:
        sf.actuate(body, cable, [0.6], gravity=GRAVITY, max_iterations=3)
    assert body.actuations == [1.0]
