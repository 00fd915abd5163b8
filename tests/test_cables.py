"""Cables: validation, placement, actuation without rebuild, continuation, free nodes, output."""

from __future__ import annotations


import meshio
import numpy as np
import pytest
from independent import material_point_positions

import sorofem as sf
from sorofem.cables import CablePlacement, segment_tensions

GRAVITY = np.array([0.0, 0.0, -9.81])


@pytest.fixture
def silicone() -> sf.NeoHookean:
    return sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080)


@pytest.fixture
def beam(silicone) -> sf.Body:
    """The 0.4 m cantilever, 8 x 2 x 2 cells, clamped at x = 0."""
    mesh = sf.Mesh.box(size=(0.4, 0.1, 0.1), cells=(8, 2, 2))
    body = sf.Body(mesh, silicone)
    body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    return body


def edge_cable(**options) -> sf.Cable:
    """Along the lower edge at y = z = 1 cm, x = 0 .. 0.4 m, 10 segments."""
    return sf.Cable.line((0.0, 0.01, 0.01), (1, 0, 0), 0.4, 10, stiffness=1e5, **options)


# -- validation ---------------------------------------------------------------------


@pytest.mark.parametrize(
    "kwargs, parameter",
    [
        ({"points": [[0, 0, 0]]}, "points"),
        ({"points": [[0, 0, 0], [0, 0, 0]]}, "points"),
        ({"points": [[0, 0, 0], [np.nan, 0, 0]]}, "points"),
        ({"stiffness": 0.0}, "stiffness"),
        ({"stiffness": -1.0}, "stiffness"),
        ({"stiffness": "stiff"}, "stiffness"),
        ({"actuation": 0.0}, "actuation"),
        ({"actuation": float("inf")}, "actuation"),
        ({"transition": 0.0}, "transition"),
        ({"transition": 1.0}, "transition"),
        ({"anchor_first": "yes"}, "anchor_first"),
        ({"snap_tolerance": -1e-3}, "snap_tolerance"),
        ({"outside": "ignore"}, "outside"),
        ({"free_node_mass": -0.1}, "free_node_mass"),
        ({"damping": -0.1}, "damping"),
        ({"damping": "viscous"}, "damping"),
    ],
)
def test_cable_parameter_errors_name_the_parameter(kwargs, parameter):
    args = {"points": [[0, 0, 0], [1, 0, 0]], "stiffness": 1e3, **kwargs}
    with pytest.raises(sf.ParameterError) as info:
        sf.Cable(**args)
    assert info.value.parameter == parameter
    assert parameter in str(info.value)


def test_cable_shape_error():
    with pytest.raises(sf.ShapeError, match=r"points: expected shape \(k, 3\)"):
        sf.Cable([[0, 0], [1, 0]], stiffness=1.0)


@pytest.mark.parametrize(
    "kwargs, parameter",
    [({"direction": (0, 0, 0)}, "direction"), ({"length": -1.0}, "length"), ({"divisions": 0}, "divisions"),
     ({"divisions": 2.5}, "divisions")],
)
def test_line_errors(kwargs, parameter):
    args = {"start": (0, 0, 0), "direction": (1, 0, 0), "length": 1.0, "divisions": 4, "stiffness": 1.0, **kwargs}
    with pytest.raises(sf.ParameterError) as info:
        sf.Cable.line(**args)
    assert info.value.parameter == parameter


def test_line_points_evenly_spaced():
    cable = sf.Cable.line((0, 1, 2), (0, 0, 3), length=0.5, divisions=5, stiffness=10.0, actuation=0.9)
    assert cable.points.shape == (6, 3) and cable.n_segments == 5
    np.testing.assert_allclose(cable.rest_lengths, 0.1)
    np.testing.assert_allclose(cable.points[-1], [0, 1, 2.5])
    assert cable.length == pytest.approx(0.5) and cable.actuation == 0.9
    assert not cable.points.flags.writeable
    assert "6 points" in repr(cable)


def test_body_cable_bookkeeping_errors(beam):
    with pytest.raises(sf.InputError, match="expected a sorofem.Cable"):
        beam.add_cable([[0, 0, 0], [1, 0, 0]])
    cable = edge_cable()
    assert beam.add_cable(cable) == 0
    with pytest.raises(sf.InputError, match="already been added"):
        beam.add_cable(cable)
    assert beam.add_cable(edge_cable(actuation=0.9)) == 1
    assert beam.actuations == [1.0, 0.9]
    with pytest.raises(sf.InputError, match="index 2 out of range"):
        beam.set_actuation(2, 0.5)
    with pytest.raises(sf.InputError, match="not been added"):
        beam.set_actuation(edge_cable(), 0.5)
    with pytest.raises(sf.ParameterError) as info:
        beam.set_actuation(cable, -0.5)
    assert info.value.parameter == "alpha"


def test_point_outside_the_mesh_is_an_error(beam):
    beam.add_cable(sf.Cable([[0.2, 0.05, 0.05], [0.2, 0.05, 0.3]], stiffness=1.0))
    with pytest.raises(sf.ParameterError, match=r"cables\[0\]\.points\[1\]"):
        beam.cable_placements()


# -- statics ------------------------------------------------------------------------


def test_rest_actuation_without_gravity_is_the_rest_state(beam):
    beam.add_cable(edge_cable())
    result = sf.solve_static(beam)
    assert np.abs(result.displacement).max() == 0.0
    assert len(result.cable_tensions) == 1 and result.cable_tensions[0].shape == (10,)
    assert np.all(result.cable_tensions[0] == 0.0)
    np.testing.assert_allclose(result.cable_points[0], beam.cables[0].points, atol=1e-15)


def test_actuation_changes_without_rebuild(beam):
    cable = edge_cable()
    beam.add_cable(cable)
    first = sf.solve_static(beam)
    model = beam._core_model()
    beam.set_actuation(cable, 0.95)
    pulled = sf.solve_static(beam, initial=first)
    assert beam._core_model() is model, "set_actuation rebuilt the model"
    assert pulled.actuations == [0.95]
    assert pulled.cable_tensions[0].min() > 0
    # Back to rest: the rest state again.
    beam.set_actuation(0, 1.0)
    again = sf.solve_static(beam, initial=pulled)
    assert np.abs(again.displacement).max() < 1e-9
    # Adding a cable rebuilds the model.
    beam.add_cable(sf.Cable.line((0, 0.09, 0.09), (1, 0, 0), 0.4, 4, stiffness=1e4))
    assert beam._core_model() is not model


def test_continuation_to_half_length(beam):
    cable = edge_cable()
    beam.add_cable(cable)
    gravity_only = sf.solve_static(beam, gravity=GRAVITY)
    results = sf.actuate(beam, cable, 0.5, gravity=GRAVITY)
    assert len(results) == 10  # steps of 0.05 from 1.0
    assert [r.actuations[0] for r in results] == pytest.approx(np.linspace(0.95, 0.5, 10))
    assert beam.actuations == [0.5]
    final = results[-1]
    assert all(r.report.converged for r in results)
    tensions = final.cable_tensions[0]
    assert np.all(tensions > 0)
    # The spring law, recomputed here from the cable points.
    np.testing.assert_allclose(tensions, segment_tensions(cable, final.cable_points[0], 0.5), rtol=1e-9)
    tip = beam.mesh.nodes_on_plane((0.4, 0, 0), (1, 0, 0))
    # Towards the cable (y < 0; gravity alone bends in z only), the cable side shortened;
    # the cable is internal, so the supports still carry just the weight.
    assert abs(gravity_only.displacement[tip, 1].mean()) < 1e-3  # (the tet split is not quite symmetric)
    assert final.displacement[tip, 1].mean() < -0.05
    # The cable points are material points: where NumPy's interpolation in their tets puts them.
    np.testing.assert_allclose(
        final.cable_points[0], material_point_positions(beam.mesh, cable.points, final.positions), rtol=0, atol=1e-12
    )
    chord = np.linalg.norm(final.cable_points[0][-1] - final.cable_points[0][0])
    assert chord < 0.8 * cable.length
    weight = 0.004 * 1080 * 9.81
    np.testing.assert_allclose(final.reactions.sum(axis=0), [0, 0, weight], atol=1e-6 * weight)
    # An explicit path and a warm start from a previous result work too.
    back = sf.actuate(beam, 0, [0.6, 0.7], gravity=GRAVITY, initial=final)
    assert [r.actuations[0] for r in back] == [0.6, 0.7]


def test_actuate_argument_errors(beam):
    cable = edge_cable()
    with pytest.raises(sf.InputError, match="not been added"):
        sf.actuate(beam, cable, 0.9)
    beam.add_cable(cable)
    with pytest.raises(sf.ParameterError, match=r"alphas\[1\]"):
        sf.actuate(beam, cable, [0.9, 0.0])
    with pytest.raises(sf.ParameterError, match="alphas"):
        sf.actuate(beam, cable, [])


def test_placements_embedded_snapped_free_anchor(silicone):
    mesh = sf.Mesh.box(size=(0.1, 0.1, 0.1), cells=(2, 2, 2))
    body = sf.Body(mesh, silicone)
    body.fix(np.arange(mesh.n_nodes))
    body.add_cable(sf.Cable([[0.05, 0.05, 0.01], [0.05, 0.05, -0.05]], 1e3, 0.99, outside="free", free_node_mass=0.1))
    body.add_cable(
        sf.Cable([[0.2, 0.05, 0.01], [0.101, 0.05, 0.05], [0.05, 0.05, 0.05]], 1e3, anchor_first=True, snap_tolerance=2e-3)
    )
    placements = body.cable_placements()
    assert [p.kind for p in placements[0]] == ["embedded", "free"]
    assert placements[0][1] == CablePlacement("free", -1, 0, 0.0)
    assert [p.kind for p in placements[1]] == ["anchor", "snapped", "embedded"]
    assert placements[1][1].distance == pytest.approx(1e-3)
    assert 0 <= placements[1][1].tet < mesh.n_tets
    counts = sf.solve_static(body, gravity=GRAVITY).to_dict()["cables"][1]["placement_counts"]
    assert counts == {"embedded": 1, "snapped": 1, "free": 0, "anchor": 1, "max_snap_distance": pytest.approx(1e-3)}


def test_free_node_weight_reaches_the_supports(silicone):
    """A 0.1 kg free node hanging from a fully clamped cube: the supports carry its weight."""
    mesh = sf.Mesh.box(size=(0.1, 0.1, 0.1), cells=(2, 2, 2))
    body = sf.Body(mesh, silicone)
    body.fix(np.arange(mesh.n_nodes))
    # alpha < 1: taut from the start (a free node on a slack cable has no stiffness at all).
    body.add_cable(sf.Cable([[0.05, 0.05, 0.01], [0.05, 0.05, -0.05]], 1e3, 0.99, outside="free", free_node_mass=0.1))
    result = sf.solve_static(body, gravity=GRAVITY)
    weight = (1080 * 1e-3 + 0.1) * 9.81
    np.testing.assert_allclose(result.reactions.sum(axis=0), [0, 0, weight], rtol=1e-9, atol=1e-12)


def test_free_node_with_mass_hangs_below(silicone):
    mesh = sf.Mesh.box(size=(0.1, 0.1, 0.1), cells=(2, 2, 2))
    body = sf.Body(mesh, silicone)
    body.fix(np.arange(mesh.n_nodes))
    cable = sf.Cable([[0.05, 0.05, 0.01], [0.05, 0.05, -0.05]], 1e3, 0.99, outside="free", free_node_mass=0.1)
    body.add_cable(cable)
    result = sf.solve_static(body, gravity=GRAVITY)
    # Taut spring: k (L - alpha l - w/2) = m g.
    l = 0.06
    expected = 0.99 * l + 0.1 * 9.81 / 1e3 + cable.transition * l / 2
    np.testing.assert_allclose(result.cable_points[0][1], [0.05, 0.05, 0.01 - expected], atol=1e-9)
    assert result.cable_tensions[0][0] == pytest.approx(0.1 * 9.81, rel=1e-9)


def test_summary_and_cable_file(beam, tmp_path):
    beam.add_cable(edge_cable(actuation=0.9))
    result = sf.solve_static(beam, gravity=GRAVITY)
    summary = result.to_dict()["cables"][0]
    assert summary["actuation"] == 0.9 and len(summary["tensions"]) == 10
    assert summary["placement_counts"]["embedded"] == 11
    path = tmp_path / "cables.vtu"
    sf.cables.write_cables(path, result)
    back = meshio.read(path)
    assert back.points.shape == (11, 3)
    np.testing.assert_allclose(back.cell_data["tension"][0], result.cable_tensions[0])


# -- scene files and the command line ------------------------------------------------


CABLE_SCENE = """\
[mesh]
box = { size = [0.4, 0.1, 0.1], cells = [8, 2, 2] }

[material]
youngs_modulus = 66e3
poisson_ratio = 0.45
density = 1080

[[fixed]]
box = { min = [-1e-9, -1, -1], max = [1e-9, 1, 1] }

[loads]
gravity = [0, 0, -9.81]

[[cable]]
start = [0, 0.01, 0.01]
direction = [1, 0, 0]
length = 0.4
divisions = 10
stiffness = 1e5
actuation = 0.9

[[cable]]
points = [[0.0, 0.09, 0.09], [0.2, 0.09, 0.09], [0.4, 0.09, 0.101]]
stiffness = 2e4
actuation = 1.1
transition = 0.01
snap_tolerance = 0.002
"""


def test_scene_with_cables_matches_the_api(tmp_path, beam):
    path = tmp_path / "cables.toml"
    path.write_text(CABLE_SCENE, encoding="utf-8")
    scene = sf.Scene.load(path)
    assert len(scene.cables) == 2 and scene.body.actuations == [0.9, 1.1]
    assert scene.cables[1].transition == 0.01 and scene.cables[1].snap_tolerance == 0.002
    assert [p.kind for p in scene.body.cable_placements()[1]] == ["embedded", "embedded", "snapped"]
    from_scene = scene.solve()
    beam.add_cable(edge_cable(actuation=0.9))
    beam.add_cable(sf.Cable(scene.cables[1].points, 2e4, 1.1, transition=0.01, snap_tolerance=0.002))
    from_api = sf.solve_static(beam, gravity=GRAVITY)
    np.testing.assert_allclose(from_scene.positions, from_api.positions, atol=1e-12)
    assert scene.to_dict()["cables"][0]["actuation"] == 0.9


@pytest.mark.parametrize(
    "old, new, key",
    [
        ("stiffness = 1e5", "stiffness = 0", "cable[0].stiffness"),
        ("stiffness = 1e5", "stiffnes = 1e5", "cable[0].stiffnes"),
        ("actuation = 0.9", "actuation = -0.9", "cable[0].actuation"),
        ("divisions = 10", "divisions = 0", "cable[0].divisions"),
        ("divisions = 10", "", "cable[0].divisions"),
        ("length = 0.4", "length = 0.4\npoints = [[0, 0, 0], [1, 0, 0]]", "cable[0]"),
        ("transition = 0.01", "transition = 2.0", "cable[1].transition"),
        ("snap_tolerance = 0.002", "snap_tolerance = 0.0", "cable[1].points"),
        ("actuation = 1.1", "actuation = 1.1\noutside = \"drop\"", "cable[1].outside"),
    ],
)
def test_bad_cable_entries_name_the_key(tmp_path, old, new, key):
    path = tmp_path / "bad.toml"
    text = CABLE_SCENE.replace(old, new, 1)
    path.write_text(text, encoding="utf-8")
    with pytest.raises(sf.SceneError) as info:
        sf.Scene.load(path)
    assert info.value.key == key, str(info.value)


def test_cable_must_be_an_array_of_tables(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(CABLE_SCENE.split("[[cable]]")[0] + "[cable]\npoints = [[0, 0, 0], [0.1, 0, 0]]\nstiffness = 1.0\n")
    with pytest.raises(sf.SceneError, match=r"write \[\[cable\]\]") as info:
        sf.Scene.load(path)
    assert info.value.key == "cable" and info.value.line is not None


def test_run_scene_with_cables(tmp_path):
    import json

    from sorofem.cli import main

    path = tmp_path / "cables.toml"
    path.write_text(CABLE_SCENE, encoding="utf-8")
    assert main(["run", str(path), "--out", str(tmp_path / "out"), "--quiet"]) == 0
    summary = json.loads((tmp_path / "out" / "summary.json").read_text(encoding="utf-8"))
    first, second = summary["cables"]
    assert len(first["tensions"]) == 10 and first["max_tension"] > 0
    assert second["placements"] == ["embedded", "embedded", "snapped"]
    assert second["placement_counts"]["max_snap_distance"] == pytest.approx(0.001, rel=0.05)
    assert (tmp_path / "out" / "cables.vtu").is_file()


@pytest.mark.parametrize("dashpot", [0.0, 0.8])
def test_cable_dashpot_follows_the_implicit_euler_oscillator(silicone, dashpot):
    """A 0.1 kg free node hanging from a world anchor on one taut segment (k = 100 N/m, dashpot
    c) is the oscillator m L'' = m g - k (L - alpha l - w/2) - c L'. Its implicit Euler
    recursion, solved here in closed form per step, must match the simulated free node."""
    mesh = sf.Mesh.box(size=(0.1, 0.1, 0.1), cells=(1, 1, 1))
    body = sf.Body(mesh, silicone)
    body.fix(np.arange(mesh.n_nodes))
    rest_length, stiffness, alpha, mass, g = 0.1, 100.0, 0.85, 0.1, 9.81
    cable = sf.Cable([[0.2, 0.05, 0.05], [0.2, 0.05, 0.05 - rest_length]], stiffness, alpha, anchor_first=True,
                     outside="free", free_node_mass=mass, damping=dashpot)
    body.add_cable(cable)
    h, steps = 2e-3, 500
    trajectory = sf.simulate(body, h, steps, gravity=(0, 0, -g), tolerance=1e-12)
    simulated = np.array([frame[0][1, 2] for frame in trajectory.cable_points])
    length, velocity, expected = rest_length, 0.0, [rest_length]
    width = cable.transition * rest_length
    for _ in range(steps):
        new = (mass * (length + h * velocity) / h**2 + dashpot * length / h
               + stiffness * (alpha * rest_length + width / 2) + mass * g) / (mass / h**2 + dashpot / h + stiffness)
        length, velocity = new, (new - length) / h
        expected.append(length)
    expected_z = 0.05 - np.array(expected)
    # Taut throughout (the recursion assumes it): the stretch stays above the transition.
    assert np.all(np.array(expected) - alpha * rest_length > width)
    np.testing.assert_allclose(simulated, expected_z, rtol=0, atol=1e-9)
    # Over five periods (2 pi sqrt(m / k) = 0.2 s) the swing decays by implicit Euler's own
    # damping (|1 / (1 + i h omega)|^400 = 0.45) and, with the dashpot (damping ratio
    # c / (2 sqrt(k m)) = 0.13), by a further exp(-0.13 omega 0.8 s) = 0.04.
    period = int(round(2 * np.pi * np.sqrt(mass / stiffness) / h))
    decay = np.ptp(simulated[-period:]) / np.ptp(simulated[:period])
    print(f"dashpot {dashpot} N s/m: swing decay over five periods {decay:.3f}")
    assert (decay < 0.05) if dashpot > 0 else (decay > 0.3), decay


def test_anchor_reaction_closes_the_force_balance(silicone):
    """A clamped beam pulled towards a world anchor beyond its tip, under gravity: supports,
    anchor and weight balance, and the anchor reaction equals the cable's pull on the body
    (minus the supports' share, computed independently from the internal forces)."""
    mesh = sf.Mesh.box(size=(0.2, 0.05, 0.05), cells=(8, 2, 2))
    body = sf.Body(mesh, silicone)
    body.fix(mesh.nodes_in_box(min=(-1e-9, -1, -1), max=(1e-9, 1, 1)))
    # From an anchor 5 cm beyond the tip, obliquely down into the beam and along it to its root.
    points = [[0.25, 0.025, -0.02], [0.19, 0.025, 0.01], [0.1, 0.025, 0.01], [0.01, 0.025, 0.01]]
    body.add_cable(sf.Cable(points, 2e3, 0.9, anchor_first=True))
    body.add_cable(sf.Cable([[0.02, 0.01, 0.04], [0.18, 0.01, 0.04]], 2e3, 0.95))  # internal: no anchor
    result = sf.solve_static(body, gravity=GRAVITY)
    anchor, internal = result.anchor_reactions
    assert internal is None and np.linalg.norm(anchor) > 1.0  # a real pull, N
    weight = np.array(GRAVITY) * 1080 * mesh.volumes.sum()
    np.testing.assert_allclose(result.reactions.sum(axis=0) + anchor + weight, 0.0, atol=1e-8 * np.linalg.norm(anchor))
    # The anchor pulls the cable towards itself, i.e. from the first interior point to the anchor.
    towards_anchor = result.cable_points[0][0] - result.cable_points[0][1]
    assert anchor @ towards_anchor > 0.99 * np.linalg.norm(anchor) * np.linalg.norm(towards_anchor)
    summary = result.to_dict()["cables"]
    assert summary[0]["anchor_reaction"] == pytest.approx(anchor.tolist()) and summary[1]["anchor_reaction"] is None


def test_a_cable_changed_after_a_solve_rebuilds_the_model(silicone):
    """The compiled model holds the cables' dashpots and routing: a dashpot set on the cable
    after a simulation must damp the next one (it did not: the model was kept), which then
    equals a fresh body's."""

    def body_with(cable):
        mesh = sf.Mesh.box(size=(0.4, 0.1, 0.1), cells=(8, 2, 2))
        body = sf.Body(mesh, silicone)
        body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
        body.add_cable(cable)
        return body

    def run(body):
        return sf.simulate(body, 0.01, 10, actuation=[0.8], gravity=(0, 0, -9.81)).positions

    cable = sf.Cable.line((0, 0.01, 0.09), (1, 0, 0), 0.4, 8, stiffness=1e4)
    body = body_with(cable)
    undamped = run(body)
    cable.damping = 50.0
    damped = run(body)
    fresh = run(body_with(sf.Cable.line((0, 0.01, 0.09), (1, 0, 0), 0.4, 8, stiffness=1e4, damping=50.0)))
    assert np.abs(damped - undamped).max() > 1e-4
    np.testing.assert_allclose(damped, fresh, rtol=0, atol=1e-12)
