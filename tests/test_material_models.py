"""The decoupled models (Mooney-Rivlin, Yeoh, Ogden) through a Body: homogeneous deformations
against the energies' own definitions, and adjoint sensitivities by coefficient name against
re-solved equilibria."""

from __future__ import annotations

import numpy as np
import pytest

import sorofem as sf
from sorofem.cli import main
from fdcheck import central_difference, check_gradient

# Silicone-like coefficients (Pa, 1/Pa): shear modulus ~ 20-25 kPa, bulk modulus ~ 1 MPa.
MATERIALS = {
    "mooney-rivlin": sf.MooneyRivlin(c10=8e3, c01=3e3, d1=2e-6, density=1070),
    "yeoh": sf.Yeoh(c10=11e3, c20=-400.0, c30=40.0, d1=2e-6, d2=4e-5, density=1070),
    "ogden": sf.Ogden(mu=[1.9e3, 2.2e4, -1.5e3], alpha=[-3.8, 1.7, 4.2], d1=2e-6, density=1070),
}


def energy_density(material: sf.materials.Material, F: np.ndarray) -> float:
    """W(F) written from the issue's definitions (Pa), independently of the core."""
    J = np.linalg.det(F)
    C = F.T @ F
    I1 = np.trace(C)
    I2 = 0.5 * (I1**2 - np.trace(C @ C))
    I1b, I2b = J ** (-2 / 3) * I1, J ** (-4 / 3) * I2
    if isinstance(material, sf.MooneyRivlin):
        return material.c10 * (I1b - 3) + material.c01 * (I2b - 3) + (J - 1) ** 2 / material.d1
    if isinstance(material, sf.Yeoh):
        c = (material.c10, material.c20, material.c30)
        d = (material.d1, material.d2, material.d3)
        iso = sum(ci * (I1b - 3) ** (i + 1) for i, ci in enumerate(c))
        return iso + sum((J - 1) ** (2 * (i + 1)) / di for i, di in enumerate(d) if di > 0)
    stretches = J ** (-1 / 3) * np.sqrt(np.linalg.eigvalsh(C))
    iso = sum(2 * m / a**2 * (np.sum(stretches**a) - 3) for m, a in zip(material.mu, material.alpha))
    return iso + (J - 1) ** 2 / material.d1


def first_piola(material: sf.materials.Material, F: np.ndarray) -> np.ndarray:
    """P = dW/dF (Pa) by central differences of :func:`energy_density`, entry by entry."""
    P = np.zeros((3, 3))
    for i in range(3):
        for j in range(3):
            unit = np.zeros((3, 3))
            unit[i, j] = 1.0
            P[i, j] = central_difference(lambda f: energy_density(material, f.reshape(3, 3)), F.ravel(), unit.ravel(), 1e-6)
    return P


@pytest.mark.parametrize("name", list(MATERIALS))
@pytest.mark.parametrize("formulation", ["standard", "mixed"])
def test_homogeneous_deformation_is_reproduced_with_the_analytic_stress(name: str, formulation: str) -> None:
    """Every boundary node of a unit cube prescribed to x = F X: the interior nodes follow F and
    the reactions' first moment sum_a r_a X_a^T = P V (column j: the force on the face X_j = 1,
    the side faces' contributions cancelling in pairs) equals the analytic P of the energy."""
    material = MATERIALS[name]
    F = np.array([[1.35, 0.12, 0.0], [0.05, 0.88, -0.07], [0.0, 0.04, 0.93]])
    mesh = sf.Mesh.box(size=[1.0, 1.0, 1.0], cells=[2, 2, 2])
    X = mesh.points
    boundary = np.flatnonzero(np.any((X < 1e-12) | (X > 1 - 1e-12), axis=1))
    interior = np.setdiff1d(np.arange(mesh.n_nodes), boundary)
    assert interior.size == 1
    body = sf.Body(mesh, material, formulation=formulation)
    body.fix(boundary, displacement=X[boundary] @ (F - np.eye(3)).T)
    result = sf.solve_static(body, load_steps=4)
    assert np.abs(result.positions[interior] - X[interior] @ F.T).max() < 1e-9
    moment = result.reactions.T @ X[body.fixed_nodes]
    P = first_piola(material, F)
    assert np.abs(moment - P).max() < 1e-6 * np.abs(P).max(), (moment, P)


def tip_objective(positions: np.ndarray) -> tuple[float, np.ndarray]:
    """Mean vertical position of the tip face (m) and its gradient."""
    tip = np.isclose(positions[:, 0], positions[:, 0].max(), atol=2e-3)
    grad = np.zeros_like(positions)
    grad[tip, 2] = 1.0 / tip.sum()
    return float(positions[tip, 2].mean()), grad


@pytest.mark.parametrize("name", list(MATERIALS))
def test_cantilever_sensitivities_by_coefficient_name(name: str) -> None:
    """sf.gradient by the coefficient names against central differences of re-solved equilibria
    (a cantilever under gravity, every coefficient at once along a random direction)."""
    material = MATERIALS[name]
    mesh = sf.Mesh.box(size=[0.1, 0.02, 0.02], cells=[6, 2, 2])
    names = list(material.model.core_form.names)
    names = [n for n in names if material.value(n) != 0]  # Yeoh's absent d3 term stays absent

    def body_with(values: np.ndarray) -> sf.Body:
        given = {n: material.value(n) for n in material.model.core_form.names} | dict(zip(names, values))
        body = sf.Body(mesh, material.with_values(given, material.density))
        body.fix(mesh.points[:, 0] < 1e-9)
        return body

    theta = np.array([material.value(n) for n in names], dtype=float)
    gravity = [0.0, 0.0, -9.81]
    result = sf.gradient(body_with(theta), tip_objective, params=names, gravity=gravity)
    grad = np.array([result.gradient[n] for n in names])

    def tip(values: np.ndarray) -> float:
        return tip_objective(sf.solve_static(body_with(values), gravity=gravity, tolerance=1e-10).positions)[0]

    check = check_gradient(tip, theta, grad, step=1e-4, rtol=1e-5)
    assert check.passed, str(check)
    # Each coefficient matters: the tip moves by a measurable amount along every direction.
    assert np.all(np.abs(grad * theta) > 1e-9), dict(zip(names, grad * theta))


SCENE_MATERIALS = {
    "mooney-rivlin": 'model = "mooney-rivlin"\nc10 = 8e3\nc01 = 3e3\nd1 = 2e-6',
    "yeoh": 'model = "yeoh"\nc10 = 11e3\nc20 = -400.0\nc30 = 40.0\nd1 = 2e-6\nd2 = 4e-5',
    "ogden": 'model = "ogden"\n"mu:0" = 1.9e3\n"alpha:0" = -3.8\n"mu:1" = 2.2e4\n"alpha:1" = 1.7\n'
             '"mu:2" = -1.5e3\n"alpha:2" = 4.2\nd1 = 2e-6',
}


def scene_text(material: str, formulation: str = "standard", region: str = "") -> str:
    return (
        '[mesh]\nbox = { size = [0.1, 0.02, 0.02], cells = [4, 1, 1] }\n\n'
        f"[material]\n{material}\ndensity = 1070\n{region}\n"
        f'[formulation]\nkind = "{formulation}"\n\n'
        "[[fixed]]\nbox = { min = [-1e-9, -1, -1], max = [1e-9, 1, 1] }\n\n"
        "[loads]\ngravity = [0, 0, -9.81]\n"
    )


@pytest.mark.parametrize("name", list(MATERIALS))
@pytest.mark.parametrize("formulation", ["standard", "mixed"])
def test_scene_material_model_matches_the_body(tmp_path, name: str, formulation: str) -> None:
    """[material] model = "yeoh" etc. with the coefficient names builds the same material and
    equilibrium as the Python API."""
    path = tmp_path / "scene.toml"
    path.write_text(scene_text(SCENE_MATERIALS[name], formulation))
    scene = sf.Scene.load(path)
    assert type(scene.material) is type(MATERIALS[name])
    assert scene.material.to_dict() == MATERIALS[name].to_dict()
    body = sf.Body(scene.mesh, MATERIALS[name], formulation=formulation)
    body.fix(scene.body.fixed_nodes)
    expected = sf.solve_static(body, gravity=[0, 0, -9.81]).positions
    assert np.abs(scene.solve().positions - expected).max() < 1e-12


def test_scene_region_overrides_an_ogden_coefficient(tmp_path) -> None:
    """A [[material.region]] entry gives one coefficient; the others are inherited, and the tip
    (made stiffer) sags less."""
    region = '\n[[material.region]]\nbox = { min = [0.05, -1, -1], max = [1, 1, 1] }\n"mu:1" = 8.8e4\n'
    path = tmp_path / "scene.toml"
    path.write_text(scene_text(SCENE_MATERIALS["ogden"]))
    plain = sf.Scene.load(path)
    path.write_text(scene_text(SCENE_MATERIALS["ogden"], region=region))
    stiff = sf.Scene.load(path)
    mu1 = np.asarray(stiff.material.value("mu:1"))
    centroids = stiff.mesh.points[stiff.mesh.tets].mean(axis=1)[:, 0]
    assert np.all(mu1[centroids >= 0.05] == 8.8e4) and np.all(mu1[centroids < 0.05] == 2.2e4)
    assert np.all(np.asarray(stiff.material.value("alpha:2")) == 4.2)
    assert stiff.solve().displacement[:, 2].min() > plain.solve().displacement[:, 2].min()


@pytest.mark.parametrize(
    ("material", "key", "words"),
    [
        ('model = "yeoh"\nc10 = 11e3\nc20 = 0.0\nc30 = 0.0\nd1 = 0.0', "material.d1", ["> 0", "got 0"]),
        ('model = "mooney-rivlin"\nc10 = 8e3\nc01 = -9e3\nd1 = 2e-6', "material.c10", ["c10 + c01 > 0"]),
        ('model = "ogden"\n"mu:0" = 2e4\n"alpha:0" = 0.0\nd1 = 2e-6', "material.alpha:0", ["nonzero"]),
    ],
)
def test_bad_scene_coefficients_exit_2_naming_the_key(tmp_path, capsys, material: str, key: str, words: list[str]) -> None:
    path = tmp_path / "scene.toml"
    path.write_text(scene_text(material))
    assert main(["run", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert key in err and all(w in err for w in words), err


def test_cli_run_writes_the_model_and_its_coefficients(tmp_path) -> None:
    import json

    path = tmp_path / "scene.toml"
    path.write_text(scene_text(SCENE_MATERIALS["yeoh"], "mixed"))
    assert main(["run", str(path), "--out", str(tmp_path / "out")]) == 0
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["material"]["model"] == "yeoh"
    assert summary["material"]["c20"] == -400.0 and summary["material"]["d2"] == 4e-5


@pytest.mark.parametrize(
    ("name", "params", "x0"),
    [("yeoh", ["c10", "c20"], [8e3, -100.0]), ("ogden", ["mu:1", "alpha:1"], [1.5e4, 2.5])],
)
def test_estimate_recovers_coefficients_by_name(name: str, params: list[str], x0: list[float]) -> None:
    """sf.estimate by coefficient name recovers them from a synthetic equilibrium (a cantilever
    under gravity, sagging past the small-strain range so that the higher terms show); a
    negative c20 is optimised in identity space."""
    truth = MATERIALS[name]
    mesh = sf.Mesh.box(size=[0.15, 0.015, 0.015], cells=[8, 2, 2])
    body = sf.Body(mesh, truth)
    body.fix(mesh.points[:, 0] < 1e-9)
    gravity = [0.0, 0.0, -9.81]
    goal = sf.solve_static(body, gravity, tolerance=1e-10).positions
    fit = sf.estimate(body, sf.Target.nodes(np.arange(mesh.n_nodes), goal), params, x0=x0, gravity=gravity)
    for p in params:
        assert fit.params[p] == pytest.approx(truth.value(p), rel=1e-5), (p, fit.params)
    assert fit.converged


@pytest.mark.parametrize(
    ("build", "parameter", "words"),
    [
        (lambda: sf.MooneyRivlin(c10=8e3, c01=3e3, d1=0.0), "d1", ["> 0", "got 0"]),
        (lambda: sf.MooneyRivlin(c10=-8e3, c01=3e3, d1=2e-6), "c10", ["c10 + c01 > 0"]),
        (lambda: sf.Yeoh(c10=0.0, d1=2e-6), "c10", ["> 0"]),
        (lambda: sf.Yeoh(c10=1e4), "d1", ["required"]),
        (lambda: sf.Yeoh(c10=1e4, d1=2e-6, d2=-1e-5), "d2", [">= 0"]),
        (lambda: sf.Ogden(mu=[1e4, 2e3], alpha=[2.0], d1=2e-6), "alpha", ["as many exponents"]),
        (lambda: sf.Ogden(mu=[1e4] * 4, alpha=[2.0] * 4, d1=2e-6), "mu", ["1 to 3"]),
        (lambda: sf.Ogden(mu=[1e4, 2e3], alpha=[2.0, 0.0], d1=2e-6), "alpha:1", ["nonzero"]),
        (lambda: sf.Ogden(mu=[-1e4], alpha=[2.0], d1=2e-6), "mu:0", ["sum_p mu_p"]),
        (lambda: sf.Yeoh(c10=1e4, c20=float("nan"), d1=2e-6), "c20", ["finite"]),
    ],
)
def test_bad_coefficients_name_the_parameter(build, parameter: str, words: list[str]) -> None:
    with pytest.raises(sf.ParameterError) as err:
        build()
    assert err.value.parameter == parameter and str(err.value).startswith(f"{parameter}:")
    assert all(w in str(err.value) for w in words), str(err.value)
