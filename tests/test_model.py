"""Mesh, NeoHookean, Body and solve_static: validation and bookkeeping."""

from __future__ import annotations

import numpy as np
import pytest

import sorofem as sf

UNIT_TET_POINTS = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]


@pytest.fixture
def beam() -> sf.Mesh:
    return sf.Mesh.box(size=(1.0, 0.1, 0.1), cells=(8, 2, 2))


@pytest.fixture
def silicone() -> sf.NeoHookean:
    return sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080)


# -- Mesh ---------------------------------------------------------------------------


def test_unit_tet_volume_and_properties():
    mesh = sf.Mesh(UNIT_TET_POINTS, [[0, 1, 2, 3]])
    assert (mesh.n_nodes, mesh.n_tets) == (4, 1)
    assert mesh.points.dtype == np.float64 and mesh.tets.dtype == np.int64
    assert mesh.volumes == pytest.approx([1 / 6])
    assert mesh.reoriented.size == 0
    assert mesh.boundary_faces().shape == (4, 3)
    lo, hi = mesh.bounds
    assert lo.tolist() == [0, 0, 0] and hi.tolist() == [1, 1, 1]
    assert "n_nodes=4" in repr(mesh)


def test_box_counts_and_volume(beam):
    assert (beam.n_nodes, beam.n_tets) == (81, 192)
    assert beam.volumes.sum() == pytest.approx(0.01)
    assert np.all(beam.volumes > 0)
    assert beam.boundary_faces().shape[1] == 3


@pytest.mark.parametrize(
    "points, tets, words",
    [
        (np.zeros((4, 2)), [[0, 1, 2, 3]], ["points", "(n, 3)", "(4, 2)"]),
        (UNIT_TET_POINTS, [[0, 1, 2]], ["tets", "(m, 4)", "(1, 3)"]),
        (UNIT_TET_POINTS, [[0.0, 1.0, 2.0, 3.0]], ["tets", "integer"]),
    ],
)
def test_mesh_shape_errors_name_parameter(points, tets, words):
    with pytest.raises(sf.ShapeError) as info:
        sf.Mesh(points, tets)
    for word in words:
        assert word in str(info.value)


def test_mesh_nan_coordinate():
    points = np.array(UNIT_TET_POINTS)
    points[2, 1] = np.nan
    with pytest.raises(sf.MeshError, match="points"):
        sf.Mesh(points, [[0, 1, 2, 3]])


@pytest.mark.parametrize("bad", [4, -1])
def test_mesh_index_out_of_range(bad):
    with pytest.raises(sf.MeshError, match="tets"):
        sf.Mesh(UNIT_TET_POINTS, [[0, 1, 2, bad]])


def test_degenerate_tet_is_mesh_error():
    flat = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]]
    with pytest.raises(sf.MeshError):
        sf.Mesh(flat, [[0, 1, 2, 3]])


def test_mesh_errors_are_value_errors():
    with pytest.raises(ValueError):
        sf.Mesh(UNIT_TET_POINTS, [[0, 1, 2, 7]])


def test_inverted_tet_reoriented_and_reported():
    tets = [[0, 1, 2, 3], [0, 2, 1, 3]]  # the second one is inverted
    points = UNIT_TET_POINTS
    mesh = sf.Mesh(points, tets)
    assert mesh.reoriented.tolist() == [1]
    assert np.all(mesh.volumes > 0)
    assert sorted(mesh.tets[1].tolist()) == [0, 1, 2, 3]
    assert "reoriented=1" in repr(mesh)
    with pytest.raises(sf.MeshError):
        sf.Mesh(points, tets, orientation="reject")


def test_mesh_arrays_are_read_only(beam):
    with pytest.raises(ValueError):
        beam.points[0, 0] = 1.0


def test_nodes_in_box_selects_clamped_face(beam):
    nodes = beam.nodes_in_box(min=(-1e-9, -1, -1), max=(1e-9, 1, 1))
    assert nodes.dtype == np.int64
    assert nodes.size == 9
    assert np.all(np.diff(nodes) > 0)
    assert np.all(beam.points[nodes, 0] == 0.0)


def test_nodes_on_plane_and_where(beam):
    tip = beam.nodes_on_plane(point=(1.0, 0, 0), normal=(2.0, 0, 0))
    assert tip.size == 9 and np.all(beam.points[tip, 0] == pytest.approx(1.0))
    mid = beam.nodes_where(lambda p: np.isclose(p[:, 0], 0.5))
    assert mid.size == 9
    with pytest.raises(sf.ShapeError, match="predicate"):
        beam.nodes_where(lambda p: p[:, 0])
    with pytest.raises(sf.InputError, match="normal"):
        beam.nodes_on_plane((0, 0, 0), (0, 0, 0))


def test_nodes_in_box_rejects_swapped_bounds(beam):
    with pytest.raises(sf.InputError, match="min"):
        beam.nodes_in_box(min=(1, 1, 1), max=(0, 0, 0))


def test_scaled(beam):
    small = beam.scaled(1e-3)
    assert small.bounds[1] == pytest.approx([1e-3, 1e-4, 1e-4])
    assert small.volumes.sum() == pytest.approx(1e-11)
    with pytest.raises(sf.ParameterError, match="factor"):
        beam.scaled(-1.0)


def test_box_validation():
    with pytest.raises(sf.ParameterError, match="cells"):
        sf.Mesh.box(size=(1, 1, 1), cells=(0, 1, 1))
    with pytest.raises(sf.ParameterError, match="size"):
        sf.Mesh.box(size=(1, -1, 1), cells=(1, 1, 1))


# -- NeoHookean ------------------------------------------------------------------------


def test_neo_hookean_conversions():
    E, nu = 66e3, 0.45
    m = sf.NeoHookean(youngs_modulus=E, poisson_ratio=nu, density=1080)
    assert m.shear_modulus == pytest.approx(E / (2 * (1 + nu)))
    assert m.lame_lambda == pytest.approx(E * nu / ((1 + nu) * (1 - 2 * nu)))
    back = sf.NeoHookean(shear_modulus=m.shear_modulus, lame_lambda=m.lame_lambda)
    assert back.youngs_modulus == pytest.approx(E)
    assert back.poisson_ratio == pytest.approx(nu)
    assert back.density == 0.0
    mu, lam, rho = m.per_element(5)
    assert mu.shape == lam.shape == rho.shape == (5,)
    assert np.all(rho == 1080)


def test_neo_hookean_per_element():
    E = np.array([1e4, 2e4, 3e4])
    m = sf.NeoHookean(youngs_modulus=E, poisson_ratio=0.3)
    mu, _, _ = m.per_element(3)
    assert mu == pytest.approx(E / 2.6)
    with pytest.raises(sf.ParameterError, match=r"\(4,\)"):
        m.per_element(4)


@pytest.mark.parametrize("nu", [0.5, 0.6])
def test_poisson_ratio_at_or_above_half(nu):
    with pytest.raises(sf.ParameterError, match="nu < 0.5") as info:
        sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=nu)
    assert info.value.parameter == "poisson_ratio"
    assert "poisson_ratio" in str(info.value)


@pytest.mark.parametrize(
    "kwargs, parameter",
    [
        (dict(youngs_modulus=-1.0, poisson_ratio=0.3), "youngs_modulus"),
        (dict(youngs_modulus=1e4, poisson_ratio=-1.5), "poisson_ratio"),
        (dict(youngs_modulus=1e4, poisson_ratio=-0.2), "poisson_ratio"),  # lambda would be < 0
        (dict(youngs_modulus=np.inf, poisson_ratio=0.3), "youngs_modulus"),
        (dict(youngs_modulus=1e4, poisson_ratio=0.3, density=-1.0), "density"),
        (dict(shear_modulus=0.0, lame_lambda=1e4), "shear_modulus"),
        (dict(shear_modulus=1e4, lame_lambda=-1.0), "lame_lambda"),
        (dict(youngs_modulus=np.array([1e4, -1.0]), poisson_ratio=0.3), "youngs_modulus"),
    ],
)
def test_neo_hookean_errors(kwargs, parameter):
    with pytest.raises(sf.ParameterError) as info:
        sf.NeoHookean(**kwargs)
    assert info.value.parameter == parameter
    assert parameter in str(info.value)


@pytest.mark.parametrize(
    "kwargs",
    [
        dict(youngs_modulus=1e4),
        dict(youngs_modulus=1e4, poisson_ratio=0.3, shear_modulus=1e3, lame_lambda=1e3),
        dict(youngs_modulus=1e4, lame_lambda=1e3),
        dict(),
    ],
)
def test_neo_hookean_needs_exactly_one_pair(kwargs):
    with pytest.raises(sf.ParameterError, match="exactly one pair"):
        sf.NeoHookean(**kwargs)


# -- Body ---------------------------------------------------------------------------------


def test_body_fix_accumulates_and_overrides(beam, silicone):
    body = sf.Body(beam, silicone)
    body.fix([3, 1])
    body.fix([1, 2], displacement=(0.0, 0.0, 0.01))
    assert body.fixed_nodes.tolist() == [1, 2, 3]
    assert body.prescribed_displacement.tolist() == [[0, 0, 0.01], [0, 0, 0.01], [0, 0, 0]]
    body.fix([5], displacement=[[1.0, 2.0, 3.0]])
    assert body.prescribed_displacement[-1].tolist() == [1, 2, 3]
    mask = np.zeros(beam.n_nodes, dtype=bool)
    mask[[7, 8]] = True
    body.fix(mask)
    assert body.fixed_nodes.tolist() == [1, 2, 3, 5, 7, 8]


@pytest.mark.parametrize(
    "nodes, displacement, error, word",
    [
        ([81], None, sf.InputError, "nodes"),
        ([-1], None, sf.InputError, "nodes"),
        ([0.5], None, sf.ShapeError, "nodes"),
        ([[0, 1]], None, sf.ShapeError, "nodes"),
        ([0, 1], [[0, 0, 0]], sf.ShapeError, "displacement"),
        ([0, 1], [0, 0], sf.ShapeError, "displacement"),
        ([0], [np.nan, 0, 0], sf.InputError, "displacement"),
    ],
)
def test_body_fix_validation(beam, silicone, nodes, displacement, error, word):
    body = sf.Body(beam, silicone)
    with pytest.raises(error, match=word):
        body.fix(nodes, displacement)
    assert body.fixed_nodes.size == 0


def test_body_add_force_accumulates(beam, silicone):
    body = sf.Body(beam, silicone)
    body.add_force([0, 0, 1], (0.0, 0.0, -1.0))
    body.add_force([1], [[1.0, 0.0, 0.0]])
    assert body.forces[0].tolist() == [0, 0, -2]
    assert body.forces[1].tolist() == [1, 0, -1]
    with pytest.raises(sf.InputError, match="nodes"):
        body.add_force([100], (0, 0, 1))


def test_body_rejects_bad_material_size_and_formulation(beam):
    per_element = sf.NeoHookean(youngs_modulus=np.full(3, 1e4), poisson_ratio=0.3)
    with pytest.raises(sf.ParameterError, match=r"\(192,\)"):
        sf.Body(beam, per_element)
    with pytest.raises(sf.InputError, match="formulation"):
        sf.Body(beam, sf.NeoHookean(youngs_modulus=1e4, poisson_ratio=0.3), formulation="magic")


# -- solve_static --------------------------------------------------------------------------


def test_cantilever_sags_under_gravity(beam, silicone):
    body = sf.Body(beam, silicone)
    clamp = beam.nodes_in_box(min=(-1e-9, -1, -1), max=(1e-9, 1, 1))
    body.fix(clamp)
    result = sf.solve_static(body, gravity=(0, 0, -9.81))
    assert result.report.converged
    assert result.report.iterations >= 1
    assert result.displacement.shape == (81, 3)
    assert np.allclose(result.displacement[clamp], 0.0)
    # The supports carry the weight of the 1 x 0.1 x 0.1 m beam.
    np.testing.assert_allclose(result.reactions.sum(axis=0), [0, 0, 1080 * 0.01 * 9.81], rtol=1e-7, atol=1e-7)
    assert result.pressure is None
    assert result.J.shape == result.von_mises.shape == (192,)
    assert np.all(result.J > 0)
    summary = result.to_dict()
    for key in ("converged", "newton_iterations", "residual_norm", "max_displacement", "timings"):
        assert key in summary
    assert "converged" in result.report.summary()
    assert result.report.residual_norm <= 1e-8
    report = result.report
    assert report.absolute_residual_norm == pytest.approx(report.residual_norm * report.reference_norm, rel=1e-12)
    assert set(result.report.timings) >= {"assembly", "factorization", "solve", "line_search", "total"}


def test_prescribed_displacement_is_applied(beam, silicone):
    body = sf.Body(beam, silicone)
    body.fix(beam.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    tip = beam.nodes_on_plane((1, 0, 0), (1, 0, 0))
    body.fix(tip, displacement=(0.0, 0.0, 0.01))
    result = sf.solve_static(body)
    assert result.displacement[tip] == pytest.approx(np.tile([0.0, 0.0, 0.01], (tip.size, 1)), abs=1e-12)


def test_solve_static_argument_validation(beam, silicone):
    body = sf.Body(beam, silicone)
    body.fix(beam.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    with pytest.raises(sf.ShapeError, match="gravity"):
        sf.solve_static(body, gravity=(0, -9.81))
    with pytest.raises(sf.ParameterError, match="tolerance"):
        sf.solve_static(body, tolerance=0.0)
    with pytest.raises(sf.ParameterError, match="max_iterations"):
        sf.solve_static(body, max_iterations=0)
    with pytest.raises(sf.ParameterError, match="load_steps"):
        sf.solve_static(body, load_steps=1.5)
    with pytest.raises(sf.ShapeError, match="initial"):
        sf.solve_static(body, initial=np.zeros((3, 3)))


def test_convergence_error_carries_report(beam, silicone):
    body = sf.Body(beam, silicone)
    body.fix(beam.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    # Far too few iterations for a large load: the solver must give up and say why.
    with pytest.raises(sf.ConvergenceError) as info:
        sf.solve_static(body, gravity=(0, 0, -9.81 * 50), max_iterations=1, tolerance=1e-14)
    report = info.value.report
    assert isinstance(report, sf.SolveReport)
    assert not report.converged
    assert isinstance(info.value, sf.SolverError) and isinstance(info.value, RuntimeError)


def test_convergence_error_constructor_matches_extension_usage():
    err = sf.ConvergenceError("did not converge")
    err.report = {"converged": False}
    assert str(err) == "did not converge"
    assert sf.SolveReport.from_dict(err.report).converged is False


def test_error_hierarchy():
    assert issubclass(sf.ShapeError, sf.InputError)
    assert issubclass(sf.InputError, ValueError) and issubclass(sf.InputError, sf.SorofemError)
    assert issubclass(sf.SceneError, sf.InputError)
    assert issubclass(sf.ConvergenceError, sf.SolverError)
    err = sf.SceneError("bad", path="s.toml", key="material.poisson_ratio", line=7)
    assert str(err) == "s.toml:7, key 'material.poisson_ratio': bad"
