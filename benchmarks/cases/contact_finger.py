"""Contact costs on realistic meshes: a ~10k-tet tendon-driven finger pressing on a ball, against
the same pull without the ball; and self-contact of a C-shaped body switched on against off."""

from __future__ import annotations

from typing import Any, Callable

import numpy as np
from harness import TABLES, Row, Table, case, col

from .common import TOLERANCE
from .contact import paired, paired_columns

FINGER_SIZE = (0.1, 0.02, 0.02)  # m
FINGER_PULL = 0.006  # m: the tendon's pull, one solve from rest
BALL_CENTER, BALL_RADIUS = (0.08, 0.01, -0.035), 0.02  # m: its top 5 mm under the finger

C_SIZE = (0.2, 0.02, 0.08)  # m
LOWER_TOP, UPPER_BOTTOM = 0.02, 0.06  # m: the slot between the arms
C_GRAVITY = {"resting": 1.0, "apart": 0.3}  # times 9.81 m/s^2 down

TABLES["contact-finger"] = Table(
    "Contact: finger on a ball (sorofem)",
    "A 100 x 20 x 20 mm silicone finger (Mesh.box, E = 100 kPa, nu = 0.45, standard formulation), clamped at "
    "x = 0, a tendon 3 mm above its underside from x = 0 to 95 mm pulled 6 mm in one solve from rest (one "
    "load step, tolerance 1e-8, no gravity): it curls down onto a frictionless ball (sf.Sphere, radius 20 mm, "
    "its top 5 mm under the finger, 80 mm out), against the same pull without the ball; both run in the same "
    "process, alternating. Columns as in the contact table; ball force = |F| of the ball on the finger.",
    paired_columns(col("ball force [N]", "ball_force")),
)

TABLES["self-contact"] = Table(
    "Self-contact (sorofem)",
    "A C-shaped body (0.2 x 0.02 x 0.08 m box without a 40 mm slot open towards +x and without the second "
    "half of its upper arm; E = 30 kPa, nu = 0.45, rho = 1080 kg/m^3), clamped at z = 0, under gravity, one "
    "load step, tolerance 1e-8, with `set_contact(self_contact=True)` against the same solve without it; both "
    "run in the same process, alternating. `resting`: under g the upper arm rests on the lower one (without "
    "self-contact it passes through it: a different solve, whose iterations the pair shows); `apart`: under "
    "0.3 g it sags without touching (the same solve: the cost of looking for self-contact). Columns as in the "
    "contact table.",
    paired_columns(),
)


def _finger(cells: tuple[int, int, int], ball: bool) -> Row:
    body = _finger_body(cells, ball)
    return _solved(body, (0.0, 0.0, 0.0), ball, lambda r: {"ball_force": float(np.linalg.norm(r.obstacle_forces[0]))})


def _finger_body(cells: tuple[int, int, int], ball: bool) -> Any:
    """The finger with its tendon pulled (and the ball, when ``ball``), not yet solved."""
    import sorofem as sf

    mesh = sf.Mesh.box(size=FINGER_SIZE, cells=cells)
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=100e3, poisson_ratio=0.45, density=1080.0))
    body.fix(mesh.nodes_on_plane((0.0, 0.0, 0.0), (1.0, 0.0, 0.0)))
    x = np.linspace(0.0, 0.095, 20)
    tendon = body.add_cable(sf.Cable(np.c_[x, np.full_like(x, 0.01), np.full_like(x, 0.003)], model="tendon"))
    body.pull(tendon, displacement=FINGER_PULL)
    if ball:
        body.add_obstacle(sf.Sphere(center=BALL_CENTER, radius=BALL_RADIUS))
    return body


def _c_shape(cells: tuple[int, int, int], gravity: float, self_contact: bool) -> Row:
    import sorofem as sf

    box = sf.Mesh.box(size=C_SIZE, cells=cells)
    centres = box.points[box.tets].mean(axis=1)
    slot = (centres[:, 0] > C_SIZE[0] / 8) & (centres[:, 2] > LOWER_TOP) & (centres[:, 2] < UPPER_BOTTOM)
    beyond = (centres[:, 0] > C_SIZE[0] / 2) & (centres[:, 2] > UPPER_BOTTOM)
    tets = box.tets[~(slot | beyond)]
    used, inverse = np.unique(tets, return_inverse=True)
    mesh = sf.Mesh(box.points[used], inverse.reshape(tets.shape))
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=30e3, poisson_ratio=0.45, density=1080.0))
    body.fix(np.flatnonzero(mesh.points[:, 2] < 1e-9))
    body.set_contact(self_contact=self_contact)
    return _solved(body, (0.0, 0.0, -9.81 * gravity), self_contact, lambda r: {})


def _solved(body: Any, gravity: tuple[float, float, float], contact: bool, extra: Callable[[Any], Row]) -> Row:
    import sorofem as sf

    try:
        result = sf.solve_static(body, gravity=gravity, tolerance=TOLERANCE, load_steps=1)
    except sf.ConvergenceError as err:
        return {"converged": False, "failure": str(err), "tets": body.mesh.n_tets}
    report = result.report
    row: Row = {"converged": bool(report.converged), "iterations": report.iterations,
                "timings": dict(report.timings), "tets": body.mesh.n_tets}
    if contact:
        row["active_contacts"] = result.active_contacts
        row.update(extra(result))
    return row


@case("sorofem/contact-finger-on-ball-10x2x2", "contact-finger", quick=True)
def finger_small() -> Row:
    return paired(lambda ball: _finger((10, 2, 2), ball), 2.0, "sorofem.Sphere / Body.add_obstacle / solve_static")


@case("sorofem/contact-finger-on-ball-35x7x7", "contact-finger")
def finger() -> Row:
    return paired(lambda ball: _finger((35, 7, 7), ball), 8.0, "sorofem.Sphere / Body.add_obstacle / solve_static")


@case("sorofem/self-contact-c-shape-resting-24x3x12", "self-contact")
def self_contact_resting() -> Row:
    return paired(lambda on: _c_shape((24, 3, 12), C_GRAVITY["resting"], on), 6.0, "Body.set_contact(self_contact=True)")


@case("sorofem/self-contact-c-shape-apart-24x5x12", "self-contact")
def self_contact_apart() -> Row:
    return paired(lambda on: _c_shape((24, 5, 12), C_GRAVITY["apart"], on), 6.0, "Body.set_contact(self_contact=True)")
