"""Closed surfaces to tetrahedral meshes (sorofem.meshing, sorofem.tetrahedralize).

The input checks run without the mesher; the meshing tests need the optional extra
(``pip install ".[mesh]"`` from a checkout) and are skipped without it.
"""

from __future__ import annotations

import sys

import meshio
import numpy as np
import pytest

import sorofem as sf
from sorofem.meshing import check_surface, read_surface, surface_area, surface_volume

SIDE = 0.02  # m
CUBE_POINTS = np.array(
    [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], dtype=float
) * SIDE
CUBE_TRIANGLES = np.array([
    [0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4],
    [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7],
])
ENVELOPE = 1e-3  # sf.tetrahedralize's default


@pytest.fixture
def mesher():
    return pytest.importorskip(sf.meshing.MESHER, reason=f"the optional mesher is not installed: {sf.meshing.INSTALL_HINT}")


def icosphere(subdivisions: int, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """An icosahedron with each triangle split in four ``subdivisions`` times, points on the sphere."""
    t = (1 + 5**0.5) / 2
    points = [np.array(p, dtype=float) for p in (
        [-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
        [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1],
    )]
    points = [p / np.linalg.norm(p) for p in points]
    faces = [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2],
             [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5], [2, 4, 11],
             [6, 2, 10], [8, 6, 7], [9, 8, 1]]
    for _ in range(subdivisions):
        middle: dict[tuple[int, int], int] = {}

        def mid(a: int, b: int) -> int:
            key = (min(a, b), max(a, b))
            if key not in middle:
                p = points[a] + points[b]
                points.append(p / np.linalg.norm(p))
                middle[key] = len(points) - 1
            return middle[key]

        faces = [f for a, b, c in faces for f in (
            [a, mid(a, b), mid(c, a)], [b, mid(b, c), mid(a, b)], [c, mid(c, a), mid(b, c)], [mid(a, b), mid(b, c), mid(c, a)]
        )]
    return np.array(points) * radius, np.array(faces)


def envelope_bound(points: np.ndarray, triangles: np.ndarray) -> float:
    """The volume of fTetWild's envelope, 2 eps A: the most the mesh volume may differ by."""
    diagonal = float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))
    return 2 * ENVELOPE * diagonal * surface_area(points, triangles)


# ---------------------------------------------------------------------------
# Surface geometry and checks (no mesher needed)


def test_surface_volume_and_area_of_a_cube():
    assert surface_volume(CUBE_POINTS, CUBE_TRIANGLES) == pytest.approx(SIDE**3, rel=1e-12)
    assert surface_volume(CUBE_POINTS, CUBE_TRIANGLES[:, ::-1]) == pytest.approx(-SIDE**3, rel=1e-12)
    assert surface_area(CUBE_POINTS, CUBE_TRIANGLES) == pytest.approx(6 * SIDE**2, rel=1e-12)
    # Far from the origin too (the sum is taken about the centroid).
    assert surface_volume(CUBE_POINTS + 1e3, CUBE_TRIANGLES) == pytest.approx(SIDE**3, rel=1e-9)


def test_icosphere_volume_approaches_the_sphere():
    exact = 4 / 3 * np.pi * 0.01**3
    errors = [abs(surface_volume(*icosphere(n, 0.01)) / exact - 1) for n in (1, 2, 3)]
    assert errors[0] > errors[1] > errors[2] and errors[2] < 0.01


def test_check_surface_merges_duplicates_and_turns_outwards():
    # An STL-like soup: every triangle has its own three corners, and all face inwards.
    soup = CUBE_POINTS[CUBE_TRIANGLES[:, ::-1]].reshape(-1, 3)
    triangles = np.arange(len(soup)).reshape(-1, 3)
    points, tidy = check_surface(np.vstack([soup, [[9.0, 9.0, 9.0]]]), triangles)  # plus an unused point
    assert points.shape == (8, 3) and tidy.shape == (12, 3)
    assert surface_volume(points, tidy) == pytest.approx(SIDE**3, rel=1e-12)


def test_read_surface_splits_quads(tmp_path):
    quads = np.array([[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]])
    path = tmp_path / "cube.obj"
    meshio.write(path, meshio.Mesh(CUBE_POINTS * 1e3, [("quad", quads)]))
    points, triangles = read_surface(path, scale=1e-3)
    assert triangles.shape == (12, 3)
    assert surface_volume(*check_surface(points, triangles)) == pytest.approx(SIDE**3, rel=1e-9)


def _cube_with(triangles=None, points=None):
    return (CUBE_POINTS if points is None else points, CUBE_TRIANGLES if triangles is None else triangles)


@pytest.mark.parametrize(
    "surface, error, words",
    [
        (_cube_with(CUBE_TRIANGLES[:-1]), sf.MeshError, ["not closed", "one triangle only"]),
        (_cube_with(np.vstack([CUBE_TRIANGLES, CUBE_TRIANGLES[:1]])), sf.MeshError, ["not manifold"]),
        (_cube_with(np.vstack([CUBE_TRIANGLES[:3], CUBE_TRIANGLES[3, ::-1], CUBE_TRIANGLES[4:]])), sf.MeshError,
         ["inconsistent orientation", "triangles 3 and 11", "same direction", "3 edge(s)"]),
        (_cube_with(np.vstack([CUBE_TRIANGLES, [[0, 0, 1]]])), sf.MeshError, ["triangle 12 is degenerate", "same point"]),
        (_cube_with(np.vstack([CUBE_TRIANGLES, [[0, 1, 8]]]), np.vstack([CUBE_POINTS, [[2 * SIDE, 0, 0]]])),
         sf.MeshError, ["triangle 12 is degenerate", "collinear"]),
        (_cube_with(points=CUBE_POINTS[:, :2]), sf.ShapeError, ["surface points", "expected shape (n, 3)", "(8, 2)"]),
        (_cube_with(CUBE_TRIANGLES[:, [0, 1, 2, 0]]), sf.ShapeError, ["surface triangles", "expected shape (m, 3)", "(12, 4)"]),
        (_cube_with(CUBE_TRIANGLES.astype(float)), sf.ShapeError, ["surface triangles", "integer"]),
        (_cube_with(points=np.where(np.arange(24).reshape(8, 3) == 7, np.nan, CUBE_POINTS)), sf.MeshError,
         ["surface points", "finite", "point 2"]),
        (_cube_with(points=np.full((8, 3), "a")), sf.ShapeError, ["surface points", "real numbers"]),
        (_cube_with(CUBE_TRIANGLES + 1), sf.MeshError, ["indices must be in [0, 8)"]),
        (_cube_with(CUBE_TRIANGLES[:3]), sf.MeshError, ["at least 4 triangles", "got 3"]),
        # A flat closed "pillow": two triangles on each side of one square.
        ((CUBE_POINTS[:4], np.array([[0, 1, 2], [0, 2, 3], [0, 3, 1], [1, 3, 2]])), sf.MeshError, ["encloses no volume"]),
        (CUBE_POINTS, sf.InputError, ["surface: expected a file path", "(points, triangles) pair"]),
        ((CUBE_POINTS, CUBE_TRIANGLES, None), sf.InputError, ["surface: expected"]),
    ],
    ids=["open", "non-manifold", "orientation", "repeated-corner", "collinear", "points-shape", "triangles-shape",
         "triangles-float", "nan", "strings", "index-range", "too-few", "flat", "bare-array", "triple"],
)
def test_bad_surfaces_are_rejected_before_meshing(surface, error, words):
    """Validation comes first: these errors need no mesher."""
    with pytest.raises(error) as info:
        sf.tetrahedralize(surface)
    for word in words:
        assert word in str(info.value), (word, str(info.value))


@pytest.mark.parametrize(
    "kwargs, parameter",
    [
        ({"edge_length": -1.0}, "edge_length"),
        ({"edge_length": float("nan")}, "edge_length"),
        ({"edge_length": 1.0}, "edge_length"),  # longer than the cube's diagonal
        ({"envelope": 0.5}, "envelope"),
        ({"scale": 0}, "scale"),
        ({"coarsen": "yes"}, "coarsen"),
        ({"threads": -1}, "threads"),
    ],
)
def test_bad_parameters_are_named(kwargs, parameter):
    with pytest.raises(sf.ParameterError) as info:
        sf.tetrahedralize((CUBE_POINTS, CUBE_TRIANGLES), **kwargs)
    assert info.value.parameter == parameter
    assert parameter in str(info.value)


def test_surface_files_are_checked(tmp_path):
    with pytest.raises(FileNotFoundError, match="surface file not found"):
        sf.tetrahedralize(tmp_path / "missing.stl")
    volume = tmp_path / "box.vtu"
    sf.Mesh.box(size=(0.1, 0.1, 0.1), cells=(1, 1, 1)).write(volume)
    with pytest.raises(sf.MeshError, match="volume mesh"):
        sf.tetrahedralize(volume)
    garbage = tmp_path / "garbage.stl"
    garbage.write_text("this is not an STL file\n")
    with pytest.raises(sf.MeshError, match="could not read the surface"):
        sf.tetrahedralize(garbage)
    holed = tmp_path / "holed.stl"
    meshio.write(holed, meshio.Mesh(CUBE_POINTS, [("triangle", CUBE_TRIANGLES[:-1])]), binary=True)
    with pytest.raises(sf.MeshError, match=r"surface .*holed\.stl: the surface is not closed"):
        sf.tetrahedralize(holed)


def test_missing_mesher_says_how_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, sf.meshing.MESHER, None)  # makes the import fail
    assert sf.meshing.mesher_available() is False
    with pytest.raises(ImportError, match=r'pip install "\.\[mesh\]" from a checkout'):
        sf.tetrahedralize((CUBE_POINTS, CUBE_TRIANGLES))


def test_mesher_that_needs_pyvista_says_so(monkeypatch, tmp_path):
    """pytetwild 0.3 to 0.4.2 import PyVista on import: without it, say which version to install."""
    fake = tmp_path / sf.meshing.MESHER
    fake.mkdir()
    (fake / "__init__.py").write_text("import pyvista\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, sf.meshing.MESHER, raising=False)
    monkeypatch.setitem(sys.modules, "pyvista", None)
    with pytest.raises(ImportError, match=r"imports PyVista.*pytetwild>=0\.2\.3,<0\.3"):
        sf.meshing.require_mesher()


# ---------------------------------------------------------------------------
# Meshing (needs the mesher)


def test_cube_from_arrays(mesher, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    mesh = sf.tetrahedralize((CUBE_POINTS, CUBE_TRIANGLES), edge_length=SIDE / 4)
    assert list(tmp_path.iterdir()) == []  # fTetWild's debug file went to a scratch folder
    assert isinstance(mesh, sf.Mesh) and mesh.source is None
    assert mesh.reoriented.size == 0 and np.all(mesh.volumes > 0)
    # Planar faces: the volume is kept far inside the envelope bound (2 eps A = 2 % of V here).
    bound = envelope_bound(CUBE_POINTS, CUBE_TRIANGLES)
    error = abs(mesh.volumes.sum() - SIDE**3)
    assert error <= bound and error < 1e-3 * SIDE**3
    lo, hi = mesh.bounds
    np.testing.assert_allclose(lo, 0.0, atol=ENVELOPE * mesh.size)
    np.testing.assert_allclose(hi, SIDE, atol=ENVELOPE * mesh.size)
    assert 20 < mesh.n_tets < 5000


def test_sphere_volume(mesher):
    points, triangles = icosphere(2, 0.01)  # 320 triangles
    enclosed = surface_volume(points, triangles)
    mesh = sf.tetrahedralize((points, triangles), edge_length=0.004)
    error = abs(mesh.volumes.sum() - enclosed)
    # The guarantee is the envelope's volume (2.1 % of V); fTetWild does much better.
    assert error <= envelope_bound(points, triangles)
    assert error < 2e-3 * enclosed
    # Every boundary point lies within the envelope of the polyhedron: between its inscribed
    # radius (nearest facet plane) and the sphere, widened by the envelope.
    corners = points[triangles]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    inradius = np.min(np.abs(np.einsum("ij,ij->i", normals, corners[:, 0])) / np.linalg.norm(normals, axis=1))
    radii = np.linalg.norm(mesh.points[np.unique(mesh.boundary_faces())], axis=1)
    assert radii.max() < 0.01 + ENVELOPE * mesh.size
    assert radii.min() > inradius - ENVELOPE * mesh.size


def test_stl_in_millimetres_inward_facing(mesher, tmp_path):
    """A binary STL in mm whose triangles all face inwards (some CAD exports do)."""
    path = tmp_path / "cube_mm.stl"
    meshio.write(path, meshio.Mesh(CUBE_POINTS * 1e3, [("triangle", CUBE_TRIANGLES[:, ::-1])]), binary=True)
    mesh = sf.tetrahedralize(path, edge_length=SIDE / 4, scale=1e-3)
    assert mesh.source == path
    assert mesh.volumes.sum() == pytest.approx(SIDE**3, rel=1e-3)
    assert mesh.size == pytest.approx(SIDE * 3**0.5, rel=1e-3)


def test_edge_length_sets_the_size(mesher):
    coarse = sf.tetrahedralize((CUBE_POINTS, CUBE_TRIANGLES), edge_length=SIDE / 2)
    fine = sf.tetrahedralize((CUBE_POINTS, CUBE_TRIANGLES), edge_length=SIDE / 8)
    assert fine.n_tets > 8 * coarse.n_tets
    # A target, not a bound: the typical edge is about that long.
    pairs = fine.tets[:, [[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]]]
    edges = np.linalg.norm(fine.points[pairs[..., 0]] - fine.points[pairs[..., 1]], axis=-1)
    assert SIDE / 16 < np.median(edges) < SIDE / 4


def test_mesh_simulates(mesher):
    """The mesh is a normal sorofem mesh: a clamped cube sags under gravity, the clamp carries its weight."""
    mesh = sf.tetrahedralize((CUBE_POINTS, CUBE_TRIANGLES), edge_length=SIDE / 3)
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=100e3, poisson_ratio=0.49, density=1070), formulation="mixed")
    body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    result = sf.solve_static(body, gravity=(0, 0, -9.81))
    weight = 1070 * mesh.volumes.sum() * 9.81
    # Newton stops at a relative residual of 1e-8: the balance holds to that, not to rounding.
    assert np.linalg.norm(result.reactions.sum(axis=0) - [0, 0, weight]) < 1e-6 * weight
    assert result.displacement[:, 2].min() < 0
