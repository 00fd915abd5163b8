"""Rayleigh damping against the closed-form implicit Euler recurrence of a one-DOF oscillator.

One tetrahedron with three nodes clamped and its fourth node, at the origin, moved along the
diagonal ``d = (1, 1, 1) / sqrt 3``: the tet and the load are symmetric under every permutation of
the axes, so the free node stays on the diagonal (one degree of freedom, ``q``). For the corner
tet of edge ``L`` (``V = L^3 / 6``, ``grad N_0 = -(1, 1, 1) / L``) the displacement ``q d`` is a
uniaxial strain ``eps = -sqrt(3) q / L`` along ``d``, of energy ``V (lambda + 2 mu) eps^2 / 2``
at small strain: the stiffness is ``k = 3 V (lambda + 2 mu) / L^2`` and the lumped mass of the
node ``m = rho V / 4``.

An implicit Euler step with Rayleigh damping ``c = alpha_M m + beta_K k`` solves
``m (v' - v) / h + c v' + k (q + h v') = 0`` and sets ``q' = q + h v'``:

    v' = (m v - h k q) / (m + h c + h^2 k)

At an amplitude of ``1e-9 L`` the Neo-Hookean response is linear to about 1e-9, so the simulated
motion must follow this recurrence to 1e-6 of the amplitude. The parameters make each of
``alpha_M h``, ``beta_K k h / m`` and ``k h^2 / m`` about 0.1-0.3 of the leading term: a factor 2
on either damping coefficient moves the trajectory by percents.
"""

from __future__ import annotations

import numpy as np
import pytest

import sorofem as sf

EDGE = 0.1  # m
E, NU, RHO = 66e3, 0.45, 1080.0
DT, STEPS = 1e-3, 30  # s
AMPLITUDE = 1e-9 * EDGE  # m
ALPHA_M = 100.0  # 1/s
BETA_K = 1e-3  # s


def corner_tet() -> sf.Body:
    """The corner tet, free node 0 at the origin (its displacement is stored exactly)."""
    points = [[0.0, 0.0, 0.0], [EDGE, 0.0, 0.0], [0.0, EDGE, 0.0], [0.0, 0.0, EDGE]]
    mesh = sf.Mesh(points, [[0, 1, 2, 3]])
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=E, poisson_ratio=NU, density=RHO))
    body.fix([1, 2, 3])
    return body


def stiffness_and_mass() -> tuple[float, float]:
    material = sf.NeoHookean(youngs_modulus=E, poisson_ratio=NU)
    volume = EDGE**3 / 6.0
    k = 3.0 * volume * (float(material.lame_lambda) + 2.0 * float(material.shear_modulus)) / EDGE**2
    return k, RHO * volume / 4.0


def implicit_euler(q0: float, v0: float, k: float, m: float, c: float, steps: int) -> tuple[np.ndarray, np.ndarray]:
    q, v = [q0], [v0]
    for _ in range(steps):
        v.append((m * v[-1] - DT * k * q[-1]) / (m + DT * c + DT**2 * k))
        q.append(q[-1] + DT * v[-1])
    return np.array(q), np.array(v)


@pytest.mark.parametrize(
    "alpha_m, beta_k", [(ALPHA_M, 0.0), (0.0, BETA_K), (ALPHA_M, BETA_K)], ids=["mass", "stiffness", "both"]
)
@pytest.mark.parametrize("start", ["displaced", "moving"])
def test_rayleigh_damping_follows_the_one_dof_recurrence(alpha_m, beta_k, start):
    body = corner_tet()
    k, m = stiffness_and_mass()
    d = np.ones(3) / np.sqrt(3.0)
    q0, v0 = (AMPLITUDE, 0.0) if start == "displaced" else (0.0, AMPLITUDE * np.sqrt(k / m))
    initial = body.mesh.points.copy()
    initial[0] = q0 * d
    velocity = np.zeros((4, 3))
    velocity[0] = v0 * d
    traj = sf.simulate(body, DT, STEPS, damping=(alpha_m, beta_k), initial=initial, initial_velocity=velocity,
                       tolerance=1e-12)
    q_ref, v_ref = implicit_euler(q0, v0, k, m, alpha_m * m + beta_k * k, STEPS)
    u = traj.positions[:, 0, :]  # the node sits at the origin: positions are displacements
    along = u @ d
    scale = max(abs(q0), abs(v0) * DT)
    assert np.abs(along - q_ref).max() < 1e-6 * scale, np.abs(along - q_ref).max() / scale
    assert np.abs(u - along[:, None] * d).max() < 1e-6 * scale  # it stays on the diagonal
    np.testing.assert_allclose(traj.velocities[0], v_ref[-1] * d, rtol=1e-6, atol=1e-6 * np.abs(v_ref).max())
    np.testing.assert_allclose(traj.kinetic_energy, 0.5 * m * v_ref**2, rtol=1e-6, atol=1e-9 * m * np.abs(v_ref).max() ** 2)
    # The damping matters here: the undamped motion differs by far more than the tolerance.
    q_undamped, _ = implicit_euler(q0, v0, k, m, 0.0, STEPS)
    assert np.abs(q_undamped - q_ref).max() > 1e-2 * scale
