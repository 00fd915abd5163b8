"""A cable-driven silicone finger, meshed from a generated surface, curling onto a sphere and
pressing on it, with physics checks: the contact force against the pull.

The finger of example 10: a closed triangle surface (120 mm long along x, a rounded-square
cross-section tapering from 12.5 to 7.5 mm half-width, written as a binary STL), filled with
tetrahedra by ``sf.tetrahedralize`` (fTetWild, the optional extra ``mesh``), silicone
like Dragon Skin 10 (Neo-Hookean, E = 150 kPa, nu = 0.49, rho = 1070 kg/m^3) in the mixed
formulation, its base clamped, under gravity (0, 0, -9.81) m/s^2. A cable on its upper side,
from a motor behind the clamp (a world anchor) to 6 mm short of the tip, 12 segments of
1e5 N/m, curls it upwards as the motor winds it in (alpha from 1 down to 0.88, by continuation
with ``sf.actuate``).

Above the finger hangs a rigid ball the size of a football (radius 120 mm, its lowest point 20 mm
above the finger's axis, 70 mm out; frictionless): the curling finger meets it and presses on it
harder as the pull grows. Pressing a slender finger on a frictionless ball is stable only while
the ball's curvature pushes sideways less than the finger resists bending sideways (a lateral
slip at about F / R N/m against ~7 N/m here): a 15 mm ball let the finger slip off it sideways
beyond 0.1 N, a football-sized one holds it centred. Contact is Incremental
Potential Contact (a log barrier on the distance between the finger's boundary and the ball,
active below ``dhat``, and a collision-bounded Newton line search), so the finger never enters
the ball at any iterate.

The script exits with status 1 unless every check passes:

* ``reaches_the_ball``: at rest the finger is farther than ``dhat`` from the ball (no force);
  at the last pull it presses on it.
* ``force_grows_with_pull``: once in contact, the ball's force on the finger grows at every
  further pull.
* ``presses_down``: the ball pushes the finger down (F_z < 0): it resists the upward curl.
* ``stays_centred``: the setup is symmetric about y = 0, so the sideways force is at most 5 %
  of the contact force (the mesh is not exactly symmetric).
* ``no_penetration``: no accepted Newton iterate of any solve touched the ball, and the
  finger's nodes end outside it.
* ``balance``: clamp reactions + the ball's force + the motor's pull on the cable + the weight
  = 0, to 1e-8 of the largest of them (forces; moments about the origin to 1e-8 of that times
  the length).

Outputs in ``--out DIR`` (default ``results/finger_on_sphere``): ``finger.stl``, ``result.vtu``
(last pull, with ``contact_force``), ``shape.png``, ``force.png`` (contact force against the
pull) and ``summary.json``. ``--quick`` (what the test suite runs) uses a coarser mesh and
larger pull steps.

Run::

    pip install ".[mesh]"     # from a checkout of sorofem
    python examples/13_finger_on_sphere.py --out results/finger_on_sphere
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

REQUIRED_MODULES = (sf.meshing.MESHER,)

LENGTH = 0.12  # m
HALF_WIDTH = (0.0125, 0.0075)  # m, base and tip
EXPONENT = 4.0  # superellipse cross-section |y/a|^p + |z/a|^p = 1
N_AROUND = 24
YOUNGS_MODULUS = 150e3  # Pa
POISSON_RATIO = 0.49
DENSITY = 1070.0  # kg/m^3
GRAVITY = np.array([0.0, 0.0, -9.81])  # m/s^2
ENVELOPE = 1e-3  # fTetWild's envelope, fraction of the bounding-box diagonal
EDGE_LENGTH = {True: 0.006, False: 0.003}  # m
CABLE_HEIGHT = 0.5  # the cable at z = 0.5 a(x)
CABLE_X = (0.005, LENGTH - 0.006)
MOTOR_X = -0.01
CABLE_DIVISIONS = 12
CABLE_STIFFNESS = 1e5  # N/m
BALL_CENTER = (0.07, 0.0, 0.14)  # m
BALL_RADIUS = 0.12  # m
PULL = {True: np.arange(1.0, 0.8799, -0.02), False: np.arange(1.0, 0.8799, -0.01)}
CENTRED = 0.05  # |F_y| / |F| at most
TOLERANCE = 1e-10

BALANCE_TOLERANCE = 1e-8


def half_width(x: np.ndarray | float) -> np.ndarray | float:
    return HALF_WIDTH[0] + (HALF_WIDTH[1] - HALF_WIDTH[0]) * np.asarray(x) / LENGTH


def finger_surface() -> tuple[np.ndarray, np.ndarray]:
    """The closed, outward-oriented surface: base ring, tip ring, two cap centres."""
    theta = np.linspace(0.0, 2.0 * np.pi, N_AROUND, endpoint=False)
    c, s = np.cos(theta), np.sin(theta)
    r = (np.abs(c) ** EXPONENT + np.abs(s) ** EXPONENT) ** (-1.0 / EXPONENT)
    rings = [np.c_[np.full(N_AROUND, x), half_width(x) * r * c, half_width(x) * r * s] for x in (0.0, LENGTH)]
    points = np.vstack(rings + [[[0.0, 0.0, 0.0], [LENGTH, 0.0, 0.0]]])
    n = N_AROUND
    j = np.arange(n)
    k = (j + 1) % n
    sides = np.r_[np.c_[j, k, k + n], np.c_[j, k + n, j + n]]
    base = np.c_[np.full(n, 2 * n), k, j]
    tip = np.c_[np.full(n, 2 * n + 1), j + n, k + n]
    return points, np.r_[sides, base, tip].astype(np.int64)


def lumped_weight(mesh: sf.Mesh) -> np.ndarray:
    """``rho V g / 4`` per tet and node, ``(n_nodes, 3)``, N."""
    forces = np.zeros((mesh.n_nodes, 3))
    for a in range(4):
        np.add.at(forces, mesh.tets[:, a], (DENSITY * mesh.volumes / 4.0)[:, None] * GRAVITY[None, :])
    return forces


def build(stl: Path, quick: bool) -> tuple[sf.Body, sf.Cable]:
    mesh = sf.tetrahedralize(stl, edge_length=EDGE_LENGTH[quick], envelope=ENVELOPE)
    material = sf.NeoHookean(youngs_modulus=YOUNGS_MODULUS, poisson_ratio=POISSON_RATIO, density=DENSITY)
    body = sf.Body(mesh, material, formulation="mixed")
    on_boundary = np.unique(mesh.boundary_faces())
    body.fix(np.intersect1d(mesh.nodes_on_plane((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), tol=ENVELOPE), on_boundary))
    x = np.linspace(CABLE_X[0], CABLE_X[1], CABLE_DIVISIONS + 1)
    inside = np.c_[x, np.zeros_like(x), CABLE_HEIGHT * half_width(x)]
    motor = [MOTOR_X, 0.0, CABLE_HEIGHT * HALF_WIDTH[0]]
    cable = sf.Cable(np.vstack([motor, inside]), stiffness=CABLE_STIFFNESS, anchor_first=True)
    body.add_cable(cable)
    body.add_obstacle(sf.Sphere(center=BALL_CENTER, radius=BALL_RADIUS))
    return body, cable


def plot_force(alphas: list[float], forces: list[float], path: Path) -> None:
    from sorofem.plot import _new_figure

    fig = _new_figure((6.0, 4.0))
    ax = fig.add_subplot()
    ax.plot(1.0 - np.asarray(alphas), forces, "o-", markersize=3)
    ax.set_xlabel("pull 1 - alpha")
    ax.set_ylabel("ball force on the finger |F| [N]")
    ax.set_title("contact force against the pull")
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)


def run(out_dir: str | Path = "results/finger_on_sphere", quick: bool = False) -> dict[str, Any]:
    """Mesh, simulate, write the outputs to ``out_dir`` and return the summary (``checks`` inside)."""
    import meshio

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    points, triangles = finger_surface()
    stl = out / "finger.stl"
    meshio.write(stl, meshio.Mesh(points, [("triangle", triangles)]), file_format="stl", binary=True)
    body, cable = build(stl, quick)
    mesh = body.mesh
    t1 = time.perf_counter()
    rest = sf.solve_static(body, gravity=GRAVITY, tolerance=TOLERANCE)
    path = [rest] + sf.actuate(body, cable, list(PULL[quick][1:]), gravity=GRAVITY, tolerance=TOLERANCE,
                               initial=rest)
    t2 = time.perf_counter()
    final = path[-1]
    alphas = [r.actuations[0] for r in path]
    forces = [float(np.linalg.norm(r.obstacle_forces[0])) for r in path]
    touching = [r.contact is not None and r.active_contacts > 0 for r in path]
    first = touching.index(True) if any(touching) else len(path)

    f_grav = lumped_weight(mesh)
    pull = final.anchor_reactions[0]
    assert pull is not None
    ball = final.obstacle_forces[0]
    reactions = final.reactions.sum(axis=0)
    scale = max(float(np.linalg.norm(v)) for v in (reactions, ball, pull, f_grav.sum(axis=0)))
    force_error = float(np.linalg.norm(reactions + ball + pull + f_grav.sum(axis=0))) / scale
    motor = final.cable_points[0][0]
    fixed = body.fixed_nodes
    moment = (np.cross(final.positions[fixed], final.reactions).sum(axis=0)
              + np.cross(final.positions, final.contact_forces + f_grav).sum(axis=0) + np.cross(motor, pull))
    moment_error = float(np.linalg.norm(moment)) / (scale * LENGTH)
    inside = np.linalg.norm(final.positions - np.asarray(BALL_CENTER), axis=1).min() - BALL_RADIUS
    iterate_gaps = np.concatenate([r.contact.iterate_min_distances for r in path if r.contact is not None])

    checks = {
        "reaches_the_ball": {
            "passed": bool(not touching[0] and touching[-1] and forces[0] == 0.0 and forces[-1] > 0),
            "value": {"rest_distance": rest.min_distance, "dhat": body.dhat, "final_force": forces[-1],
                      "first_contact_alpha": alphas[first] if first < len(path) else None},
            "limit": "no force at rest, a force at the last pull",
        },
        "force_grows_with_pull": {
            "passed": bool(first < len(path) - 1 and np.all(np.diff(forces[first:]) > 0)),
            "value": forces,
            "limit": "|F| increases at every pull after the first contact",
        },
        "presses_down": {
            "passed": bool(ball[2] < 0),
            "value": ball.tolist(),
            "limit": "F_z < 0",
        },
        "stays_centred": {
            "passed": bool(abs(ball[1]) <= CENTRED * np.linalg.norm(ball)),
            "value": float(abs(ball[1]) / max(np.linalg.norm(ball), 1e-300)),
            "limit": f"|F_y| <= {CENTRED:g} |F|",
        },
        "no_penetration": {
            "passed": bool(np.all(iterate_gaps > 0) and inside > 0),
            "value": {"min_iterate_distance": float(iterate_gaps.min()), "final_min_distance": float(inside)},
            "limit": "distance to the ball > 0 at every accepted iterate and at the end",
        },
        "balance": {
            "passed": force_error < BALANCE_TOLERANCE and moment_error < BALANCE_TOLERANCE,
            "value": {"force": force_error, "moment": moment_error},
            "limit": f"|R + F_ball + A + W| < {BALANCE_TOLERANCE:g} x the largest, moments likewise",
        },
    }
    sf.io.write_result(out / "result.vtu", final)
    sf.plot.plot_rest_and_deformed(final, out / "shape.png",
                                   title=f"finger pressing on a ball: |F| = {forces[-1]:.3f} N at alpha = {alphas[-1]:.2f}")
    plot_force(alphas, forces, out / "force.png")
    summary = {
        "example": "13_finger_on_sphere",
        "n_nodes": mesh.n_nodes,
        "n_tets": mesh.n_tets,
        "dhat": body.dhat,
        "path": [{"alpha": a, "force": r.obstacle_forces[0].tolist(), "active_contacts": r.active_contacts,
                  "min_distance": r.min_distance, "iterations": r.report.iterations} for a, r in zip(alphas, path)],
        "checks": checks,
        "passed": all(c["passed"] for c in checks.values()),
        "files": ["finger.stl", "result.vtu", "shape.png", "force.png", "summary.json"],
        "timings": {"mesh": t1 - t0, "solves": t2 - t1, "total": time.perf_counter() - t0},
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    return summary


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("results/finger_on_sphere"), metavar="DIR")
    parser.add_argument("--quick", action="store_true", help="a coarser mesh and larger pull steps")
    args = parser.parse_args(argv)
    try:
        import pytetwild  # noqa: F401
    except ImportError:
        print(f"error: this example needs the mesher: {sf.meshing.INSTALL_HINT}", file=sys.stderr)
        return 2
    try:
        summary = run(args.out, quick=args.quick)
    except sf.ConvergenceError as exc:
        print(f"error: the solver did not converge: {exc}", file=sys.stderr)
        return 3
    for step in summary["path"]:
        print(f"alpha {step['alpha']:.2f}: ball force {np.round(step['force'], 4).tolist()} N, "
              f"{step['active_contacts']} active contacts, {step['iterations']} Newton iterations")
    for name, check in summary["checks"].items():
        print(f"[{'ok' if check['passed'] else 'FAILED'}] {name}: {check['limit']}")
    print(f"{'all checks passed' if summary['passed'] else 'SOME CHECKS FAILED'}; wrote {', '.join(summary['files'])} "
          f"to {args.out} in {summary['timings']['total']:.1f} s")
    return 0 if summary["passed"] else 1


if __name__ == "__main__":
    sys.exit(main())
