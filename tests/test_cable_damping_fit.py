"""A spring cable's dashpot set per solve (Body.set_cable_damping) and fitted to a recorded
motion (sf.estimate(..., params=["cable_damping"], dynamics=...)); a Cable's own values changed
after it was added are taken, not ignored. The derivatives by the dashpot are checked against
central differences in test_trajectory_contact.py."""

from __future__ import annotations

import numpy as np
import pytest

import sorofem as sf

G = (0.0, 0.0, -9.81)
DT, STEPS = 0.01, 30
TRUE_DASHPOT = 40.0  # N s/m
MARKERS = np.array([[0.4, 0.05, 0.05], [0.4, 0.0, 0.1], [0.2, 0.1, 0.0]])
FRAMES = np.arange(2, STEPS + 1, 2)
# The cable pulled in 0.1 s and held: its segments shorten fast, then the beam swings.
SCHEDULE = sf.dynamics.Keyframes([[0.0, 1.0], [0.1, 0.8], [0.3, 0.8]])
MASS_DAMPING = 1.0  # 1/s
RUN = dict(dt=DT, steps=STEPS, actuation=SCHEDULE, damping=(MASS_DAMPING, 0.0))
NOISE = 1e-4  # m


def cable(damping=0.0, stiffness=1e4):
    return sf.Cable.line((0.0, 0.01, 0.09), (1, 0, 0), 0.4, 8, stiffness=stiffness, damping=damping)


def beam(*cables):
    """The 0.4 m cantilever on 8 x 2 x 2 cells with ``cables``."""
    mesh = sf.Mesh.box(size=(0.4, 0.1, 0.1), cells=(8, 2, 2))
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080))
    body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    for c in cables:
        body.add_cable(c)
    return body


def run(body):
    return sf.simulate(body, DT, STEPS, actuation=SCHEDULE, gravity=G, damping=(MASS_DAMPING, 0.0), tolerance=1e-12,
                       method="newton").positions


@pytest.fixture(scope="module")
def recorded():
    """The markers ``(frames, markers, 3)`` of the pull with the true dashpot."""
    body = beam(cable(TRUE_DASHPOT))
    positions = run(body)
    bound = sf.Target.points(MARKERS, MARKERS).bind(body.mesh)
    return np.stack([bound.points(positions[k]) for k in FRAMES])


def tracks_of(positions):
    return sf.inverse.marker_tracks(FRAMES * DT, MARKERS, positions)


def test_set_cable_damping_equals_a_body_built_with_it():
    body = beam(cable())
    undamped = run(body)
    body.set_cable_damping(0, TRUE_DASHPOT)
    assert body.cable_dampings == [TRUE_DASHPOT]
    assert body.cables[0].damping == 0.0  # the Cable keeps its own
    damped = run(body)
    fresh = run(beam(cable(TRUE_DASHPOT)))
    assert np.abs(damped - undamped).max() > 1e-4
    np.testing.assert_allclose(damped, fresh, rtol=0, atol=1e-12)


def test_a_cable_changed_after_it_was_added_is_taken():
    """The latest change wins: the Cable's attribute, then the body's setter."""
    c = cable()
    body = beam(c)
    run(body)
    c.damping, c.stiffness = TRUE_DASHPOT, 2e4
    np.testing.assert_allclose(run(body), run(beam(cable(TRUE_DASHPOT, 2e4))), rtol=0, atol=1e-12)
    assert body.cable_stiffnesses == [2e4] and body.cable_dampings == [TRUE_DASHPOT]
    body.set_cable_damping(c, 5.0)
    np.testing.assert_allclose(run(body), run(beam(cable(5.0, 2e4))), rtol=0, atol=1e-12)


def test_set_cable_damping_names_bad_input():
    body = beam(cable(), sf.Cable.line((0.0, 0.05, 0.05), (1, 0, 0), 0.4, 8, model="tendon"))
    with pytest.raises(sf.ParameterError, match="damping: expected a finite number >= 0, got -1"):
        body.set_cable_damping(0, -1.0)
    with pytest.raises(sf.InputError, match="cable 1 is a tendon, which has no damping"):
        body.set_cable_damping(1, 1.0)


@pytest.mark.parametrize("method, rtol", [("least-squares", 1e-6), ("l-bfgs-b", 1e-5)])
def test_noiseless_dashpot_is_recovered(recorded, method, rtol):
    body = beam(cable(TRUE_DASHPOT / 2))  # the fit's start: half the truth
    fit = sf.estimate(body, tracks_of(recorded), ["cable_damping"], dynamics=RUN, gravity=G, method=method)
    assert fit.converged, fit.message
    assert fit.params["cable_damping"] == pytest.approx(TRUE_DASHPOT, rel=rtol)
    assert fit.residual < 1e-8
    assert body.cable_dampings == [TRUE_DASHPOT / 2]  # the user's body is left as it was


def test_noisy_dashpot_and_mass_damping_within_their_uncertainty(recorded):
    noisy = recorded + np.random.default_rng(3).normal(0.0, NOISE, recorded.shape)
    fit = sf.estimate(beam(cable(TRUE_DASHPOT * 2)), tracks_of(noisy), ["cable_damping", "mass_damping"],
                      dynamics=RUN | {"damping": (MASS_DAMPING / 2, 0.0)}, gravity=G)
    unc = fit.uncertainty
    assert fit.converged and unc is not None
    true = {"cable_damping": TRUE_DASHPOT, "mass_damping": MASS_DAMPING}
    errors = np.array([fit.params[n] - true[n] for n in unc.names])
    assert np.all(np.abs(errors) <= 3 * unc.std), (errors, unc.std)
    assert unc.std[unc.names.index("cable_damping")] < 0.2 * TRUE_DASHPOT  # the pull determines the dashpot
    assert unc.sigma == pytest.approx(NOISE, rel=0.25)
    assert "cable_damping = " in fit.summary() and " N s/m\n" in fit.summary()


@pytest.mark.parametrize("cables, words", [
    ((), "needs a body with exactly one spring cable; this one has 0"),
    ((cable(1.0), cable(2.0)), "needs a body with exactly one spring cable; this one has 2"),
])
def test_cable_damping_needs_one_spring_cable(recorded, cables, words):
    with pytest.raises(sf.InputError, match=words):
        sf.estimate(beam(*cables), tracks_of(recorded), ["cable_damping"], dynamics=RUN, gravity=G)


def test_a_zero_dashpot_start_is_refused_by_name(recorded):
    with pytest.raises(sf.ParameterError, match=r"cable_damping must be .*the cable's damping"):
        sf.estimate(beam(cable(0.0)), tracks_of(recorded), ["cable_damping"], dynamics=RUN, gravity=G)
