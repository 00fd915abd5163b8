"""The forward (tangent-linear) trajectory sensitivity (``Model::trajectory_sensitivity``, the
Jacobian of sf.estimate(dynamics=)) against central differences of re-simulated trajectories
(tests/fdcheck.py), every parameter on its own: material, density, Rayleigh damping, a spring
cable's stiffness, standard and mixed, with a pulled tendon (the bordered steps) and one driven
by its tension; and the Jacobian's transpose times the residual against the adjoint gradient."""

from __future__ import annotations

import numpy as np
import pytest
from fdcheck import check_jacobian

import sorofem as sf
from sorofem.dynamics import Keyframes
from sorofem.inverse._estimate_dynamics import DynamicParameters, DynamicProblem, _run_options, _tracks

G = (0.0, 0.0, -9.81)
TIGHT = 1e-11  # Newton tolerance of every step, in the sensitivity's run and the re-simulations
DT, STEPS = 0.01, 10


def beam(formulation="standard", cable=None, tendon=None):
    """The 0.4 m cantilever on 4 x 1 x 1 cells, with a spring cable (alpha, stiffness) near the
    bottom face or a tendon ({"pull": d} or {"tension": T}) near the top face."""
    mesh = sf.Mesh.box(size=(0.4, 0.1, 0.1), cells=(4, 1, 1))
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080.0), formulation)
    body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    if cable is not None:
        alpha, k = cable
        body.add_cable(sf.Cable.line((0.0, 0.05, 0.02), (1, 0, 0), 0.4, 4, stiffness=k, actuation=alpha))
    if tendon is not None:
        body.add_cable(sf.Cable.line((0.01, 0.05, 0.08), (1, 0, 0), 0.38, 4, model="tendon", **tendon))
    return body


def problem(body, names, damping=(2.0, 0.004), **dynamics):
    tip = body.mesh.nodes_on_plane((0.4, 0, 0), (1, 0, 0))
    tracks = [(DT * STEPS, sf.Target.nodes(tip, body.mesh.points[tip]))]
    run = _run_options(dict(dt=DT, steps=STEPS, damping=damping, **dynamics), G, TIGHT, 50, body)
    params = DynamicParameters(body, names, None, run["damping"])
    return DynamicProblem(body, params, _tracks(tracks, body, DT, STEPS), run)


def assert_matches_differences(prob):
    """Each parameter's column of d positions / d theta (every frame) against the central
    difference of re-simulated trajectories, relative step 1e-5."""
    p = prob.params
    theta = p.current()
    positions, dx = prob.sensitivities(theta)
    assert positions.shape == (STEPS + 1, prob.body.mesh.n_nodes, 3)
    np.testing.assert_allclose(positions, prob.simulate(theta).positions, atol=1e-12)
    assert np.all(dx[:, 0] == 0.0)  # the initial state is data
    jacobian = dx.reshape(p.size, -1).T

    def run(t):
        return prob.simulate(t).positions.ravel()

    result = check_jacobian(run, theta, jacobian, direction=np.abs(theta), step=1e-5, rtol=2e-5,
                            blocks=[[j] for j in range(p.size)])
    assert result.passed, f"{p.names}: {result}"
    for j in range(p.size):
        assert np.abs(dx[j]).max() > 0, f"{p.names[j]} moves nothing"


@pytest.mark.parametrize("formulation", ["standard", "mixed"])
def test_material_density_and_damping(formulation):
    names = ["youngs_modulus", "poisson_ratio", "density", "mass_damping", "stiffness_damping"]
    assert_matches_differences(problem(beam(formulation), names))


@pytest.mark.parametrize("formulation", ["standard", "mixed"])
def test_spring_cable_stiffness(formulation):
    body = beam(formulation, cable=(0.85, 3e3))
    assert_matches_differences(problem(body, ["cable_stiffness", "shear_modulus", "stiffness_damping"]))


@pytest.mark.parametrize("formulation", ["standard", "mixed"])
@pytest.mark.parametrize("command", ["pull", "tension"])
def test_tendon(formulation, command):
    """A tendon pulled by keyframes (a constraint of every step: the bordered solves) or driven
    by its tension; its force is the motor's, which stiffness damping leaves undamped."""
    if command == "pull":
        frames = Keyframes([[0.0, 0.0], [0.05, 0.004], [0.1, 0.006]])
    else:
        frames = Keyframes([[0.0, 0.0], [0.05, 1.5], [0.1, 2.0]])
    body = beam(formulation, tendon={command: 0.0})
    names = ["youngs_modulus", "density", "mass_damping", "stiffness_damping"]
    assert_matches_differences(problem(body, names, damping=(2.0, 0.003), actuation={0: frames}))


def test_jacobian_times_residual_is_the_adjoint_gradient():
    """Two independent derivatives of the same misfit: ``J^T r`` from the forward sensitivity
    and the adjoint gradient of ``1/2 |r|^2``."""
    prob = problem(beam("mixed", cable=(0.9, 3e3)), ["mass_damping", "stiffness_damping", "density", "cable_stiffness"],
                   initial_velocity=np.tile([0.0, 0.1, 0.0], (beam().mesh.n_nodes, 1)))
    s = prob.params.to_s(prob.params.current())
    r, J = prob.evaluate(s, "jacobian")
    r_adjoint, g = prob.evaluate(s, "gradient")
    np.testing.assert_allclose(r_adjoint, r, atol=1e-12)
    np.testing.assert_allclose(J.T @ r, g, rtol=1e-8, atol=1e-10 * np.abs(g).max())
