"""What sf.estimate reports beside the optimum: parameters at a bound (no interior covariance),
standard errors in every form of the material, the profile of the misfit along a poorly
determined parameter, the readable summary, and fit.png / profile.png."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import sorofem as sf
from sorofem.cli import main
from sorofem.fitting import format_uncertain

G = (0.0, 0.0, -9.81)
TRUTH = sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080)
NOISE = 2e-4  # m, standard deviation of the synthetic marker noise


def build(material: sf.NeoHookean = TRUTH) -> sf.Body:
    mesh = sf.Mesh.box(size=(0.4, 0.1, 0.1), cells=(4, 2, 2))
    body = sf.Body(mesh, material)
    body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    return body


@pytest.fixture(scope="module")
def noisy() -> sf.Target:
    """The free half of the beam, observed with Gaussian noise (seeded)."""
    body = build()
    goal = sf.solve_static(body, G, tolerance=1e-12).positions
    nodes = np.flatnonzero(body.mesh.points[:, 0] >= 0.2)
    rng = np.random.default_rng(7)
    return sf.Target.nodes(nodes, goal[nodes] + rng.normal(0.0, NOISE, (nodes.size, 3)))


def test_a_parameter_on_its_bound_gets_no_standard_error(noisy):
    """lambda capped below the truth ends on its bound: reported "upper", no standard error,
    and mu's is the one with lambda held there, which is what a fit of mu alone at that
    lambda gives."""
    cap = 0.5 * TRUTH.lame_lambda
    fit = sf.estimate(build(), noisy, ["shear_modulus", "lame_lambda"], x0=[20e3, 0.1e6], gravity=G,
                      bounds=[(1e3, 1e6), (1e3, cap)], profile=False)
    unc = fit.uncertainty
    assert fit.params["lame_lambda"] == pytest.approx(cap, rel=1e-12)
    assert unc.at_bound == {"shear_modulus": None, "lame_lambda": "upper"}
    assert math.isnan(unc.std[1]) and not unc.identifiable["lame_lambda"]
    assert np.isnan(unc.covariance[1]).all() and np.isnan(unc.covariance[:, 1]).all()
    held = build(sf.NeoHookean(shear_modulus=20e3, lame_lambda=cap, density=1080))
    alone = sf.estimate(held, noisy, ["shear_modulus"], x0=[20e3], gravity=G)
    assert fit.params["shear_modulus"] == pytest.approx(alone.params["shear_modulus"], rel=1e-6)
    assert unc.std[0] == pytest.approx(alone.uncertainty.std[0], rel=1e-4)
    text = fit.summary()
    assert "at its upper bound (no standard error" in text
    assert format_uncertain(fit.params["shear_modulus"], unc.std[0], "Pa") in text


def test_errors_in_every_form_agree_between_parametrisations(noisy):
    """The standard errors of (E, nu) propagated from a (mu, lambda) fit equal those of an
    (E, nu) fit of the same data, and the other way round (one optimum, two coordinates)."""
    lame = sf.estimate(build(), noisy, ["shear_modulus", "lame_lambda"], x0=[20e3, 0.3e6], gravity=G, profile=False)
    young = sf.estimate(build(), noisy, ["youngs_modulus", "poisson_ratio"], x0=[50e3, 0.3], gravity=G,
                        bounds=[(1e3, 1e6), (0.01, 0.499)], profile=False)
    assert lame.youngs_modulus == pytest.approx(young.youngs_modulus, rel=1e-6)
    a, b = lame.uncertainty.material_std, young.uncertainty.material_std
    assert set(a) == set(b) == {"shear_modulus", "lame_lambda", "youngs_modulus", "poisson_ratio"}
    for name in a:
        assert a[name] == pytest.approx(b[name], rel=2e-3), name
    assert a["shear_modulus"] == pytest.approx(lame.uncertainty.std[0], rel=1e-6)
    # The data (2e-4 m noise on 0.2 m of beam) pin E to about a percent.
    assert a["youngs_modulus"] / lame.youngs_modulus < 0.02
    assert abs(lame.youngs_modulus - 66e3) < 4 * a["youngs_modulus"]


def test_profile_interval_matches_the_linear_one_where_the_problem_is_linear(noisy):
    """A well-determined parameter: the likelihood-ratio interval is close to +-1.96 standard
    errors, and the profile's lowest point is the fit."""
    fit = sf.estimate(build(), noisy, ["shear_modulus", "lame_lambda"], x0=[20e3, 0.3e6], gravity=G,
                      profile="shear_modulus")
    prof, std = fit.profile, fit.uncertainty.std[0]
    mu = fit.params["shear_modulus"]
    assert prof.name == "shear_modulus" and set(prof.params) == {"lame_lambda"}
    assert np.all(np.isfinite(prof.loss))
    best = int(np.argmin(prof.loss))
    assert prof.values[best] == pytest.approx(mu, rel=1e-12) and prof.loss[best] == pytest.approx(fit.loss, rel=1e-6)
    # The automatic grid: four standard errors either side, in 9 points.
    assert prof.values[0] == pytest.approx(mu * math.exp(-4 * std / mu), rel=1e-9)
    assert prof.values[-1] == pytest.approx(mu * math.exp(4 * std / mu), rel=1e-9)
    lo, hi = prof.interval
    assert prof.closed == (True, True) and lo < mu < hi
    assert hi - lo == pytest.approx(2 * 1.96 * std, rel=0.05)
    assert prof.forward_solves > 0 and fit.forward_solves > prof.forward_solves


def test_profile_at_given_values_and_the_automatic_choice(noisy):
    values = TRUTH.lame_lambda * np.array([0.25, 0.5, 1.0, 2.0, 4.0])
    fit = sf.estimate(build(), noisy, ["shear_modulus", "lame_lambda"], x0=[20e3, 0.3e6], gravity=G,
                      profile="lame_lambda", profile_values=values)
    prof = fit.profile
    np.testing.assert_allclose(prof.values, values, rtol=1e-12)
    # Each point is a fit of mu with lambda held: the re-fitted mu moves against lambda.
    mu = prof.params["shear_modulus"]
    assert np.all(np.diff(mu) < 0)
    for value, m, loss in zip(values[[0, -1]], mu[[0, -1]], prof.loss[[0, -1]]):
        held = build(sf.NeoHookean(shear_modulus=20e3, lame_lambda=value, density=1080))
        alone = sf.estimate(held, noisy, ["shear_modulus"], x0=[20e3], gravity=G)
        assert m == pytest.approx(alone.params["shear_modulus"], rel=1e-5)
        assert loss == pytest.approx(alone.loss, rel=1e-6)
    assert "profile of lambda over" in fit.summary()
    # None (default): no profile for a single parameter, nor for a well-conditioned pair.
    single = sf.estimate(build(), noisy, ["shear_modulus"], x0=[20e3], gravity=G)
    assert single.profile is None
    auto = sf.estimate(build(), noisy, ["shear_modulus", "lame_lambda"], x0=[20e3, 0.3e6], gravity=G)
    assert (auto.profile is not None) == (auto.uncertainty.condition > sf.inverse.PROFILE_CONDITION)
    with pytest.raises(sf.InputError, match="profile: expected the name of a fitted scalar parameter"):
        sf.estimate(build(), noisy, ["shear_modulus"], x0=[20e3], gravity=G, profile="density")
    with pytest.raises(sf.InputError, match="profile_values"):
        sf.estimate(build(), noisy, ["shear_modulus"], x0=[20e3], gravity=G, profile=True, profile_values=[-1, 2])


def test_weak_direction_and_condition():
    """Gravity alone on a nearly incompressible beam (nu = 0.499, mixed formulation), its tip
    observed: lambda hardly matters, the worst determined direction is lambda's (condition
    number 1.5e3), and the automatic profile follows it."""
    truth = sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.499, density=1080)
    body = build(truth).replace(formulation="mixed")
    goal = sf.solve_static(body, G, tolerance=1e-10).positions
    tip = body.mesh.nodes_on_plane((0.4, 0, 0), (1, 0, 0))
    target = sf.Target.nodes(tip, goal[tip] + np.random.default_rng(1).normal(0, NOISE, (tip.size, 3)))
    start = build(sf.NeoHookean(shear_modulus=20e3, lame_lambda=0.3e6, density=1080)).replace(formulation="mixed")
    fit = sf.estimate(start, target, ["shear_modulus", "lame_lambda"], x0=[20e3, 0.3e6], gravity=G,
                      bounds=[(1e3, 1e6), (1e3, 1e9)])
    unc = fit.uncertainty
    assert unc.condition > sf.inverse.PROFILE_CONDITION
    assert abs(unc.weak_direction[1]) > 0.9 and np.linalg.norm(unc.weak_direction) == pytest.approx(1.0)
    assert fit.profile is not None and fit.profile.name == "lame_lambda"


def test_plots_of_a_fit(noisy, tmp_path):
    from matplotlib.figure import Figure

    fit = sf.estimate(build(), noisy, ["shear_modulus", "lame_lambda"], x0=[20e3, 0.3e6], gravity=G,
                      profile="lame_lambda")
    fig = sf.plot.plot_fit(fit, tmp_path / "fit.png")
    markers, history = fig.axes[:2]
    # The goals and the model's points, in the plane of the two widest coordinates (x, z here).
    (model, goal, _), = fit.markers()
    assert markers.get_xlabel() == "x [m]" and markers.get_ylabel() == "z [m]"
    offsets = [c.get_offsets() for c in markers.collections]
    np.testing.assert_allclose(offsets[0], goal[:, [0, 2]])
    np.testing.assert_allclose(offsets[1], model[:, [0, 2]])
    x = history.lines[0].get_xdata()
    assert x[0] == 0 and len(x) == len(fit.history)
    assert (tmp_path / "fit.png").read_bytes()[:4] == b"\x89PNG"
    mine = Figure()
    ax = mine.add_subplot()
    assert sf.plot.plot_profile(fit, ax=ax) is mine
    assert ax.get_xscale() == "log" and ax.get_xlabel() == "lambda [Pa]"
    without = sf.estimate(build(), noisy, ["shear_modulus"], x0=[20e3], gravity=G, profile=False)
    with pytest.raises(sf.InputError, match="has no profile"):
        sf.plot.plot_profile(without)


def _estimate_scene(nodes: list[int], positions: list[list[float]], cap: float) -> str:
    return f"""\
[mesh]
box = {{ size = [0.4, 0.1, 0.1], cells = [4, 2, 2] }}

[material]
shear_modulus = 20e3
lame_lambda = 0.3e6
density = 1080

[[fixed]]
box = {{ min = [-1e-9, -1, -1], max = [1e-9, 1, 1] }}

[loads]
gravity = [0, 0, -9.81]

[target]
nodes = {nodes}
positions = {positions}

[estimate]
params = ["shear_modulus", "lame_lambda"]
x0 = [20e3, 0.3e6]
bounds = [[1e3, 1e6], [1e3, {cap}]]
"""


def test_cli_estimate_prints_errors_and_bounds_and_writes_figures(noisy, tmp_path, capsys):
    bound = noisy.bind(build().mesh)
    nodes = np.flatnonzero(build().mesh.points[:, 0] >= 0.2)
    scene = tmp_path / "fit.toml"
    scene.write_text(_estimate_scene(nodes.tolist(), bound.goal.tolist(), 0.5 * TRUTH.lame_lambda), encoding="utf-8")
    out = tmp_path / "out"
    assert main(["estimate", str(scene), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    unc = summary["uncertainty"]
    assert unc["at_bound"] == {"shear_modulus": None, "lame_lambda": "upper"}
    assert unc["std"]["lame_lambda"] is None  # NaN is no JSON: null
    mu, std = summary["params"]["shear_modulus"], unc["std"]["shear_modulus"]
    assert f"mu     = {format_uncertain(mu, std, 'Pa')}" in text
    assert "lambda = " in text and "at its upper bound" in text
    for name in ("fit.png", "result.vtu", "summary.json"):
        assert (out / name).is_file(), name
