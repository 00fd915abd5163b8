"""Static closed forms: stresses and energy of homogeneous deformations, and the weight of a
body made of two materials.

Homogeneous deformations: every boundary node of a cube is moved to ``x = F X``; the interior
follows (patch test) and every tetrahedron carries the same Cauchy stress. For the
compressible Neo-Hookean model ``psi = mu/2 (I1 - 3) - mu ln J + lambda/2 c(J)^2``,

    sigma = (mu (B - I) + lambda c(J) c'(J) J I) / J,        B = F F^T,

whose deviatoric part is ``mu dev(B) / J``. So the von Mises stress ``sqrt(3/2 |dev sigma|^2)``
is

* pure dilation ``F = s I``: 0 (``B`` is isotropic);
* uniaxial strain ``F = diag(s, 1, 1)``: ``mu |s^2 - 1| / s``;
* simple shear ``F = I + gamma e_x e_y^T`` (J = 1): ``mu gamma sqrt(3 + gamma^2)``,

in both formulations (the mixed one reports the stress of the same energy). The total
potential energy at equilibrium is ``V psi(F)``.
"""

from __future__ import annotations

import numpy as np
import pytest

import sorofem as sf
from independent import lumped_weight

MU, LAMBDA = 22.76e3, 204.8e3  # Pa
SIDE = 0.1  # m
GRAVITY = np.array([0.0, 0.0, -9.81])


def neo_hookean_energy_density(F: np.ndarray, volumetric: str) -> float:
    """``psi(F)`` in Pa, written out from the model's definition."""
    J = float(np.linalg.det(F))
    c = np.log(J) if volumetric == "log" else J - 1.0
    return MU / 2 * (np.trace(F.T @ F) - 3) - MU * np.log(J) + LAMBDA / 2 * c**2


HOMOGENEOUS = {
    "dilation": (1.1 * np.eye(3), 0.0),
    "uniaxial_strain": (np.diag([1.2, 1.0, 1.0]), MU * (1.2**2 - 1) / 1.2),
    "compression": (np.diag([1.0, 0.85, 1.0]), MU * (1 - 0.85**2) / 0.85),
    "simple_shear": (np.eye(3) + 0.3 * np.outer([1, 0, 0], [0, 1, 0]), MU * 0.3 * np.sqrt(3 + 0.3**2)),
}


def solve_homogeneous(F: np.ndarray, volumetric: str, formulation: str) -> sf.StaticResult:
    """The cube with its boundary nodes at ``F X``, solved for the interior."""
    mesh = sf.Mesh.box(size=(SIDE, SIDE, SIDE), cells=(2, 2, 2))
    body = sf.Body(mesh, sf.NeoHookean(shear_modulus=MU, lame_lambda=LAMBDA), formulation, volumetric=volumetric)
    lo, hi = mesh.bounds()
    boundary = mesh.nodes_where(lambda p: np.any(np.isclose(p, lo) | np.isclose(p, hi), axis=1))
    assert boundary.size < mesh.n_nodes  # the interior node is free: its position is a patch test
    body.fix(boundary, displacement=mesh.points[boundary] @ (F - np.eye(3)).T)
    result = sf.solve_static(body, tolerance=1e-12)
    np.testing.assert_allclose(result.positions, mesh.points @ F.T, rtol=0, atol=1e-12 * SIDE)
    np.testing.assert_allclose(result.J, np.linalg.det(F), rtol=1e-12)
    return result


@pytest.mark.parametrize("formulation", ["standard", "mixed"])
@pytest.mark.parametrize("volumetric", ["log", "linear"])
@pytest.mark.parametrize("case", sorted(HOMOGENEOUS))
def test_homogeneous_deformation_von_mises(case, volumetric, formulation):
    F, von_mises = HOMOGENEOUS[case]
    result = solve_homogeneous(F, volumetric, formulation)
    np.testing.assert_allclose(result.von_mises, von_mises, rtol=1e-9, atol=1e-9 * MU)


@pytest.mark.parametrize("volumetric", ["log", "linear"])
@pytest.mark.parametrize("case", sorted(HOMOGENEOUS))
def test_homogeneous_deformation_energy(case, volumetric):
    """The standard solver's merit is the total potential energy (the mixed one minimises
    another merit): here only the elastic energy ``V psi(F)``."""
    F, _ = HOMOGENEOUS[case]
    result = solve_homogeneous(F, volumetric, "standard")
    energy = SIDE**3 * neo_hookean_energy_density(F, volumetric)
    assert result.report.merit_history[-1] == pytest.approx(energy, rel=1e-9)


@pytest.mark.parametrize("formulation", ["standard", "mixed"])
def test_two_density_bar_reactions_carry_its_weight(formulation):
    """A 0.4 m bar, light (1000 kg/m^3) near the clamp and heavy (3000 kg/m^3) beyond x = 0.2 m:
    the reactions carry ``g (rho_1 + rho_2) V / 2`` (V / 2 per half, from the box size alone),
    and their moment about the origin cancels that of the lumped weight at the deformed nodes."""
    size = (0.4, 0.1, 0.1)
    mesh = sf.Mesh.box(size=size, cells=(8, 2, 2))
    centroid_x = mesh.points[mesh.tets].mean(axis=1)[:, 0]
    density = np.where(centroid_x < 0.2, 1000.0, 3000.0)
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=np.full(mesh.n_tets, 3e5), poisson_ratio=0.3, density=density),
                   formulation)
    body.fix(mesh.nodes_on_plane((0.0, 0.0, 0.0), (1.0, 0.0, 0.0)))
    result = sf.solve_static(body, gravity=GRAVITY, tolerance=1e-10)
    half = np.prod(size) / 2
    weight = GRAVITY * (1000.0 + 3000.0) * half
    np.testing.assert_allclose(result.reactions.sum(axis=0), -weight, rtol=0, atol=1e-10 * np.linalg.norm(weight))
    forces = lumped_weight(mesh, density, GRAVITY)
    moment = np.cross(result.positions[body.fixed_nodes], result.reactions).sum(axis=0) + np.cross(
        result.positions, forces
    ).sum(axis=0)
    assert np.linalg.norm(moment) < 1e-9 * np.linalg.norm(weight) * size[0]
    # The lumped weight acts at the centre of mass, x = (1000 * 0.1 + 3000 * 0.3) / 4000 = 0.25 m.
    lever = np.cross(mesh.points, forces).sum(axis=0)[1] / np.linalg.norm(weight)
    assert lever == pytest.approx(0.25, rel=1e-12)
