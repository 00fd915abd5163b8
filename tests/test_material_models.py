"""The decoupled models (Mooney-Rivlin, Yeoh, Ogden) through a Body: homogeneous deformations
against the energies' own definitions, and adjoint sensitivities by coefficient name against
re-solved equilibria."""

from __future__ import annotations

import numpy as np
import pytest

import sorofem as sf
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
