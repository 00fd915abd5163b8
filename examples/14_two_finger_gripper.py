"""A two-finger soft gripper squeezing a box, with friction and physics checks.

The gripper is one silicone body (Neo-Hookean, E = 150 kPa, nu = 0.45, rho = 1070 kg/m^3,
standard linear tetrahedra) built by the script from boxes of a structured grid: a palm
(70 x 20 x 10 mm, its top face clamped) and two fingers hanging from its ends (60 mm long,
20 mm wide, 10 mm thick), their inner faces 25 mm from the middle plane y = 0. One half
(y >= 0) is meshed and mirrored node by node, so the mesh is exactly symmetric about y = 0.
Each finger has a tendon (``sf.Cable(..., model="tendon")``) from a motor above the palm down
its inner side to 5 mm short of its tip; winding the motors in (``body.pull``) curls the
fingers towards each other. Between them stands a fixed rigid box (``sf.Box``, 40 mm wide,
its faces 5 mm from the fingers at rest), friction coefficient 0.5: the curling fingertips
meet its two faces and squeeze it harder as the pull grows. Contact is Incremental Potential
Contact (a log barrier on the distances between the gripper's boundary and the box, active
below ``dhat``, a collision-bounded Newton line search, lagged smoothed Coulomb friction).

The fingers close with gravity off (``sf.actuate`` on both pulls together, warm-started),
then gravity (0, 0, -9.81) m/s^2 is switched on along the fingers at the last pull: the
fingertips would slide down the box, and friction holds part of the fingers' weight.

The script exits with status 1 unless every check passes:

* ``reaches_the_box``: no contact at rest; contact at the last pull.
* ``squeeze_is_symmetric``: the box pushes the two fingers apart with equal and opposite
  forces along y (and equal ones along x and z): the setup (mesh, tendons, box faces) is its
  own mirror image about y = 0, so the right side's force and the mirror image of the left
  side's differ by at most 1e-6 of it (the solver's tolerance, not a modelling allowance).
* ``squeeze_grows_with_pull``: once in contact, each side's squeeze force grows at every
  further pull.
* ``no_penetration``: no accepted Newton iterate of any solve touched the box, and every node
  ends outside it.
* ``balance``: clamp reactions + the box's force + the motors' pulls on the tendons + the
  weight = 0, to 1e-8 of the largest of them, at the last pull with and without gravity.
* ``friction_holds_weight``: switching gravity on, the box's force on the fingers along +z
  (its friction: the faces' normals are along y) grows by a share of the gripper's weight W,
  0 < dF_z <= W, while on each side it stays within the friction cone, |F_t| <= mu |F_n|
  (to 1e-3: the friction is lagged, its normal forces those of the state it was lagged at).

Outputs in ``--out DIR`` (default ``results/two_finger_gripper``): ``result.vtu`` (with
``contact_force``), ``shape.png``, ``force.png`` (squeeze force against the pull) and
``summary.json``. ``--quick`` (what the test suite runs) uses a coarser mesh and fewer pulls.

Run::

    python examples/14_two_finger_gripper.py --out results/two_finger_gripper
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

import sorofem as sf

PALM = (0.02, 0.035, 0.01)  # m: depth (x), half-span (y), thickness (z); the palm is z in [0, 0.01]
FINGER = (0.06, 0.01)  # m: length (down from z = 0), thickness (y)
INNER = 0.025  # m: |y| of the fingers' inner faces
CELL = {True: 0.005, False: 0.0025}  # m
YOUNGS_MODULUS = 150e3  # Pa
POISSON_RATIO = 0.45
DENSITY = 1070.0  # kg/m^3
GRAVITY = np.array([0.0, 0.0, -9.81])  # m/s^2
TENDON_INSET = 0.0025  # m: the tendon runs this far inside the inner face
TENDON_TIP = 0.005  # m: tied this far short of the tip
MOTOR_Z = 0.02  # m
BOX_HALF = (0.02, 0.02, 0.03)  # m: half-extents x, y, z
BOX_CENTER = (0.0, 0.0, -0.06)  # m
FRICTION = 0.5
PULLS = {True: np.linspace(0.0, 2.4e-3, 7)[1:], False: np.linspace(0.0, 2.4e-3, 13)[1:]}  # m
TOLERANCE = 1e-10

SYMMETRY_TOLERANCE = 1e-6
BALANCE_TOLERANCE = 1e-8
CONE_TOLERANCE = 1e-3


def half_mesh(cell: float) -> tuple[np.ndarray, np.ndarray]:
    """Points and tets of the half y >= 0: the palm's half and one finger, on one grid."""
    depth, span, thick = PALM
    length, finger = FINGER
    cells = np.rint(np.array([depth, span, length + thick]) / cell).astype(int)
    grid = sf.Mesh.box(size=(depth, span, length + thick), cells=cells, origin=(-depth / 2, 0.0, -length))
    centroids = grid.points[grid.tets].mean(axis=1)
    keep = (centroids[:, 2] > 0.0) | (centroids[:, 1] > INNER) & (centroids[:, 1] < INNER + finger)
    tets = grid.tets[keep]
    used, inverse = np.unique(tets, return_inverse=True)
    return grid.points[used], inverse.reshape(-1, 4)


def gripper_mesh(cell: float) -> sf.Mesh:
    """The half mirrored about y = 0, nodes on the plane shared: an exactly symmetric mesh."""
    points, tets = half_mesh(cell)
    on_plane = np.abs(points[:, 1]) < 1e-12
    off = np.flatnonzero(~on_plane)
    mirror = np.arange(len(points))
    mirror[off] = len(points) + np.arange(len(off))
    mirrored = points[off] * np.array([1.0, -1.0, 1.0])
    return sf.Mesh(np.vstack([points, mirrored]), np.vstack([tets, mirror[tets]]))


def tendon(side: float, cell: float) -> sf.Cable:
    """From the motor above the palm down the inner side of the finger at ``y = side * ...``."""
    y = side * (INNER + TENDON_INSET)
    z = np.arange(PALM[2] / 2, -FINGER[0] + TENDON_TIP - 1e-12, -cell)
    points = np.vstack([[0.0, y, MOTOR_Z], np.c_[np.zeros_like(z), np.full_like(z, y), z]])
    return sf.Cable(points, model="tendon", anchor_first=True)


def build(quick: bool) -> tuple[sf.Body, list[sf.Cable]]:
    mesh = gripper_mesh(CELL[quick])
    material = sf.NeoHookean(youngs_modulus=YOUNGS_MODULUS, poisson_ratio=POISSON_RATIO, density=DENSITY)
    body = sf.Body(mesh, material)
    body.fix(mesh.nodes_on_plane((0.0, 0.0, PALM[2]), (0.0, 0.0, 1.0)))
    cables = [tendon(side, CELL[quick]) for side in (1.0, -1.0)]
    for cable in cables:
        body.add_cable(cable)
    box = sf.Box(min=np.subtract(BOX_CENTER, BOX_HALF), max=np.add(BOX_CENTER, BOX_HALF))
    body.add_obstacle(box, friction=FRICTION)
    return body, cables


def lumped_weight(mesh: sf.Mesh, gravity: np.ndarray) -> np.ndarray:
    """``rho V g / 4`` per tet and node, ``(n_nodes, 3)``, N."""
    forces = np.zeros((mesh.n_nodes, 3))
    for a in range(4):
        np.add.at(forces, mesh.tets[:, a], (DENSITY * mesh.volumes / 4.0)[:, None] * gravity[None, :])
    return forces


def side_forces(result: sf.StaticResult) -> np.ndarray:
    """The box's force on the right (y > 0) and the left finger, ``(2, 3)``, N."""
    y = result.mesh.points[:, 1]
    f = result.contact_forces
    return np.array([f[y > 0].sum(axis=0), f[y < 0].sum(axis=0)])


def balance(body: sf.Body, result: sf.StaticResult, gravity: np.ndarray) -> float:
    """|clamp reactions + box + motors + weight| over the largest of them."""
    motors = sum(a for a in result.anchor_reactions if a is not None)
    weight = lumped_weight(body.mesh, gravity).sum(axis=0)
    parts = [result.reactions.sum(axis=0), result.obstacle_forces[0], motors, weight]
    return float(np.linalg.norm(sum(parts))) / max(float(np.linalg.norm(p)) for p in parts)


def set_pull(body: sf.Body, cables: list[sf.Cable], pull: float) -> None:
    for cable in cables:
        body.pull(cable, displacement=pull)


def plot_force(pulls: list[float], squeeze: list[float], path: Path) -> None:
    from sorofem.plot import _new_figure

    fig = _new_figure((6.0, 4.0))
    ax = fig.add_subplot()
    ax.plot(1e3 * np.asarray(pulls), squeeze, "o-", markersize=3)
    ax.set_xlabel("tendon pull [mm]")
    ax.set_ylabel("squeeze force per side |F_y| [N]")
    ax.set_title("two-finger gripper: squeeze against the pull")
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)


def run(out_dir: str | Path = "results/two_finger_gripper", quick: bool = False) -> dict[str, Any]:
    """Build, solve, write the outputs to ``out_dir`` and return the summary (``checks`` inside)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    body, cables = build(quick)
    mesh = body.mesh
    no_gravity = np.zeros(3)
    rest = sf.solve_static(body, tolerance=TOLERANCE)
    path = [rest]
    for pull in PULLS[quick]:
        set_pull(body, cables, float(pull))
        path.append(sf.solve_static(body, tolerance=TOLERANCE, initial=path[-1]))
    closed = path[-1]
    held = sf.solve_static(body, gravity=GRAVITY, tolerance=TOLERANCE, initial=closed)
    t1 = time.perf_counter()

    pulls = [0.0] + [float(p) for p in PULLS[quick]]
    sides = [side_forces(r) for r in path]
    squeeze = [float(s[0, 1]) for s in sides]  # the box pushes the right finger towards +y
    touching = [r.active_contacts > 0 for r in path]
    first = touching.index(True) if any(touching) else len(path)
    final = sides[-1]
    mirror = np.array([1.0, -1.0, 1.0])
    asymmetry = float(np.linalg.norm(final[0] - mirror * final[1])) / max(float(np.linalg.norm(final[0])), 1e-300)
    grows = bool(np.all(np.diff([s[0, 1] for s in sides[first:]]) > 0)
                 and np.all(np.diff([-s[1, 1] for s in sides[first:]]) > 0))

    lo, hi = np.asarray(BOX_CENTER) - BOX_HALF, np.asarray(BOX_CENTER) + BOX_HALF
    solves = path + [held]
    inside = [bool(np.all((r.positions > lo) & (r.positions < hi), axis=1).any()) for r in solves]
    iterate_gaps = np.concatenate([r.contact.iterate_min_distances for r in solves if r.contact is not None])

    weight = float(-lumped_weight(mesh, GRAVITY).sum(axis=0)[2])
    closing_cone = [float(np.hypot(s[0], s[2]) / (FRICTION * abs(s[1]))) for s in final]
    held_sides = side_forces(held)
    lifted = float(held.obstacle_forces[0][2] - closed.obstacle_forces[0][2])
    cone = [float(np.hypot(s[0], s[2]) / (FRICTION * abs(s[1]))) for s in held_sides]

    checks = {
        "reaches_the_box": {
            "passed": bool(not touching[0] and touching[-1]),
            "value": {"rest_distance": rest.min_distance, "dhat": body.dhat,
                      "first_contact_pull": pulls[first] if first < len(path) else None},
            "limit": "no contact at rest, contact at the last pull",
        },
        "squeeze_is_symmetric": {
            "passed": bool(asymmetry < SYMMETRY_TOLERANCE),
            "value": {"right": final[0].tolist(), "left": final[1].tolist(), "relative_difference": asymmetry},
            "limit": f"|F_right - M F_left| < {SYMMETRY_TOLERANCE:g} |F_right|, M the mirror y -> -y",
        },
        "squeeze_grows_with_pull": {
            "passed": bool(first < len(path) - 1 and grows),
            "value": squeeze,
            "limit": "each side's |F_y| increases at every pull after the first contact",
        },
        "no_penetration": {
            "passed": bool(np.all(iterate_gaps > 0) and not any(inside)),
            "value": {"min_iterate_distance": float(iterate_gaps.min(initial=np.inf)), "nodes_inside": inside},
            "limit": "distance to the box > 0 at every accepted iterate, no node inside it",
        },
        "balance": {
            "passed": bool(max(balance(body, closed, no_gravity), balance(body, held, GRAVITY)) < BALANCE_TOLERANCE),
            "value": {"closed": balance(body, closed, no_gravity), "held": balance(body, held, GRAVITY)},
            "limit": f"|R + F_box + A + W| < {BALANCE_TOLERANCE:g} x the largest",
        },
        "friction_holds_weight": {
            "passed": bool(0.0 < lifted <= weight and max(cone) <= 1.0 + CONE_TOLERANCE),
            "value": {"box_force_z_change": lifted, "weight": weight, "share": lifted / weight, "cone_ratio": cone},
            "limit": f"0 < dF_z <= W, |F_t| / (mu |F_n|) <= 1 + {CONE_TOLERANCE:g} per side",
        },
    }
    sf.io.write_result(out / "result.vtu", held)
    sf.plot.plot_rest_and_deformed(held, out / "shape.png",
                                   title=f"gripper squeezing a box: {squeeze[-1]:.3f} N per side at {1e3 * pulls[-1]:.1f} mm")
    plot_force(pulls, squeeze, out / "force.png")
    summary = {
        "example": "14_two_finger_gripper",
        "n_nodes": mesh.n_nodes,
        "n_tets": mesh.n_tets,
        "dhat": body.dhat,
        "path": [{"pull": p, "right": s[0].tolist(), "left": s[1].tolist(), "active_contacts": r.active_contacts,
                  "tension": r.cable_tension[0], "iterations": r.report.iterations}
                 for p, s, r in zip(pulls, sides, path)],
        "held": {"right": held_sides[0].tolist(), "left": held_sides[1].tolist(),
                 "iterations": held.report.iterations},
        "closed_cone_ratio": closing_cone,
        "checks": checks,
        "passed": all(c["passed"] for c in checks.values()),
        "files": ["result.vtu", "shape.png", "force.png", "summary.json"],
        "timings": {"solves": t1 - t0, "total": time.perf_counter() - t0},
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    return summary


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("results/two_finger_gripper"), metavar="DIR")
    parser.add_argument("--quick", action="store_true", help="a coarser mesh and fewer pulls")
    args = parser.parse_args(argv)
    try:
        summary = run(args.out, quick=args.quick)
    except sf.ConvergenceError as exc:
        print(f"error: the solver did not converge: {exc}", file=sys.stderr)
        return 3
    for step in summary["path"]:
        print(f"pull {1e3 * step['pull']:.2f} mm: box force right {np.round(step['right'], 4).tolist()} N, "
              f"left {np.round(step['left'], 4).tolist()} N, {step['active_contacts']} active contacts, "
              f"{step['iterations']} Newton iterations")
    print(f"gravity on: right {np.round(summary['held']['right'], 4).tolist()} N, "
          f"left {np.round(summary['held']['left'], 4).tolist()} N")
    for name, check in summary["checks"].items():
        print(f"[{'ok' if check['passed'] else 'FAILED'}] {name}: {check['limit']}")
    print(f"{'all checks passed' if summary['passed'] else 'SOME CHECKS FAILED'}; wrote {', '.join(summary['files'])} "
          f"to {args.out} in {summary['timings']['total']:.1f} s")
    return 0 if summary["passed"] else 1


if __name__ == "__main__":
    sys.exit(main())
