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


# --- fits --------------------------------------------------------------------------------

def _synthetic(model: str, params: dict, modes: tuple[str, ...], stretch: np.ndarray, *, bulk: float | None = None,
               noise: float = 0.0, seed: int = 0) -> list[dict]:
    rng = np.random.default_rng(seed)
    out = []
    for mode in modes:
        stress = nominal_stress(model, mode, stretch, params, bulk_modulus=bulk)
        out.append({"mode": mode, "stretch": stretch,
                    "nominal_stress": stress * (1 + noise * rng.standard_normal(stretch.size))})
    return out


# Which data make each model identifiable (see docs/materials.md): Mooney-Rivlin's two
# coefficients separate with two modes (or a wide uniaxial range); Yeoh's three with a wide
# uniaxial range; Ogden's exponents need two or three modes.
NOISELESS = [
    ("neo_hookean", {"mu": 25e3}, None, ("uniaxial",), np.linspace(1.0, 2.5, 20)),
    ("mooney_rivlin", {"c10": 10e3, "c01": 2.5e3}, None, ("uniaxial", "equibiaxial"), np.linspace(0.7, 2.5, 25)),
    ("mooney_rivlin", {"c10": 10e3, "c01": 2.5e3}, None, ("uniaxial",), np.linspace(1.0, 4.0, 25)),
    ("yeoh", {"c10": 12e3, "c20": -300.0, "c30": 25.0}, 3, ("uniaxial",), np.linspace(1.0, 5.0, 30)),
    ("ogden", {"mu:0": 300.0, "alpha:0": -3.0}, 1, ("uniaxial", "equibiaxial"), np.linspace(0.7, 3.0, 25)),
    ("ogden", {"mu:0": -600.0, "alpha:0": -2.2, "mu:1": 9e3, "alpha:1": 2.6}, 2, MODES, np.linspace(0.6, 4.0, 30)),
    ("ogden", {"mu:0": 1.9e3, "alpha:0": -3.8, "mu:1": 22e3, "alpha:1": 0.66, "mu:2": 3.6e3, "alpha:2": 4.2}, 3, MODES,
     np.linspace(0.5, 4.0, 40)),
]


@pytest.mark.parametrize("model, truth, terms, modes, stretch", NOISELESS)
@pytest.mark.parametrize("bulk", [None, 5e6])
def test_noiseless_fit_recovers_the_parameters(model, truth, terms, modes, stretch, bulk) -> None:
    fit = fit_material(model, _synthetic(model, truth, modes, stretch, bulk=bulk), terms=terms, bulk_modulus=bulk)
    for name, value in truth.items():
        assert fit.params[name] == pytest.approx(value, rel=1e-8), (name, fit.summary())
        assert fit.identifiable[name]
    assert fit.rms_relative < 1e-10
    if bulk is not None and model != "neo_hookean":
        assert fit.params["d1"] == 2 / bulk
    assert json.loads(json.dumps(fit.to_dict(), allow_nan=False))["params"] == fit.params


NOISY = [
    ("mooney_rivlin", {"c10": 10e3, "c01": 2.5e3}, None, ("uniaxial", "equibiaxial"), np.linspace(0.7, 2.5, 40)),
    ("yeoh", {"c10": 12e3, "c20": -300.0, "c30": 25.0}, 3, ("uniaxial", "planar"), np.linspace(1.02, 4.0, 40)),
    ("ogden", {"mu:0": -600.0, "alpha:0": -2.2, "mu:1": 9e3, "alpha:1": 2.6}, 2, MODES, np.linspace(0.6, 3.5, 40)),
]


@pytest.mark.parametrize("model, truth, terms, modes, stretch", NOISY)
def test_noisy_fit_is_within_its_standard_errors(model, truth, terms, modes, stretch) -> None:
    """1 % relative noise: each parameter within 3 standard errors of the truth on every seed,
    and the errors neither vanish nor explode (between 0.05 % and 20 % of the value)."""
    for seed in range(4):
        fit = fit_material(model, _synthetic(model, truth, modes, stretch, noise=0.01, seed=seed), terms=terms)
        for name, value in truth.items():
            err = fit.standard_errors[name]
            assert abs(fit.params[name] - value) <= 3 * err, (seed, name, fit.summary())
            assert 5e-4 * abs(value) < err < 0.2 * abs(value), (seed, name, fit.summary())
        assert 0.005 < fit.rms_relative < 0.02


def test_not_identifiable_parameters_are_flagged() -> None:
    """Planar data see Mooney-Rivlin only through c10 + c01: J^T J is singular."""
    data = _synthetic("mooney_rivlin", {"c10": 10e3, "c01": 2.5e3}, ("planar",), np.linspace(1.0, 3.0, 20))
    fit = fit_material("mooney_rivlin", data)
    assert fit.identifiable == {"c10": False, "c01": False}
    assert math.isinf(fit.standard_errors["c10"]) and math.isinf(fit.condition_number)
    assert fit.shear_modulus == pytest.approx(25e3, rel=1e-10)  # the sum is determined
    out = fit.to_dict()
    assert out["standard_errors"] == {"c10": None, "c01": None} and out["identifiable"] == {"c10": False, "c01": False}
    json.dumps(out, allow_nan=False)
    assert "not identifiable" in fit.summary() and any("not identifiable" in w for w in fit.warnings)


def test_poorly_determined_parameters_warn() -> None:
    """Uniaxial data up to 3 % strain barely separate c10 from c01 (r = -0.9999)."""
    data = _synthetic("mooney_rivlin", {"c10": 10e3, "c01": 2.5e3}, ("uniaxial",), np.linspace(1.0, 1.03, 20),
                      noise=2e-2)
    fit = fit_material("mooney_rivlin", data)
    assert all(fit.identifiable.values()) and fit.condition_number > 1e4
    assert fit.correlation[0, 1] < -0.999
    assert any(w.startswith("c01 is poorly determined") and "correlated with c10" in w for w in fit.warnings), \
        fit.warnings


def test_fixed_parameters_and_x0() -> None:
    truth = {"mu:0": 9e3, "alpha:0": 2.6, "mu:1": -600.0, "alpha:1": -2.2}
    data = _synthetic("ogden", truth, MODES, np.linspace(0.6, 4.0, 30))
    fit = fit_material("ogden", data, terms=2, fixed={"alpha:0": 2.6},
                       x0={"mu:0": 5e3, "mu:1": -100.0, "alpha:1": -1.0})
    assert fit.free == ("mu:0", "mu:1", "alpha:1") and fit.starts == 1
    for name, value in truth.items():
        assert fit.params[name] == pytest.approx(value, rel=1e-8)
    assert "(fixed)" in fit.summary()
    bounded = fit_material("ogden", data, terms=2, bounds={"alpha:1": (2.0, 3.0)})
    assert 2.0 <= bounded.params["alpha:1"] <= 3.0 and bounded.params["alpha:1"] == pytest.approx(2.6, rel=1e-8)
    with pytest.raises(ParameterError, match="bounds leave no non-zero value"):
        fit_material("ogden", data, terms=1, bounds={"alpha:0": (-1e-4, 1e-4)})


def test_unstable_fit_and_implausible_units_warn() -> None:
    """Data beyond the model's Drucker range; stresses given in MPa but read as Pa."""
    params = {"c10": 10e3, "c20": -900.0, "c30": 10.0}
    upper = stable_range("yeoh", "uniaxial", params).upper
    data = _synthetic("yeoh", params, ("uniaxial",), np.linspace(1.0, upper + 0.3, 30))
    fit = fit_material("yeoh", data)
    assert fit.params["c20"] == pytest.approx(-900.0, rel=1e-8)
    assert any("beyond the fit's Drucker-stable range" in w for w in fit.warnings), fit.warnings
    in_mpa = _synthetic("neo_hookean", {"mu": 0.03}, ("uniaxial",), np.linspace(1.0, 2.0, 10))
    assert any("check the stress unit" in w for w in fit_material("neo_hookean", in_mpa).warnings)


def test_weights() -> None:
    data = _synthetic("yeoh", {"c10": 12e3, "c20": -300.0, "c30": 25.0}, ("uniaxial",), np.linspace(1.0, 4.0, 20),
                      noise=0.02, seed=4)
    relative = fit_material("yeoh", data)
    absolute = fit_material("yeoh", data, weights="absolute")
    given = fit_material("yeoh", data, weights=[1 / np.maximum(np.abs(data[0]["nominal_stress"]), 1.0)])
    assert absolute.rms <= relative.rms and relative.rms_relative <= absolute.rms_relative
    assert given.params["c10"] == pytest.approx(relative.params["c10"], rel=1e-3)


def test_summary_rounds_to_the_uncertainty() -> None:
    assert format_uncertain(12345.678, 67.2, "Pa") == "12346 ± 67 Pa"
    assert format_uncertain(-123.456, 4.5) == "-123.5 ± 4.5"
    assert format_uncertain(1.23456e-7, 2.1e-9, "1/Pa") == "(1.235 ± 0.021)e-07 1/Pa"
    assert format_uncertain(123456.0, 1234.0) == "123500 ± 1200"
    assert format_uncertain(300.0, 0.0, "Pa") == "300.0000000 ± <0.0000001 Pa"
    assert format_uncertain(2.5e4, math.inf, "Pa") == "2.5e+04 Pa (not identifiable)"
    data = _synthetic("mooney_rivlin", {"c10": 10e3, "c01": 2.5e3}, ("uniaxial", "equibiaxial"),
                      np.linspace(0.7, 2.5, 30), noise=0.01)
    fit = fit_material("mooney_rivlin", data)
    line = next(l for l in fit.summary().splitlines() if l.strip().startswith("c10"))
    value, err = line.split("=")[1].split("Pa")[0].split("±")
    assert len(err.strip().replace(".", "").lstrip("0")) == 2  # two significant digits of the error
    assert float(value) == pytest.approx(fit.params["c10"], abs=float(err))


def test_plot_has_one_panel_per_mode(tmp_path: Path) -> None:
    from matplotlib.figure import Figure

    data = _synthetic("neo_hookean", {"mu": 25e3}, ("uniaxial", "planar"), np.linspace(1.0, 2.0, 10))
    fit = fit_material("neo_hookean", data)
    fig = fit.plot()
    assert [a.get_title() for a in fig.axes] == ["uniaxial", "planar"]
    fig.savefig(tmp_path / "fit.png")
    assert (tmp_path / "fit.png").stat().st_size > 1000
    other = Figure()
    ax = other.add_subplot()
    assert fit.plot(ax) is other and len(ax.lines) >= 4


def test_docstring_examples_run() -> None:
    import sorofem.fitting as package
    from sorofem.fitting import data as data_module

    for module in (package, fit_module, data_module):
        result = doctest.testmod(module, optionflags=doctest.ELLIPSIS)
        assert result.failed == 0 and result.attempted > 0, module.__name__


# --- bad input ---------------------------------------------------------------------------

GOOD = {"mode": "uniaxial", "stretch": [1.0, 1.5, 2.0, 2.5], "nominal_stress": [0.0, 2e4, 3.5e4, 4.8e4]}


@pytest.mark.parametrize("kwargs, parameter, text", [
    ({"model": "gent"}, "model", "unknown model 'gent'"),
    ({"model": "ogden", "terms": 4}, "terms", "from 1 to 3"),
    ({"model": "ogden", "terms": 0}, "terms", "from 1 to 3"),
    ({"model": "mooney_rivlin", "terms": 2}, "terms", "yeoh and ogden only"),
    ({"model": "ogden", "terms": 1, "fixed": {"alpha:0": 0.0}}, "alpha:0", "must be non-zero"),
    ({"model": "ogden", "terms": 1, "x0": {"mu:0": 1e4, "alpha:0": 0}}, "alpha:0", "must be non-zero"),
    ({"model": "ogden", "terms": 1, "x0": {"mu:0": 1e4}}, "alpha:0", "every fitted Ogden exponent"),
    ({"model": "ogden", "terms": 1, "fixed": {"alpha:1": 2.0}}, "alpha:1", "does not have"),
    ({"model": "yeoh", "fixed": {"d1": 1e-6}}, "d1", "bulk_modulus"),
    ({"model": "yeoh", "bulk_modulus": -1.0}, "bulk_modulus", "> 0"),
    ({"model": "yeoh", "bulk_modulus": "stiff"}, "bulk_modulus", "a number"),
    ({"model": "yeoh", "fixed": {"c10": float("nan")}}, "c10", "finite"),
    ({"model": "yeoh", "weights": "squared"}, "weights", "'relative', 'absolute'"),
    ({"model": "yeoh", "weights": [[1.0, 1.0]]}, "weights", "4 finite positive"),
    ({"model": "yeoh", "bounds": {"c10": (1.0, 0.0)}}, "c10", "below upper"),
    ({"model": "yeoh", "terms": 3, "data": [dict(GOOD, stretch=[1.0, 1.5, 2.0], nominal_stress=[0, 1, 2])]},
     "data", "more than 3 data points"),
    ({"model": "neo_hookean", "fixed": {"mu": 1e4}}, "fixed", "nothing to fit"),
])
def test_bad_arguments_name_the_parameter(kwargs: dict, parameter: str, text: str) -> None:
    kwargs = dict(kwargs)
    data = kwargs.pop("data", [GOOD])
    with pytest.raises(ParameterError, match=text) as info:
        fit_material(kwargs.pop("model"), data, **kwargs)
    assert info.value.parameter == parameter


@pytest.mark.parametrize("curve, text", [
    (dict(GOOD, stretch=[1.0, 1.5, 1.4, 2.5]), r"data\[0\]\[2\]: stretch: stretch must be strictly monotone"),
    (dict(GOOD, stretch=[1.0, 1.5, 1.5, 2.5]), r"data\[0\]\[2\]: stretch: stretch must be strictly monotone"),
    (dict(GOOD, nominal_stress=[0.0, float("nan"), 3e4, 4e4]), r"data\[0\]\[1\]: nominal_stress: value nan"),
    (dict(GOOD, stretch=[-1.0, 1.5, 2.0, 2.5]), r"stretch must be > 0"),
    (dict(GOOD, mode="shear"), r"unknown test mode 'shear'"),
    (dict(GOOD, nominal_stress=[0.0, -2e4, -3e4, -4e4]), r"wrong sign"),
    ({"mode": "uniaxial", "stretch": [1.0, 2.0]}, r"lacks nominal_stress"),
    (dict(GOOD, stress=[1, 2]), r"unknown keys \['stress'\]"),
])
def test_bad_arrays_name_the_point(curve: dict, text: str) -> None:
    with pytest.raises(InputError, match=text):
        fit_material("neo_hookean", [GOOD, curve] if "lacks" in text or "unknown keys" in text else curve)


def test_nominal_stress_rejects_bad_parameters() -> None:
    with pytest.raises(ParameterError, match="alpha:0 = 0") as info:
        nominal_stress("ogden", "uniaxial", [1.5], {"mu:0": 1e4, "alpha:0": 0.0})
    assert info.value.parameter == "alpha:0"
    with pytest.raises(ParameterError, match="has no parameter c02"):
        nominal_stress("mooney_rivlin", "uniaxial", [1.5], {"c10": 1e4, "c02": 1.0})
    with pytest.raises(ParameterError, match="disagrees with d1"):
        nominal_stress("yeoh", "uniaxial", [1.5], {"c10": 1e4, "d1": 1e-6}, bulk_modulus=1e7)
    with pytest.raises(ParameterError, match="unknown test mode"):
        nominal_stress("yeoh", "torsion", [1.5], {"c10": 1e4})
    with pytest.raises(ParameterError, match="stretch"):
        nominal_stress("yeoh", "uniaxial", [0.0, 1.5], {"c10": 1e4})


# --- CSV files ---------------------------------------------------------------------------

def _write(tmp_path: Path, text: str, name: str = "data.csv") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def test_read_curve_units_strain_and_separators(tmp_path: Path) -> None:
    base = "# a tensile test\n# mode: uniaxial\n"
    a = read_curve(_write(tmp_path, base + "time,stretch,nominal_stress [kPa]\n0,1.0,0\n1,1.5,20\n2,2.0,35\n"))
    assert a.mode == "uniaxial" and a.nominal_stress.tolist() == [0.0, 20e3, 35e3] and a.lines == (4, 5, 6)
    b = read_curve(_write(tmp_path, "# stress_unit: MPa\nstrain [%];nominal_stress\n0;0\n50;0.02\n100;0.035\n"),
                   mode="uniaxial")
    np.testing.assert_allclose(b.stretch, [1.0, 1.5, 2.0])
    np.testing.assert_allclose(b.nominal_stress, [0.0, 20e3, 35e3])
    c = read_curve(_write(tmp_path, "stretch\tnominal_stress\n1.0\t0\n0.8\t-20\n0.6\t-50\n"), mode="equibiaxial",
                   stress_unit="psi")
    assert c.nominal_stress[1] == pytest.approx(-20 * 6894.757293168361)
    d = read_curve(_write(tmp_path, "\ufeffstretch,nominal_stress\n1.0,0\n2.0,3e4\n"), mode="planar")
    assert d.nominal_stress.tolist() == [0.0, 3e4]  # Pa by default, BOM ignored


@pytest.mark.parametrize("text, line, message", [
    ("1.0,0\n1.5,2\n", 1, "the header line is missing"),
    ("stretch,stress\n1.0,0\n1.5,2\n", 1, "missing column 'nominal_stress'; found 'stretch', 'stress'"),
    ("lambda,nominal_stress\n1.0,0\n1.5,2\n", 1, "missing column 'stretch' \\(or 'strain'\\)"),
    ("stretch,nominal_stress\n1.0,0\n1.5,abc\n2.0,3\n", 3, "column 'nominal_stress': 'abc' is not a number"),
    ("stretch,nominal_stress\n1.0,0\n1.5,nan\n2.0,3\n", 3, "column 'nominal_stress': value nan"),
    ("stretch,nominal_stress\n1.0,0\n1.5,2\n1.4,3\n2.0,4\n", 4, "strictly monotone"),
    ("stretch,nominal_stress\n1.0,0\n1.5\n", 3, "1 fields, but the header \\(line 1\\) has 2"),
    ("stretch,nominal_stress\n1.0,0\n0.8,20\n0.6,40\n", 3, "wrong sign"),
    ("stretch,nominal_stress [bar]\n1.0,0\n1.5,2\n", 1, "unknown stress unit 'bar'"),
    ("# stress_unit: kPa\nstretch,nominal_stress [MPa]\n1.0,0\n1.5,2\n", 1, "disagrees with the unit of column"),
    ("# mode: torsion\nstretch,nominal_stress\n1.0,0\n1.5,2\n", 1, "unknown test mode 'torsion'"),
    ("stretch,nominal_stress\n1.0,0\n", None, "at least 2 data lines"),
    ("# only comments\n", None, "no header line"),
])
def test_bad_files_name_file_and_line(tmp_path: Path, text: str, line: int | None, message: str) -> None:
    path = _write(tmp_path, text)
    with pytest.raises(DataFileError, match=message) as info:
        read_curve(path, mode="uniaxial")
    assert info.value.line == line and str(info.value).startswith(f"{path}:" + (f"{line}:" if line else ""))


def test_mode_from_file_or_argument(tmp_path: Path) -> None:
    path = _write(tmp_path, "# mode: planar\nstretch,nominal_stress\n1.0,0\n1.5,2\n")
    assert read_curve(path, mode="uniaxial").mode == "planar"  # the file's own line wins
    bare = _write(tmp_path, "stretch,nominal_stress\n1.0,0\n1.5,2\n", "bare.csv")
    with pytest.raises(DataFileError, match="test mode unknown"):
        read_curve(bare)
    with pytest.raises(DataFileError, match="disagrees with the unit the file declares"):
        read_curve(_write(tmp_path, "stretch,nominal_stress [kPa]\n1.0,0\n1.5,2\n", "k.csv"), mode="uniaxial",
                   stress_unit="Pa")
    fit = fit_material("neo_hookean", [str(path), bare], mode="uniaxial")
    assert [c.mode for c in fit.curves] == ["planar", "uniaxial"]


# --- command line ------------------------------------------------------------------------

def _csv(tmp_path: Path, mode: str, model: str, params: dict, name: str, unit: str = "kPa") -> Path:
    stretch = np.linspace(1.0, 3.0, 15) if mode != "equibiaxial" else np.linspace(1.0, 2.0, 15)
    stress = nominal_stress(model, mode, stretch, params) / {"kPa": 1e3, "Pa": 1.0}[unit]
    rows = "\n".join(f"{s:.12g},{p:.12g}" for s, p in zip(stretch, stress))
    return _write(tmp_path, f"# mode: {mode}\nstretch,nominal_stress [{unit}]\n{rows}\n", name)


def test_cli_fits_and_writes_json_and_png(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    truth = {"c10": 12e3, "c20": -300.0, "c30": 25.0}
    files = [_csv(tmp_path, "uniaxial", "yeoh", truth, "ut.csv"), _csv(tmp_path, "equibiaxial", "yeoh", truth, "eb.csv")]
    out = tmp_path / "out"
    assert _cli([str(f) for f in files] + ["--model", "yeoh", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "yeoh fit (incompressible, 3 terms) to 2 curve(s), 30 points" in printed and "c20 = -300.0000" in printed
    result = json.loads((out / "fit.json").read_text())
    assert result["params"]["c10"] == pytest.approx(12e3, rel=1e-9) and result["incompressible"] is True
    assert [d["mode"] for d in result["data"]] == ["uniaxial", "equibiaxial"]
    assert (out / "fit.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert sorted(p.name for p in out.iterdir()) == ["fit.json", "fit.png"]  # no temporary left behind


def test_cli_compressible_with_mode_flag(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    stretch = np.linspace(1.0, 2.5, 12)
    stress = nominal_stress("mooney_rivlin", "uniaxial", stretch, {"c10": 1e4, "c01": 2e3}, bulk_modulus=2e6)
    path = _write(tmp_path, "stretch,nominal_stress\n" + "\n".join(f"{float(s)!r},{float(p)!r}" for s, p in zip(stretch, stress)))
    code = _cli([str(path), "--model", "mooney_rivlin", "--mode", "uniaxial", "--bulk-modulus", "2e6", "--out",
                 str(tmp_path), "--quiet"])
    assert code == 0 and capsys.readouterr().out == ""
    result = json.loads((tmp_path / "fit.json").read_text())
    assert result["params"]["c01"] == pytest.approx(2e3, rel=1e-7) and result["params"]["d1"] == 1e-6


@pytest.mark.parametrize("argv, message", [
    (["missing.csv", "--model", "yeoh"], "No such file or directory"),
    (["{bad}", "--model", "yeoh"], "{bad}:4: column 'nominal_stress': 'x' is not a number"),
    (["{good}", "--model", "gent"], "invalid choice: 'gent'"),
    (["{good}", "--model", "ogden", "--terms", "5"], "terms must be an integer from 1 to 3"),
    (["{good}"], "the following arguments are required: --model"),
    (["{good}", "--model", "yeoh", "--stress-unit", "bar"], "unknown stress unit 'bar'"),
])
def test_cli_bad_input_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture, argv: list, message: str) -> None:
    good = _csv(tmp_path, "uniaxial", "neo_hookean", {"mu": 1e4}, "good.csv", unit="Pa")
    bad = _write(tmp_path, "# mode: uniaxial\nstretch,nominal_stress\n1.0,0\n1.5,x\n", "bad.csv")
    argv = [a.format(good=good, bad=bad) for a in argv] + ["--out", str(tmp_path / "out")]
    assert _cli(argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and message.format(bad=bad) in err and "Traceback" not in err


def test_cli_never_overwrites_an_input(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    data = _csv(tmp_path, "uniaxial", "neo_hookean", {"mu": 1e4}, "fit.json")
    before = data.read_bytes()
    assert _cli([str(data), "--model", "neo_hookean", "--out", str(tmp_path)]) == 2
    assert "is an input file" in capsys.readouterr().err and data.read_bytes() == before


def test_cli_non_convergence_exits_3(tmp_path: Path, capsys: pytest.CaptureFixture,
                                     monkeypatch: pytest.MonkeyPatch) -> None:
    """Two evaluations cannot take the compressible fit from its incompressible start."""
    monkeypatch.setattr(fit_module, "_MAX_NFEV", 2)
    data = _csv(tmp_path, "uniaxial", "yeoh", {"c10": 1e4, "c20": 100.0}, "ut.csv")
    argv = [str(data), "--model", "yeoh", "--bulk-modulus", "1e5", "--out", str(tmp_path / "out")]
    assert _cli(argv) == 3
    err = capsys.readouterr().err
    assert "did not converge" in err and "weighted cost of the last evaluations" in err
    assert not (tmp_path / "out").exists()
    with pytest.raises(ConvergenceError) as info:
        fit_material("yeoh", str(data), bulk_modulus=1e5)
    assert info.value.report["history"]
