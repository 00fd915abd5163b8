"""The extension's additions of issue 14: a validated ``_core.Mesh`` with its queries, models
built from it, ``SolveOptions``, the generic material setter and the ``"material"`` entry of
the sensitivities, errors that name their parameter, and no panic reaching Python."""

import numpy as np
import pytest

import sorofem as sf
from sorofem import _core

from fdcheck import check_gradient

G = np.array([0.0, 0.0, -9.81])


def box(cells=(8, 2, 2), size=(0.4, 0.1, 0.1)):
    return _core.Mesh.box(np.array(size, dtype=float), np.array(cells), np.zeros(3))


def clamped(mesh, formulation="standard"):
    fixed = mesh.nodes_in_box(np.array([-1e-9, -1.0, -1.0]), np.array([1e-9, 1.0, 1.0]))
    model = _core.Model.from_mesh(mesh, fixed, formulation)
    m = mesh.n_tets
    lam = 1e6 if formulation == "mixed" else 1e5
    model.set_material_model("neo_hookean", {"mu": np.full(m, 2.2e4), "lambda": np.full(m, lam)}, np.full(m, 1080.0))
    return model, fixed


def test_mesh_is_validated_once_and_answers_queries():
    mesh = box()
    assert (mesh.n_nodes, mesh.n_tets) == (81, 192)
    assert mesh.volumes.sum() == pytest.approx(0.004, rel=1e-14)
    faces, owners = mesh.boundary_faces()
    assert faces.shape == (144, 3) and owners.shape == (144,)
    tets = mesh.tets
    assert all(set(face) <= set(tets[owner]) for face, owner in zip(faces, owners))
    # Relative tolerance: the same query on the mesh in millimetres finds the same nodes.
    end = mesh.nodes_on_plane(np.array([0.4, 0, 0]), np.array([2.0, 0, 0]))
    mm = _core.Mesh(mesh.points * 1e3, mesh.tets)
    assert end.size == 9
    assert np.array_equal(end, mm.nodes_on_plane(np.array([400.0, 0, 0]), np.array([1.0, 0, 0])))
    located, weights, distance = mesh.locate(np.array([[0.123, 0.04, 0.07], [0.41, 0.05, 0.05], [2.0, 0, 0]]), 0.02)
    assert located[0] >= 0 and located[1] >= 0 and located[2] == -1
    # The weights reproduce the point inside, and the closest point 1 cm outside the end.
    points = mesh.points
    inside = weights[0] @ points[tets[located[0]]]
    assert np.allclose(inside, [0.123, 0.04, 0.07], atol=1e-14)
    assert distance[1] == pytest.approx(0.01) and np.isinf(distance[2])


def test_mesh_errors_name_the_parameter():
    mesh = box((2, 1, 1))
    with pytest.raises(sf.MeshError):
        _core.Mesh(np.zeros((4, 3)), np.array([[0, 1, 2, 3]]))
    with pytest.raises(sf.ParameterError) as info:
        mesh.nodes_on_plane(np.zeros(3), np.zeros(3))
    assert info.value.parameter == "normal"
    with pytest.raises(sf.ParameterError) as info:
        mesh.nodes_in_box(np.ones(3), np.zeros(3))
    assert "min <= max" in str(info.value)


def test_solve_options_object_and_keywords_agree():
    model, _ = clamped(box())
    n = model.mesh.n_nodes
    options = _core.SolveOptions(tolerance=1e-10, load_steps=2)
    assert options.to_dict()["load_steps"] == 2 and options == _core.SolveOptions(**options.to_dict())
    a = model.solve(G, np.zeros((n, 3)), np.zeros((0, 3)), options=options)
    b = model.solve(G, np.zeros((n, 3)), np.zeros((0, 3)), None, 1e-10, 50, 2)
    assert a["iterations"] == b["iterations"] and np.array_equal(a["positions"], b["positions"])
    with pytest.raises(sf.ParameterError) as info:
        _core.SolveOptions(max_iterations=0)
    assert info.value.parameter == "max_iterations"
    with pytest.raises(sf.ParameterError):
        model.solve(G, np.zeros((n, 3)), np.zeros((0, 3)), tolerance=1e-6, options=options)


def test_generic_material_setter_matches_the_original_one():
    model, _ = clamped(box())
    n, m = model.mesh.n_nodes, model.mesh.n_tets
    assert model.material_model == "neo_hookean"
    assert model.material_param_names == _core.material_param_names("neo_hookean") == ["mu", "lambda"]
    generic = model.solve(G, np.zeros((n, 3)), np.zeros((0, 3)))
    model.set_material(np.full(m, 2.2e4), np.full(m, 1e5), np.full(m, 1080.0))
    original = model.solve(G, np.zeros((n, 3)), np.zeros((0, 3)))
    assert np.array_equal(generic["positions"], original["positions"])
    with pytest.raises(sf.ParameterError) as info:
        model.set_material_model("neo_hookean", {"mu": np.full(m, -1.0), "lambda": np.full(m, 1e5)}, np.ones(m))
    assert info.value.parameter == "mu" and "at tet 0" in str(info.value)
    with pytest.raises(sf.ParameterError) as info:
        model.set_material_model("arruda_boyce", {}, np.ones(m))
    assert info.value.parameter == "model"
    with pytest.raises(sf.ParameterError) as info:
        model.set_material_model("yeoh", {}, np.ones(m))
    assert info.value.parameter == "params" and "c10" in str(info.value)
    with pytest.raises(sf.ParameterError) as info:
        model.set_material_model("ogden", {}, np.ones(m))
    assert info.value.parameter == "terms"


@pytest.mark.parametrize("formulation", ["standard", "mixed"])
def test_material_sensitivities_by_name(formulation):
    """The adjoint's "material" entry against a central difference of re-solved equilibria,
    and against the original keys."""
    model, _ = clamped(box((4, 1, 1)), formulation)
    n, m = model.mesh.n_nodes, model.mesh.n_tets
    rng = np.random.default_rng(3)
    c = rng.standard_normal((n, 3))
    # Heterogeneous, so that per-tet derivatives differ: x = (mu, lambda), Pa.
    x = np.concatenate([rng.uniform(2e4, 2.4e4, m), rng.uniform(1, 1.2, m) * (1e6 if formulation == "mixed" else 1e5)])

    def objective(x):
        model.set_material_model("neo_hookean", {"mu": x[:m], "lambda": x[m:]}, np.full(m, 1080.0))
        out = model.solve(G, np.zeros((n, 3)), np.zeros((0, 3)), tolerance=1e-12)
        return float(np.sum(c * out["positions"]))

    objective(x)
    gradient = model.adjoint(c)
    assert set(gradient["material"]) == {"mu", "lambda"}
    assert np.array_equal(gradient["mu"], gradient["material"]["mu"])
    assert np.array_equal(gradient["lam"], gradient["material"]["lambda"])
    assert np.array_equal(gradient["rho"], gradient["density"])
    grad = np.concatenate([gradient["material"]["mu"], gradient["material"]["lambda"]])
    direction = rng.uniform(-1, 1, 2 * m) * x * 0.05
    forward = model.forward({"material": {"mu": direction[:m], "lambda": direction[m:]}})["dx"]
    assert float(np.sum(c * forward)) == pytest.approx(float(grad @ direction), rel=1e-9)
    check = check_gradient(objective, x, grad, direction=direction, step=1e-2)
    assert check.passed, check


def test_internal_error_is_a_solver_error():
    assert issubclass(_core.InternalError, sf.SolverError)
    assert issubclass(_core.InternalError, RuntimeError)
