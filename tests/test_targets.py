"""Targets: barycentric embedding, residuals and their Jacobians (checked by finite differences)."""

from __future__ import annotations

import numpy as np
import pytest
from fdcheck import check_jacobian

import sorofem as sf
from sorofem.targets import Surface, embed_points, read_surface


@pytest.fixture(scope="module")
def mesh() -> sf.Mesh:
    return sf.Mesh.box(size=(0.4, 0.1, 0.1), cells=(4, 2, 2))


def _deformed(mesh: sf.Mesh, seed: int = 1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return mesh.points + 0.01 * rng.standard_normal(mesh.points.shape)


def test_embedding_reproduces_points_and_linear_fields(mesh):
    rng = np.random.default_rng(0)
    pts = rng.uniform([0, 0, 0], [0.4, 0.1, 0.1], size=(50, 3))
    tets, w = embed_points(mesh, pts)
    assert np.all(w >= 0) and np.allclose(w.sum(axis=1), 1.0)
    np.testing.assert_allclose(np.einsum("ka,kad->kd", w, mesh.points[mesh.tets[tets]]), pts, atol=1e-14)
    # An affine motion of the nodes moves embedded points by the same affine map.
    A = np.array([[1.1, 0.2, 0.0], [0.0, 0.9, 0.1], [0.05, 0.0, 1.2]])
    bound = sf.Target.points(pts, pts).bind(mesh)
    np.testing.assert_allclose(bound.points(mesh.points @ A.T + 0.3), pts @ A.T + 0.3, atol=1e-13)


def test_points_outside_are_rejected_or_attached(mesh):
    outside = [[0.5, 0.05, 0.05]]
    with pytest.raises(sf.InputError, match="outside the mesh"):
        sf.Target.points(outside, outside).bind(mesh)
    tets, w = embed_points(mesh, np.array(outside), outside="nearest")
    assert np.all(w >= 0) and np.isclose(w.sum(), 1.0)
    assert mesh.points[mesh.tets[tets[0]]][:, 0].max() == pytest.approx(0.4)


@pytest.mark.parametrize("kind", ["nodes", "points", "surface_vertices", "surface_closest"])
def test_residual_jacobian_matches_finite_differences(mesh, kind):
    x = _deformed(mesh)
    rng = np.random.default_rng(2)
    if kind == "nodes":
        target = sf.Target.nodes([3, 7, 40], rng.standard_normal((3, 3)))
    elif kind == "points":
        target = sf.Target.points(rng.uniform([0, 0, 0], [0.4, 0.1, 0.1], (6, 3)), rng.standard_normal((6, 3)))
    else:
        faces = mesh.boundary_faces()
        used, inverse = np.unique(faces, return_inverse=True)
        rest = Surface(mesh.points[used], inverse.reshape(-1, 3))
        if kind == "surface_vertices":
            target = sf.Target.surface(Surface(rest.vertices + 0.02, rest.faces))
        else:  # a different (coarser) point cloud
            target = sf.Target.surface(Surface(rest.vertices[::3] + 0.001, np.zeros((0, 3), dtype=np.int64)))
    bound = target.bind(mesh)
    assert bound.mode == ("closest" if kind == "surface_closest" else "pointwise")
    assert bound.jacobian(x).shape == (bound.n_residuals, 3 * mesh.n_nodes)
    fd = check_jacobian(
        lambda v: bound.residual(v.reshape(-1, 3)), x.ravel(), bound.jacobian(x),
        step=1e-7, direction=np.random.default_rng(3).uniform(-1, 1, x.size), rtol=1e-7,
    )
    assert fd.passed, str(fd)
    value, grad = bound.misfit(x)
    r = bound.residual(x)
    assert value == pytest.approx(0.5 * r @ r)
    np.testing.assert_allclose(grad.ravel(), bound.jacobian(x).T @ r)


def test_rms_and_max_distance(mesh):
    goal = mesh.points[[0, 1]] + [[0.0, 0.0, 0.03], [0.0, 0.04, 0.0]]
    bound = sf.Target.nodes([0, 1], goal).bind(mesh)
    assert bound.rms(mesh.points) == pytest.approx(np.sqrt((0.03**2 + 0.04**2) / 2))
    assert bound.max_distance(mesh.points) == pytest.approx(0.04)


def test_surface_from_obj_with_matching_topology(tmp_path, mesh):
    faces = mesh.boundary_faces()
    used, inverse = np.unique(faces, return_inverse=True)
    verts = mesh.points[used] * 100  # written in centimetres
    tri = inverse.reshape(-1, 3)

    def write(path, v):
        lines = [f"v {a} {b} {c}" for a, b, c in v] + [f"f {i + 1} {j + 1} {k + 1}" for i, j, k in tri]
        path.write_text("\n".join(lines) + "\n", encoding="utf-8")

    write(tmp_path / "rest.obj", verts)
    write(tmp_path / "goal.obj", verts + [0.0, 0.0, -1.0])
    surf = read_surface(tmp_path / "rest.obj", scale=0.01)
    np.testing.assert_allclose(surf.vertices, mesh.points[used])
    bound = sf.Target.surface(tmp_path / "goal.obj", scale=0.01, rest=tmp_path / "rest.obj").bind(mesh)
    assert bound.mode == "pointwise"
    assert bound.rms(mesh.points) == pytest.approx(0.01)


def test_surface_vertices_mismatch_is_an_error(mesh):
    cloud = Surface(np.zeros((4, 3)), np.array([[0, 1, 2]]))
    with pytest.raises(sf.InputError, match="topology"):
        sf.Target.surface(cloud, match="vertices").bind(mesh)


def test_shape_errors():
    with pytest.raises(sf.ShapeError):
        sf.Target.nodes([0, 1], [[0, 0, 0]])
    with pytest.raises(sf.ShapeError):
        sf.Target.points([[0, 0]], [[0, 0, 0]])
