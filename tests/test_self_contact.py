"""Self-contact through the Python API: a C-shaped body whose upper arm sags under gravity rests on
its lower arm with ``set_contact(self_contact=True)`` and passes through it without; the switch is
checked, and the scene key reaches the body."""

from __future__ import annotations

import numpy as np
import pytest

import sorofem as sf

SIZE = (0.2, 0.02, 0.08)  # m
CELLS = (8, 1, 4)
LOWER_TOP, UPPER_BOTTOM = 0.02, 0.06  # m: the slot between the arms
DENSITY = 1080.0  # kg/m^3
GRAVITY = (0.0, 0.0, -9.81)


def c_shape() -> sf.Mesh:
    """The box without the slot of the cells x > one cell, 1 <= layer <= 2 (open towards +x), and
    without the second half of the top layer: the upper arm is half as long as the lower one."""
    box = sf.Mesh.box(size=SIZE, cells=CELLS)
    centres = box.points[box.tets].mean(axis=1)
    h = np.array(SIZE) / np.array(CELLS)
    slot = (centres[:, 0] > h[0]) & (centres[:, 2] > LOWER_TOP) & (centres[:, 2] < UPPER_BOTTOM)
    beyond = (centres[:, 0] > SIZE[0] / 2) & (centres[:, 2] > UPPER_BOTTOM)
    tets = box.tets[~(slot | beyond)]
    used, inverse = np.unique(tets, return_inverse=True)
    return sf.Mesh(box.points[used], inverse.reshape(tets.shape))


def clamped_body(self_contact: bool) -> sf.Body:
    mesh = c_shape()
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=30e3, poisson_ratio=0.45, density=DENSITY))
    body.fix(np.flatnonzero(mesh.points[:, 2] < 1e-9))
    body.set_contact(self_contact=self_contact)
    return body


def lowest_of_upper_arm(body: sf.Body, positions: np.ndarray) -> float:
    rest = body.mesh.points
    arm = (rest[:, 2] >= UPPER_BOTTOM - 1e-12) & (rest[:, 0] > SIZE[0] / CELLS[0] + 1e-12)
    return float(positions[arm, 2].min())


def test_an_arm_rests_on_its_own_body_and_passes_through_it_without_self_contact():
    through = sf.solve_static(clamped_body(False), gravity=GRAVITY)
    assert through.contact is None
    sag = lowest_of_upper_arm(through.body, through.positions)
    assert sag < LOWER_TOP

    body = clamped_body(True)
    result = sf.solve_static(body, gravity=GRAVITY)
    contact = result.contact
    # Resting on the lower arm (whose top sinks a little under the load), apart from it.
    assert sag + 0.5 * (LOWER_TOP - sag) < lowest_of_upper_arm(body, result.positions) < LOWER_TOP + body.dhat
    assert contact.self_active > 0 and result.active_contacts == contact.self_active
    assert 0 < contact.self_min_distance < body.dhat
    assert np.all(contact.iterate_min_distances > 0)
    # Internal forces: they sum to zero, and the supports carry the whole weight.
    forces = result.contact_forces
    assert np.abs(forces).sum() > 0
    np.testing.assert_allclose(forces.sum(axis=0), 0.0, atol=1e-10 * np.abs(forces).sum())
    weight = DENSITY * body.mesh.volumes.sum() * np.asarray(GRAVITY)
    np.testing.assert_allclose(result.reactions.sum(axis=0), -weight, atol=1e-8 * np.linalg.norm(weight))
    assert result.to_dict()["contact"]["self_contact"]["active_contacts"] == contact.self_active


def test_the_switch_is_checked_and_defaults_to_off():
    body = clamped_body(False)
    assert body.contact_settings["self_contact"] is False
    assert body.dhat is None
    with pytest.raises(sf.ParameterError, match="self_contact"):
        body.set_contact(self_contact="yes")
    body.set_contact(self_contact=True)
    assert body.dhat > 0


def test_the_scene_key_switches_self_contact_on(tmp_path):
    scene = tmp_path / "c.toml"
    scene.write_text("""
[mesh]
box = { size = [0.1, 0.02, 0.02], cells = [5, 1, 1] }

[material]
youngs_modulus = 1e5
poisson_ratio = 0.45

[[fixed]]
box = { min = [-1e-9, -1, -1], max = [1e-9, 1, 1] }

[contact]
self_contact = true
""", encoding="utf-8")
    assert sf.Scene.load(scene).body.contact_settings["self_contact"] is True
