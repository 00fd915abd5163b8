"""sf.estimate(..., dynamics=...): Rayleigh damping (and the material) recovered from marker
tracks of a simulated release-and-swing; bad input named. The Jacobian's derivatives are
checked in test_trajectory_sensitivity.py."""

from __future__ import annotations

import numpy as np
import pytest

import sorofem as sf

G = (0.0, 0.0, -9.81)
DT, STEPS = 0.01, 40
TRUE = {"mass_damping": 2.0, "stiffness_damping": 0.005}
MARKERS = np.array([[0.4, 0.05, 0.05], [0.4, 0.0, 0.1], [0.2, 0.1, 0.0], [0.3, 0.05, 0.1]])
FRAMES = np.arange(2, STEPS + 1, 2)
START = dict(dt=DT, steps=STEPS, damping=(1.0, 0.01))  # the fits' start: half and twice the truth
NOISE = 1e-4  # m


def beam(E=66e3):
    """The 0.4 m cantilever on 8 x 2 x 2 cells, released from rest under gravity."""
    mesh = sf.Mesh.box(size=(0.4, 0.1, 0.1), cells=(8, 2, 2))
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=E, poisson_ratio=0.45, density=1080))
    body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    return body


@pytest.fixture(scope="module")
def recorded():
    """The markers' positions ``(frames, markers, 3)`` of the swing with the true damping."""
    body = beam()
    traj = sf.simulate(body, DT, STEPS, gravity=G, damping=tuple(TRUE.values()), tolerance=1e-12, method="newton")
    bound = sf.Target.points(MARKERS, MARKERS).bind(body.mesh)
    return np.stack([bound.points(traj.positions[k]) for k in FRAMES])


def tracks_of(positions):
    return sf.inverse.marker_tracks(FRAMES * DT, MARKERS, positions)


@pytest.mark.parametrize("method, rtol", [("least-squares", 1e-6), ("l-bfgs-b", 1e-5)])
def test_noiseless_damping_is_recovered(recorded, method, rtol):
    fit = sf.estimate(beam(), tracks_of(recorded), ["mass_damping", "stiffness_damping"], dynamics=START, gravity=G,
                      method=method)
    assert fit.converged, fit.message
    for name, value in TRUE.items():
        assert fit.params[name] == pytest.approx(value, rel=rtol), (name, fit.params)
    assert fit.residual < 1e-8
    assert fit.trajectory.positions.shape == (STEPS + 1, 81, 3)
    [(model, goal, _)] = fit.markers()  # what fit.png shows: every track's markers at its frame
    assert model.shape == goal.shape == (len(FRAMES) * len(MARKERS), 3)
    np.testing.assert_allclose(model, goal, atol=1e-8)


def test_noiseless_damping_and_modulus_are_recovered(recorded):
    """Youngs modulus started 20 % off, fitted jointly with both coefficients."""
    fit = sf.estimate(beam(E=55e3), tracks_of(recorded), ["mass_damping", "stiffness_damping", "youngs_modulus"],
                      dynamics=START, gravity=G)
    assert fit.converged, fit.message
    assert fit.params["youngs_modulus"] == pytest.approx(66e3, rel=1e-6)
    for name, value in TRUE.items():
        assert fit.params[name] == pytest.approx(value, rel=1e-6), (name, fit.params)
    assert fit.material.youngs_modulus == pytest.approx(66e3, rel=1e-6)


def test_noisy_damping_within_its_uncertainty(recorded):
    noisy = recorded + np.random.default_rng(7).normal(0.0, NOISE, recorded.shape)
    fit = sf.estimate(beam(), tracks_of(noisy), ["mass_damping", "stiffness_damping"], dynamics=START, gravity=G)
    unc = fit.uncertainty
    assert fit.converged and unc is not None
    errors = np.array([fit.params[n] - TRUE[n] for n in unc.names])
    assert np.all(np.abs(errors) <= 3 * unc.std), (errors, unc.std)
    # The noise is what is left: sigma estimates the 0.1 mm per coordinate.
    assert unc.sigma == pytest.approx(NOISE, rel=0.2)
    assert all(unc.identifiable.values())
    summary = fit.summary()
    assert "mass_damping" in summary and "1/s" in summary and " s\n" in summary


def test_bound_holds_a_coefficient_and_profile_brackets_the_truth(recorded):
    noisy = recorded + np.random.default_rng(7).normal(0.0, NOISE, recorded.shape)
    tracks = tracks_of(noisy)
    held = sf.estimate(beam(), tracks, ["mass_damping", "stiffness_damping"], dynamics=START, gravity=G,
                       bounds={"stiffness_damping": (0.0, 0.003)})
    assert held.uncertainty.at_bound == {"mass_damping": None, "stiffness_damping": "upper"}
    assert held.params["stiffness_damping"] == pytest.approx(0.003, rel=1e-9)
    assert np.isnan(held.uncertainty.std[1]) and np.isfinite(held.uncertainty.std[0])
    # Held too low, beta_K leaves more of the decay to alpha_M.
    assert held.params["mass_damping"] > TRUE["mass_damping"]
    fit = sf.estimate(beam(), tracks, ["mass_damping", "stiffness_damping"], dynamics=START, gravity=G,
                      profile="stiffness_damping", profile_values=[0.0047, 0.005, 0.0053])
    lo, hi = fit.profile.interval
    assert fit.profile.closed == (True, True)
    assert lo < TRUE["stiffness_damping"] < hi
    assert np.all(np.isfinite(fit.profile.loss))


def test_marker_tracks_leave_out_unseen_markers(recorded):
    seen = recorded.copy()
    seen[0, 1] = np.nan
    tracks = sf.inverse.marker_tracks(FRAMES * DT, MARKERS, seen)
    assert len(tracks) == len(FRAMES)
    assert tracks[0][1].bind(beam().mesh).n_points == len(MARKERS) - 1


@pytest.mark.parametrize("kwargs, error, words", [
    (dict(bounds=[(-1.0, 10.0), None]), sf.ParameterError, ["mass_damping", "-1"]),
    (dict(dynamics=dict(START, dt=0.0)), sf.ParameterError, ["dynamics['dt']"]),
    (dict(dynamics=dict(START, dt=-0.01)), sf.ParameterError, ["dynamics['dt']"]),
    (dict(dynamics=dict(START, steps=0)), sf.ParameterError, ["dynamics['steps']"]),
    (dict(dynamics=dict(START, steps=10**7)), sf.ParameterError, ["dynamics['steps']"]),
    (dict(dynamics=dict(START, steps=20)), sf.ParameterError, ["target[", "0.22"]),
    (dict(dynamics={"dt": DT}), sf.InputError, ["steps"]),
    (dict(dynamics=dict(START, dampnig=(1, 1))), sf.InputError, ["dampnig"]),
    (dict(dynamics=dict(START, damping=(-1.0, 0.01))), sf.ParameterError, ["alpha_M"]),
    (dict(dynamics=dict(START, damping=(0.0, 0.01))), sf.ParameterError, ["mass_damping", "> 0"]),
    (dict(params=["mass_damping", "viscosity"]), sf.InputError, ["viscosity", "mass_damping"]),
    (dict(params=["shear_modulus_field"]), sf.InputError, ["shear_modulus_field", "scalar"]),
    (dict(params=["gravity"]), sf.InputError, ["gravity"]),
    (dict(params=["mass_damping", "mass_damping"]), sf.InputError, ["twice"]),
    (dict(params=["cable_stiffness"]), sf.InputError, ["cable_stiffness", "cables"]),
    (dict(scenarios=[{}], load_steps=3), sf.InputError, ["scenarios", "load_steps"]),
    (dict(starts=2), sf.InputError, ["starts"]),
    (dict(profile="density"), sf.InputError, ["profile", "density"]),
])
def test_bad_input_is_named(recorded, kwargs, error, words):
    args = dict(params=["mass_damping", "stiffness_damping"], dynamics=START, gravity=G)
    args.update(kwargs)
    with pytest.raises(error) as info:
        sf.estimate(beam(), tracks_of(recorded), **args)
    for word in words:
        assert word in str(info.value), (word, str(info.value))


@pytest.mark.parametrize("target, words", [
    ("tracks", ["target", "marker tracks"]),
    ([(0.015, None)], ["target[0]", "(time, sorofem.Target)"]),
    ("off-frame", ["target[0]", "0.015"]),
])
def test_bad_tracks_are_named(recorded, target, words):
    if target == "tracks":
        target = sf.Target.points(MARKERS, recorded[-1])
    elif target == "off-frame":
        target = [(0.015, sf.Target.points(MARKERS, recorded[0]))]
    with pytest.raises(sf.InputError) as info:
        sf.estimate(beam(), target, ["mass_damping"], dynamics=START, gravity=G)
    for word in words:
        assert word in str(info.value)


def test_marker_tracks_shapes_are_checked(recorded):
    with pytest.raises(sf.InputError, match=r"positions: expected shape \(frames, markers, 3\)"):
        sf.inverse.marker_tracks(FRAMES * DT, MARKERS, recorded[:, :2])
    with pytest.raises(sf.InputError, match="rest_points"):
        sf.inverse.marker_tracks(FRAMES * DT, MARKERS[:, :2], recorded)
