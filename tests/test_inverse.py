"""Gradients (adjoint, checked by central differences through full solves), estimation and
control on cheap cantilevers."""

from __future__ import annotations

import json

import numpy as np
import pytest
from fdcheck import check_gradient

import sorofem as sf

SIZE, CELLS = (0.4, 0.1, 0.1), (4, 2, 2)
G = np.array([0.0, 0.0, -9.81])
TIGHT = 1e-12  # Newton tolerance of the finite-difference solves


def build(formulation="standard", mu=22.76e3, lam=0.2048e6, rho=1080.0, cable=None):
    """The 0.4 m cantilever on a coarse grid; ``cable`` = (alpha, stiffness) adds one cable
    1 cm inside the bottom and y = 0 faces."""
    mesh = sf.Mesh.box(size=SIZE, cells=CELLS)
    body = sf.Body(mesh, sf.NeoHookean(shear_modulus=mu, lame_lambda=lam, density=rho), formulation)
    body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    if cable is not None:
        alpha, k = cable
        c = sf.Cable.line((0.0, 0.02, 0.02), (1, 0, 0), 0.4, 8, stiffness=k, actuation=alpha)
        body.add_cable(c)
    return body


def tip_target(body):
    tip = body.mesh.nodes_on_plane((0.4, 0, 0), (1, 0, 0))
    return sf.Target.nodes(tip, body.mesh.points[tip] + [-0.05, 0.02, -0.15])


@pytest.mark.parametrize("formulation", ["standard", "mixed"])
def test_gradient_material_and_gravity_match_central_differences(formulation):
    body = build(formulation)
    target = tip_target(body)
    names = ["shear_modulus", "lame_lambda", "density", "gravity"]
    g = sf.gradient(body, target, names, gravity=G, tolerance=TIGHT)
    theta = np.array([22.76e3, 0.2048e6, 1080.0, *G])

    def value(t):
        b = build(formulation, mu=t[0], lam=t[1], rho=t[2])
        x = sf.solve_static(b, t[3:], tolerance=TIGHT).positions
        return target.bind(b.mesh).misfit(x)[0]

    assert g.value == pytest.approx(value(theta), rel=1e-10)
    for seed in range(2):
        fd = check_gradient(value, theta, g.vector, seed=seed, step=1e-5, rtol=1e-5)
        assert fd.passed, str(fd)


@pytest.mark.parametrize("formulation", ["standard", "mixed"])
def test_gradient_cable_actuation_and_stiffness(formulation):
    alpha, k = 0.7, 2e3
    body = build(formulation, cable=(alpha, k))
    target = tip_target(body)
    g = sf.gradient(body, target, ["cable_actuation", "cable_stiffness", "shear_modulus"], gravity=G, tolerance=TIGHT)
    assert g.gradient["cable_actuation"].shape == (1,)

    def value(t):
        b = build(formulation, mu=t[2], cable=(t[0], t[1]))
        x = sf.solve_static(b, G, tolerance=TIGHT).positions
        return target.bind(b.mesh).misfit(x)[0]

    theta = np.array([alpha, k, 22.76e3])
    fd = check_gradient(value, theta, g.vector, step=1e-5, rtol=1e-5)
    assert fd.passed, str(fd)


def test_gradient_youngs_modulus_poisson_ratio_and_regions():
    E, nu = 66e3, 0.45
    mesh = sf.Mesh.box(size=SIZE, cells=CELLS)
    tip = mesh.points[:, 0] > 0.2
    near = np.array([mesh.points[t, 0].mean() > 0.2 for t in mesh.tets])

    def make(e_far, e_near, nu_all):
        E_e = np.where(near, e_near, e_far)
        body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=E_e, poisson_ratio=np.full(mesh.n_tets, nu_all), density=1080))
        body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
        return body

    target = sf.Target.nodes(np.flatnonzero(tip), mesh.points[tip] - [0, 0, 0.1])
    body = make(E, 1.3 * E, nu)
    names = ["youngs_modulus:far", "youngs_modulus:near", "poisson_ratio"]
    g = sf.gradient(body, target, names, gravity=G, regions={"far": ~near, "near": near}, tolerance=TIGHT)

    def value(t):
        b = make(*t)
        return target.bind(mesh).misfit(sf.solve_static(b, G, tolerance=TIGHT).positions)[0]

    fd = check_gradient(value, np.array([E, 1.3 * E, nu]), g.vector, step=1e-5, rtol=1e-5)
    assert fd.passed, str(fd)


def test_gradient_field_and_callable_objective():
    body = build()
    m = body.mesh.n_tets

    def objective(x):  # mean vertical displacement of all nodes, and its gradient
        grad = np.zeros_like(x)
        grad[:, 2] = 1.0 / len(x)
        return float(x[:, 2].mean()), grad

    g = sf.gradient(body, objective, ["shear_modulus_field"], gravity=G, tolerance=TIGHT)
    assert g.gradient["shear_modulus_field"].shape == (m,)
    mu0 = np.full(m, 22.76e3)

    def value(mu):
        b = build(mu=mu)
        return objective(sf.solve_static(b, G, tolerance=TIGHT).positions)[0]

    fd = check_gradient(value, mu0, g.vector, step=1e-5, rtol=1e-5)
    assert fd.passed, str(fd)


def test_forward_sensitivity_jacobian_matches_adjoint():
    """Least squares builds J from forward sensitivities; J^T r must equal the adjoint gradient."""
    from sorofem.inverse._parameters import Parameters
    from sorofem.inverse._problem import Problem, scenarios

    body = build()
    target = tip_target(body)
    p = Parameters(body, ["shear_modulus", "lame_lambda"])
    problem = Problem(body, p, scenarios(body, target, None, G, sf.SolveOptions(TIGHT, 50, 1)))
    s = p.to_s(p.current())
    r, J = problem.evaluate(s, "jacobian")
    _, grad = problem.evaluate(s, "gradient")
    np.testing.assert_allclose(J.T @ r, grad, rtol=1e-8)
    problem.restore()


# ---------------------------------------------------------------------------
# Estimation


@pytest.fixture(scope="module")
def synthetic():
    """Goal positions of all nodes for the true material (E = 66 kPa, nu = 0.45)."""
    truth = sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080)
    body = build(mu=truth.shear_modulus, lam=truth.lame_lambda)
    goal = sf.solve_static(body, G, tolerance=TIGHT).positions
    return truth, sf.Target.nodes(np.arange(body.mesh.n_nodes), goal)


@pytest.mark.parametrize("formulation", ["standard", "mixed"])
def test_least_squares_recovers_mu_and_lambda(synthetic, formulation):
    truth, target = synthetic
    if formulation == "mixed":
        b = build("mixed", mu=truth.shear_modulus, lam=truth.lame_lambda)
        target = sf.Target.nodes(np.arange(b.mesh.n_nodes), sf.solve_static(b, G, tolerance=TIGHT).positions)
    body = build(formulation, mu=1.0, lam=1.0)  # the body's own material is only a placeholder
    fit = sf.estimate(body, target, ["shear_modulus", "lame_lambda"], x0=[20e3, 0.2e6], gravity=G)
    assert fit.params["shear_modulus"] == pytest.approx(truth.shear_modulus, rel=1e-6)
    assert fit.params["lame_lambda"] == pytest.approx(truth.lame_lambda, rel=1e-6)
    assert fit.youngs_modulus == pytest.approx(66e3, rel=1e-6)
    assert fit.poisson_ratio == pytest.approx(0.45, rel=1e-6)
    assert fit.forward_solves <= 15
    assert fit.residual < 1e-9
    assert fit.converged
    assert [h["loss"] for h in fit.history] == sorted(h["loss"] for h in fit.history)[::-1]
    assert fit.uncertainty is not None and set(fit.uncertainty.identifiable) == {"shear_modulus", "lame_lambda"}
    # The body itself is untouched.
    assert body.material.shear_modulus == 1.0


@pytest.mark.parametrize("method", ["nelder-mead", "l-bfgs-b"])
def test_other_methods_recover_mu_and_lambda(synthetic, method):
    truth, target = synthetic
    body = build()
    fit = sf.estimate(body, target, ["shear_modulus", "lame_lambda"], x0=[20e3, 0.2e6], gravity=G, method=method,
                      ftol=1e-20 if method == "l-bfgs-b" else 1e-12)
    rtol = 1e-6 if method == "nelder-mead" else 1e-5
    assert fit.params["shear_modulus"] == pytest.approx(truth.shear_modulus, rel=rtol)
    assert fit.params["lame_lambda"] == pytest.approx(truth.lame_lambda, rel=rtol)


def test_youngs_poisson_parametrisation_and_bounds(synthetic):
    truth, target = synthetic
    body = build()
    fit = sf.estimate(body, target, ["youngs_modulus", "poisson_ratio"], x0=[50e3, 0.3], gravity=G,
                      bounds=[(1e3, 1e6), (0.01, 0.49)])
    assert fit.params["youngs_modulus"] == pytest.approx(66e3, rel=1e-6)
    assert fit.params["poisson_ratio"] == pytest.approx(0.45, rel=1e-6)
    # An upper bound below the truth is respected.
    capped = sf.estimate(body, target, ["youngs_modulus"], x0=[50e3], gravity=G, bounds=[(1e3, 60e3)])
    assert capped.params["youngs_modulus"] == pytest.approx(60e3, rel=1e-9)


def test_scenarios_multistart_history_and_resume(tmp_path, synthetic):
    truth, _ = synthetic
    body = build(mu=truth.shear_modulus, lam=truth.lame_lambda)
    scenarios = []
    for g in ([0, 0, -9.81], [0, -9.81, 0]):
        goal = sf.solve_static(body, g, tolerance=TIGHT).positions
        tip = body.mesh.nodes_on_plane((0.4, 0, 0), (1, 0, 0))
        scenarios.append({"gravity": g, "target": sf.Target.nodes(tip, goal[tip])})
    path = tmp_path / "history.jsonl"
    fit = sf.estimate(build(), None, ["shear_modulus", "lame_lambda"], x0=[20e3, 0.2e6], scenarios=scenarios,
                      starts=[[40e3, 1e6]], history_path=path)
    assert len(fit.starts) == 2
    assert fit.params["shear_modulus"] == pytest.approx(truth.shear_modulus, rel=1e-6)
    assert len(fit.results) == 2
    lines = [json.loads(line) for line in path.read_text().splitlines()]
    iterates = [e for e in lines if e["kind"] == "iteration"]
    assert lines[0]["kind"] == "header" and len(lines[0]["starts"]) == 2
    assert len(iterates) == len(fit.history) and {e["start"] for e in iterates} == {0, 1}
    assert [e["start"] for e in lines if e["kind"] == "end"] == [0, 1]
    again = sf.estimate(build(), None, ["shear_modulus", "lame_lambda"], scenarios=scenarios,
                        history_path=path, resume=True)
    assert again.forward_solves <= 4  # starts at the optimum
    assert again.params["shear_modulus"] == pytest.approx(truth.shear_modulus, rel=1e-6)


def test_verbose_prints_one_line_per_iteration(synthetic, capsys):
    _, target = synthetic
    fit = sf.estimate(build(), target, ["shear_modulus"], x0=[20e3], gravity=G, verbose=True)
    err = capsys.readouterr().err
    assert err.count("\n") == len(fit.history) and "shear_modulus=" in err


def test_bad_input_is_reported():
    body = build()
    target = tip_target(body)
    with pytest.raises(sf.InputError, match="unknown parameter"):
        sf.estimate(body, target, ["stiffness"])
    with pytest.raises(sf.InputError, match="method"):
        sf.estimate(body, target, ["shear_modulus"], method="newton")
    with pytest.raises(sf.InputError, match="region"):
        sf.estimate(body, target, ["shear_modulus:soft"])
    with pytest.raises(sf.ParameterError):
        sf.estimate(body, target, ["poisson_ratio"], x0=[0.6])


# ---------------------------------------------------------------------------
# Control


def test_control_recovers_actuation_and_reports_unreachable():
    body = build(cable=(1.0, 2e3))
    cable = body.cables[0]
    tip = body.mesh.points[:, 0] > 0.399
    rest = body.mesh.points[tip].mean(axis=0, keepdims=True)
    body.set_actuation(cable, 0.6)
    goal = sf.Target.points(rest, [[0, 0, 0]]).bind(body.mesh).points(sf.solve_static(body, G, tolerance=TIGHT).positions)
    body.set_actuation(cable, 1.0)
    ctl = sf.control(body, sf.Target.points(rest, goal), cables=[cable], bounds=[(0.3, 1.0)], gravity=G)
    assert ctl.reachable and ctl.distance < 1e-6
    assert ctl.actuation[0] == pytest.approx(0.6, rel=1e-4)
    assert body.actuations == [1.0]  # the body is left as it was
    far = sf.control(body, sf.Target.points(rest, goal + [0.5, 0, 0]), cables=[cable], bounds=[(0.3, 1.0)], gravity=G)
    assert not far.reachable and "not reachable" in far.message
    assert far.distance > 0.3


# ---------------------------------------------------------------------------
# The full hammerbot calibration (both formulations, four starts, lambda profile)


@pytest.mark.bench
def test_hammerbot_calibration_full_run(tmp_path, shared_data):
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parent.parent / "examples" / "07_hammerbot_calibration.py"
    spec = importlib.util.spec_from_file_location("example_07_full", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    summary = module.run(tmp_path, quick=False)
    failed = {k: v for k, v in summary["checks"].items() if not v["passed"]}
    assert not failed, failed
