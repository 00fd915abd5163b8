"""sorofem.fitting: homogeneous test curves, their derivatives, the fits and the CLI.

The curves are checked against closed forms written here from the energies of issue 15 and
against finite differences of those energies; every derivative goes through tests/fdcheck.py.
"""

from __future__ import annotations

import doctest
import json
import math
from pathlib import Path

import numpy as np
import pytest

from fdcheck import check_gradient, check_jacobian
from sorofem.errors import ConvergenceError, InputError, ParameterError
from sorofem.fitting import (DataFileError, fit_material, format_uncertain, lateral_stretch, model_spec,
                             nominal_stress, nominal_stress_param_gradient, read_curve, stable_range)
from sorofem.fitting import _cli
from sorofem.fitting import curves as curves_module
from sorofem.fitting import fit as fit_module
from sorofem.fitting.models import kirchhoff

MODES = ("uniaxial", "equibiaxial", "planar")
# One parameter set per model, in the ranges silicones are fitted with (Pa, 1/Pa).
PARAMS = {
    "neo_hookean": {"mu": 25e3},
    "mooney_rivlin": {"c10": 10e3, "c01": 2.5e3},
    "yeoh": {"c10": 12e3, "c20": -300.0, "c30": 25.0},
    "ogden": {"mu:0": 9e3, "alpha:0": 2.6, "mu:1": -600.0, "alpha:1": -2.2},
}
BULK = 3e6  # K / mu ~ 100..300: nu ~ 0.497


def _theta(model: str, params: dict, bulk: float | None) -> tuple:
    spec = model_spec(model, 2 if model == "ogden" else None)
    theta = np.array([params.get(n, 0.0) for n in spec.param_names])
    if bulk is not None and "d1" in spec.param_names:
        theta[spec.param_names.index("d1")] = 2.0 / bulk
    return spec, theta


def _energy(model: str, params: dict, lam: np.ndarray, bulk: float | None) -> np.ndarray:
    """W at principal stretches ``lam`` (n, 3), written straight from issue 15's definitions."""
    j = lam.prod(axis=1)
    if model == "neo_hookean":
        mu = params["mu"]
        w = mu / 2 * ((lam**2).sum(axis=1) - 3)
        if bulk is not None:
            lame = bulk - 2 * mu / 3
            w += -mu * np.log(j) + lame / 2 * np.log(j) ** 2
        return w
    bar = lam * j[:, None] ** (-1 / 3)
    i1 = (bar**2).sum(axis=1)
    i2 = (bar[:, 0] * bar[:, 1]) ** 2 + (bar[:, 1] * bar[:, 2]) ** 2 + (bar[:, 0] * bar[:, 2]) ** 2
    if model == "mooney_rivlin":
        w = params["c10"] * (i1 - 3) + params["c01"] * (i2 - 3)
    elif model == "yeoh":
        w = sum(params.get(f"c{i}0", 0.0) * (i1 - 3) ** i for i in (1, 2, 3))
    else:
        w = sum(2 * params[f"mu:{p}"] / params[f"alpha:{p}"] ** 2 * ((bar ** params[f"alpha:{p}"]).sum(axis=1) - 3)
                for p in range(2))
    if bulk is not None:
        w = w + (j - 1) ** 2 / (2.0 / bulk)
    return w


def _closed_form(model: str, mode: str, lam: np.ndarray) -> np.ndarray:
    """Incompressible nominal stresses by the textbook formulas (Ogden, Non-linear elastic deformations)."""
    p = PARAMS[model]
    lat = {"uniaxial": lam**-0.5, "equibiaxial": lam**-2.0, "planar": lam**-1.0}[mode]
    if model == "ogden":
        return sum(2 * p[f"mu:{k}"] / p[f"alpha:{k}"] * (lam ** p[f"alpha:{k}"] - lat ** p[f"alpha:{k}"])
                   for k in range(2)) / lam
    if model == "neo_hookean":
        w1, w2 = p["mu"] / 2 + 0 * lam, 0 * lam
    elif model == "mooney_rivlin":
        w1, w2 = p["c10"] + 0 * lam, p["c01"] + 0 * lam
    else:
        i1 = {"uniaxial": lam**2 + 2 / lam, "equibiaxial": 2 * lam**2 + lam**-4, "planar": lam**2 + 1 + lam**-2}[mode]
        w1, w2 = p["c10"] + 2 * p["c20"] * (i1 - 3) + 3 * p["c30"] * (i1 - 3) ** 2, 0 * lam
    if mode == "uniaxial":
        return 2 * (lam - lam**-2) * (w1 + w2 / lam)
    if mode == "equibiaxial":
        return 2 * (lam - lam**-5) * (w1 + lam**2 * w2)
    return 2 * (lam - lam**-3) * (w1 + w2)


STRETCH = np.array([0.55, 0.8, 0.97, 1.0, 1.02, 1.4, 2.2, 3.5])


# --- curves ------------------------------------------------------------------------------

@pytest.mark.parametrize("model", PARAMS)
@pytest.mark.parametrize("mode", MODES)
def test_incompressible_curves_match_closed_forms(model: str, mode: str) -> None:
    got = nominal_stress(model, mode, STRETCH, PARAMS[model])
    want = _closed_form(model, mode, STRETCH)
    np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-9)
    assert abs(got[STRETCH == 1.0][0]) <= 1e-15 * np.abs(want).max()  # the rest state is stress free


@pytest.mark.parametrize("model", PARAMS)
@pytest.mark.parametrize("bulk", [None, BULK])
def test_kirchhoff_stress_is_the_energy_derivative(model: str, bulk: float | None) -> None:
    """tau_i = dW/d(ln lambda_i) by central differences of the energy written from its definition;
    incompressible, only the pressure-free differences tau_i - tau_3 along J = 1."""
    spec, theta = _theta(model, PARAMS[model], bulk)
    rng = np.random.default_rng(3)
    for eps in rng.uniform(-0.6, 0.8, size=(6, 3)):
        if bulk is None:
            eps = eps - eps.mean()
        tau = kirchhoff(spec, theta, eps[None, :], bulk)[0][0]
        for i in range(3):
            direction = np.zeros(3)
            direction[i] = 1.0
            if bulk is None:
                direction[2] -= 1.0
                if i == 2:
                    continue
            check = check_gradient(lambda e: float(_energy(model, PARAMS[model], np.exp(e)[None, :], bulk)[0]),
                                   eps, tau, direction=direction, step=1e-5, rtol=1e-7)
            assert check.passed, f"{model} tau_{i}: {check}"


@pytest.mark.parametrize("model", PARAMS)
@pytest.mark.parametrize("bulk", [None, BULK])
def test_kirchhoff_tangent_and_parameter_derivatives(model: str, bulk: float | None) -> None:
    spec, theta = _theta(model, PARAMS[model], bulk)
    eps = np.random.default_rng(5).uniform(-0.5, 0.7, size=(7, 3))
    if bulk is None:
        eps -= eps.mean(axis=1, keepdims=True)
    tau, dtau, dtheta = kirchhoff(spec, theta, eps, bulk)
    block = np.zeros((eps.size, eps.size))
    for n in range(eps.shape[0]):
        block[3 * n:3 * n + 3, 3 * n:3 * n + 3] = dtau[n]
    for seed in range(3):
        direction = np.random.default_rng(seed).uniform(-1, 1, size=eps.shape)
        if bulk is None:
            direction -= direction.mean(axis=1, keepdims=True)
        check = check_jacobian(lambda e: kirchhoff(spec, theta, e.reshape(-1, 3), bulk)[0].ravel(), eps.ravel(),
                               block, direction=direction.ravel(), step=1e-5, rtol=1e-8)
        assert check.passed, str(check)
    free = np.array([not (n.startswith("d") and v == 0) for n, v in zip(spec.param_names, theta)])
    direction = np.where(free, np.random.default_rng(7).uniform(-1, 1, theta.size) * np.abs(theta), 0.0)
    check = check_jacobian(lambda t: kirchhoff(spec, t, eps, bulk)[0].ravel(), theta,
                           dtheta.reshape(-1, theta.size), direction=direction, step=1e-5, rtol=1e-8)
    assert check.passed, str(check)


@pytest.mark.parametrize("model", PARAMS)
@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("bulk", [None, BULK])
def test_curve_parameter_derivatives(model: str, mode: str, bulk: float | None) -> None:
    """dP/dtheta of every coefficient (compressible: through the lateral solve) by central differences."""
    spec, theta = _theta(model, PARAMS[model], bulk)
    grad = nominal_stress_param_gradient(model, mode, STRETCH, PARAMS[model], terms=spec.terms if model == "ogden"
                                         else None, bulk_modulus=bulk)
    jac = np.column_stack([grad[n] for n in spec.param_names])
    live = np.array([not (n.startswith("d") and v == 0) for n, v in zip(spec.param_names, theta)])
    for seed in range(2):
        direction = np.where(live, np.random.default_rng(seed).uniform(-1, 1, theta.size) * np.abs(theta), 0.0)
        check = check_jacobian(lambda t: curves_module.nominal_stress(spec, t, mode, STRETCH, bulk)[0], theta, jac,
                               direction=direction, step=1e-5, rtol=1e-7)
        assert check.passed, str(check)


@pytest.mark.parametrize("model", PARAMS)
@pytest.mark.parametrize("mode", MODES)
def test_lateral_stretch_solve(model: str, mode: str) -> None:
    """Newton's lateral stretch frees the lateral faces to 1e-10 of the stress scale; its
    derivative d tau_3 / d ln t and its parameter derivative are checked by central differences."""
    spec, theta = _theta(model, PARAMS[model], BULK)
    log_t, tau3, dtau3 = curves_module.lateral_log_stretch(spec, theta, mode, STRETCH, BULK)
    tau = kirchhoff(spec, theta, curves_module._log_stretches(mode, np.log(STRETCH), log_t), BULK)[0]
    assert np.all(np.abs(tau[:, 2]) <= 1e-10 * np.maximum(np.abs(tau[:, 0]), 1.0)), tau[:, 2] / tau[:, 0]
    if mode == "uniaxial":
        np.testing.assert_allclose(tau[:, 1], tau[:, 2], rtol=0, atol=1e-10 * np.abs(tau[:, 0]).max())

    def tau3_of(s: np.ndarray) -> np.ndarray:
        return kirchhoff(spec, theta, curves_module._log_stretches(mode, np.log(STRETCH), s), BULK)[0][:, 2]

    check = check_jacobian(tau3_of, log_t, np.diag(dtau3), direction=np.linspace(-1, 1, STRETCH.size),
                           step=1e-6, rtol=1e-7)
    assert check.passed, str(check)
    dtheta = kirchhoff(spec, theta, curves_module._log_stretches(mode, np.log(STRETCH), log_t), BULK)[2][:, 2, :]
    ds = -dtheta / dtau3[:, None]
    live = np.array([not (n.startswith("d") and v == 0) for n, v in zip(spec.param_names, theta)])
    direction = np.where(live, np.random.default_rng(1).uniform(-1, 1, theta.size) * np.abs(theta), 0.0)
    check = check_jacobian(lambda t: curves_module.lateral_log_stretch(spec, t, mode, STRETCH, BULK)[0], theta, ds,
                           direction=direction, step=1e-5, rtol=1e-6)
    assert check.passed, str(check)
    np.testing.assert_allclose(lateral_stretch(model, mode, STRETCH, PARAMS[model], bulk_modulus=BULK), np.exp(log_t))


@pytest.mark.parametrize("model", PARAMS)
@pytest.mark.parametrize("mode", MODES)
def test_large_bulk_modulus_approaches_the_incompressible_curve(model: str, mode: str) -> None:
    incompressible = nominal_stress(model, mode, STRETCH, PARAMS[model])
    mu = {"neo_hookean": 25e3, "mooney_rivlin": 25e3, "yeoh": 24e3, "ogden": 8.4e3}[model]
    gaps = []
    for ratio in (1e4, 1e5, 1e6):
        p = nominal_stress(model, mode, STRETCH, PARAMS[model], bulk_modulus=ratio * mu)
        gaps.append(np.max(np.abs(p - incompressible) / np.maximum(np.abs(incompressible), mu * 1e-2)))
    assert gaps[-1] < 1e-4, gaps
    assert 5 < gaps[0] / gaps[1] < 20 and 5 < gaps[1] / gaps[2] < 20, gaps  # O(mu/K)
    np.testing.assert_allclose(lateral_stretch(model, mode, STRETCH, PARAMS[model], bulk_modulus=1e6 * mu),
                               curves_module.incompressible_lateral(mode, STRETCH), rtol=1e-4)


@pytest.mark.parametrize("model", PARAMS)
def test_small_strain_moduli(model: str) -> None:
    """Uniaxial slope at rest: 3 mu incompressible, E = 9 K mu / (3 K + mu) compressible, with
    mu = 2 (c10 + c01), 2 c10, sum mu_p, mu."""
    spec, theta = _theta(model, PARAMS[model], None)
    mu = fit_module.small_strain_moduli(spec, theta, None)[0]
    assert mu == pytest.approx({"neo_hookean": 25e3, "mooney_rivlin": 25e3, "yeoh": 24e3, "ogden": 8.4e3}[model])
    h = 1e-6
    for bulk, slope in ((None, 3 * mu), (BULK, 9 * BULK * mu / (3 * BULK + mu))):
        p = nominal_stress(model, "uniaxial", [1 - h, 1 + h], PARAMS[model], bulk_modulus=bulk)
        assert (p[1] - p[0]) / (2 * h) == pytest.approx(slope, rel=1e-7)


def test_drucker_tangent_is_the_log_strain_hessian() -> None:
    """D of the Drucker check equals the Hessian of W(eps1, eps2, -eps1 - eps2) by differences."""
    model, params = "yeoh", {"c10": 10e3, "c20": -900.0, "c30": 30.0}
    spec, theta = _theta(model, params, None)
    for mode, lam in (("uniaxial", 1.7), ("equibiaxial", 0.8), ("planar", 2.4)):
        log_lam = np.log(lam)
        eps = curves_module._log_stretches(mode, np.array([log_lam]), np.array([curves_module._INCOMPRESSIBLE[mode]
                                                                                 * log_lam]))[0]

        def w(e12: np.ndarray) -> float:
            e = np.array([e12[0], e12[1], -e12[0] - e12[1]])
            return float(_energy(model, params, np.exp(e)[None, :], None)[0])

        h = 1e-4
        hess = np.empty((2, 2))
        for i in range(2):
            for j in range(2):
                ei, ej = np.eye(2)[i] * h, np.eye(2)[j] * h
                hess[i, j] = (w(eps[:2] + ei + ej) - w(eps[:2] + ei - ej) - w(eps[:2] - ei + ej)
                              + w(eps[:2] - ei - ej)) / (4 * h * h)
        smallest = curves_module.drucker_eigenvalue(spec, theta, mode, np.array([lam]))[0]
        assert smallest == pytest.approx(np.linalg.eigvalsh(hess)[0], rel=1e-5, abs=1e-6 * np.abs(hess).max())


def test_drucker_range() -> None:
    """A Yeoh model with a strongly negative c20 loses stability where D stops being positive
    definite; inside, the true stress lambda P rises with ln lambda (what D > 0 implies along the
    uniaxial path; the nominal stress may peak earlier, as it does here)."""
    params = {"c10": 10e3, "c20": -900.0, "c30": 10.0}
    rng = stable_range("yeoh", "uniaxial", params)
    spec, theta = _theta("yeoh", params, None)
    assert rng.upper_reached and 1.5 < rng.upper < 4.0
    assert abs(curves_module.drucker_eigenvalue(spec, theta, "uniaxial", np.array([rng.upper]))[0]) < 1e-6 * 20e3
    assert curves_module.drucker_eigenvalue(spec, theta, "uniaxial", np.array([rng.upper * 1.01]))[0] < 0
    inside = np.geomspace(rng.lower, rng.upper, 200)[1:-1]
    assert np.all(np.diff(inside * nominal_stress("yeoh", "uniaxial", inside, params)) > 0)
    beyond = np.geomspace(rng.upper, 2 * rng.upper, 50)[1:]
    assert np.diff(beyond * nominal_stress("yeoh", "uniaxial", beyond, params))[0] < 0
    whole = stable_range("neo_hookean", "equibiaxial", {"mu": 1e4})
    assert (whole.lower, whole.upper, whole.lower_reached, whole.upper_reached) == (0.1, 10.0, False, False)
    assert stable_range("mooney_rivlin", "planar", {"c10": -1e3, "c01": 200.0}) is None
