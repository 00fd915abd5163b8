"""The 0.4 m silicone cantilever sagging under gravity onto a plane below its tip, with physics
checks.

The beam of example 01 (0.4 x 0.1 x 0.1 m, 16 x 4 x 4 hexahedral cells of 6 tets; E = 66 kPa,
nu = 0.45, rho = 1080 kg/m^3, clamped at x = 0, gravity (0, 0, -9.81) m/s^2) sags about 0.27 m
at its tip when nothing is in the way. A rigid floor (the plane z = -0.12, frictionless) stops
it: the tip comes to rest on the floor and the beam bends in an S between the clamp and the
floor. The same solve without the floor gives the free sag.

Contact is Incremental Potential Contact: a log barrier on the distance between the beam's
boundary and the floor, active below ``dhat`` (1 % of the mean boundary edge, 0.26 mm here),
and a Newton line search bounded by continuous collision detection, so that no accepted
iterate crosses the floor (Newton's first step would put the tip 0.3 m through it).

The script exits with status 1 unless every check passes:

* ``free_sag_passes_the_floor``: without the floor the tip sags below it.
* ``rests_on_the_floor``: with the floor, every node stays above it, the lowest within ``dhat``
  of it, and no accepted Newton iterate touched it.
* ``force_balance``: the clamp reactions, the floor's force and the weight balance, to 1e-8 of
  the weight.
* ``moment_balance``: their moments about the origin balance, to 1e-8 of weight x length.
* ``contact_near_the_tip``: the floor pushes up (its force is vertical: frictionless) only on
  nodes in the outer third of the beam, and carries part of the weight, not all of it.
* ``same_iterations``: the contact solve takes no more Newton iterations than 1.5 times the
  free one (the barrier and the collision bound cost no convergence).

Outputs in ``--out DIR`` (default ``results/cantilever_on_plane``): ``result.vtu`` (with
``contact_force``), ``shape.png`` (floor and contact forces drawn), ``summary.json``.

Run::

    python examples/12_cantilever_on_plane.py --out results/cantilever_on_plane
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

SIZE = (0.4, 0.1, 0.1)  # m
CELLS = {False: (16, 4, 4), True: (8, 2, 2)}  # full, quick
YOUNGS_MODULUS = 66e3  # Pa
POISSON_RATIO = 0.45
DENSITY = 1080.0  # kg/m^3
GRAVITY = np.array([0.0, 0.0, -9.81])  # m/s^2
FLOOR = -0.12  # m
TOLERANCE = 1e-10

BALANCE_TOLERANCE = 1e-8


def build(quick: bool, floor: bool) -> sf.Body:
    mesh = sf.Mesh.box(size=SIZE, cells=CELLS[quick])
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=YOUNGS_MODULUS, poisson_ratio=POISSON_RATIO, density=DENSITY))
    body.fix(mesh.nodes_on_plane((0.0, 0.0, 0.0), (1.0, 0.0, 0.0)))
    if floor:
        body.add_obstacle(sf.Plane(point=(0.0, 0.0, FLOOR), normal=(0.0, 0.0, 1.0)))
    return body


def lumped_weight(mesh: sf.Mesh) -> np.ndarray:
    """``rho V g / 4`` per tet and node, ``(n_nodes, 3)``, N."""
    forces = np.zeros((mesh.n_nodes, 3))
    for a in range(4):
        np.add.at(forces, mesh.tets[:, a], (DENSITY * mesh.volumes / 4.0)[:, None] * GRAVITY[None, :])
    return forces


def run(out_dir: str | Path = "results/cantilever_on_plane", quick: bool = False) -> dict[str, Any]:
    """Solve, write the outputs to ``out_dir`` and return the summary (``checks`` inside)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    free = sf.solve_static(build(quick, floor=False), gravity=GRAVITY, tolerance=TOLERANCE)
    t1 = time.perf_counter()
    body = build(quick, floor=True)
    result = sf.solve_static(body, gravity=GRAVITY, tolerance=TOLERANCE)
    t2 = time.perf_counter()
    mesh = body.mesh
    contact = result.contact
    assert contact is not None
    length = SIZE[0]

    f_grav = lumped_weight(mesh)
    weight = f_grav.sum(axis=0)
    w = float(np.linalg.norm(weight))
    fixed = body.fixed_nodes
    forces = result.contact_forces
    total = forces.sum(axis=0)
    force_error = float(np.linalg.norm(result.reactions.sum(axis=0) + total + weight)) / w
    moment = (np.cross(result.positions[fixed], result.reactions).sum(axis=0)
              + np.cross(result.positions, forces + f_grav).sum(axis=0))
    moment_error = float(np.linalg.norm(moment)) / (w * length)
    pushed = np.linalg.norm(forces, axis=1) > 1e-9 * w
    lowest = float(result.positions[:, 2].min())
    free_lowest = float(free.positions[:, 2].min())

    checks = {
        "free_sag_passes_the_floor": {
            "passed": free_lowest < FLOOR,
            "value": free_lowest,
            "limit": f"lowest node without the floor < {FLOOR} m",
        },
        "rests_on_the_floor": {
            "passed": bool(FLOOR < lowest < FLOOR + contact.dhat and np.all(contact.iterate_min_distances > 0)),
            "value": {"gap": lowest - FLOOR, "dhat": contact.dhat,
                      "min_iterate_distance": float(contact.iterate_min_distances.min())},
            "limit": "0 < gap < dhat; gap > 0 at every accepted iterate",
        },
        "force_balance": {
            "passed": force_error < BALANCE_TOLERANCE,
            "value": force_error,
            "limit": f"|sum R + F_floor + W| / |W| < {BALANCE_TOLERANCE:g}",
        },
        "moment_balance": {
            "passed": moment_error < BALANCE_TOLERANCE,
            "value": moment_error,
            "limit": f"|sum x x (R + f_floor + f_g)| / (|W| L) < {BALANCE_TOLERANCE:g}",
        },
        "contact_near_the_tip": {
            "passed": bool(pushed.any() and mesh.points[pushed, 0].min() > 2 * length / 3
                           and np.abs(forces[:, :2]).max() < 1e-12 * w and 0 < total[2] < w),
            "value": {"nodes": int(pushed.sum()), "from_x": float(mesh.points[pushed, 0].min()),
                      "floor_force": total.tolist(), "weight": w},
            "limit": "floor force vertical, on nodes with x > 2L/3 only, 0 < F_z < |W|",
        },
        "same_iterations": {
            "passed": result.report.iterations <= 1.5 * free.report.iterations,
            "value": {"free": free.report.iterations, "floor": result.report.iterations},
            "limit": "iterations with the floor <= 1.5 x without",
        },
    }
    sf.io.write_result(out / "result.vtu", result)
    sf.plot.plot_rest_and_deformed(result, out / "shape.png",
                                   title=f"cantilever on a floor: floor force {total[2]:.2f} N of {w:.2f} N weight")
    summary = {
        "example": "12_cantilever_on_plane",
        "n_nodes": mesh.n_nodes,
        "n_tets": mesh.n_tets,
        "free_tip_sag": -float(free.displacement[:, 2].min()),
        "floor_force": total.tolist(),
        "contact": result.to_dict()["contact"],
        "iterations": {"free": free.report.iterations, "floor": result.report.iterations},
        "checks": checks,
        "passed": all(c["passed"] for c in checks.values()),
        "files": ["result.vtu", "shape.png", "summary.json"],
        "timings": {"free": t1 - t0, "floor": t2 - t1, "contact_pass": result.report.timings.get("contact", 0.0),
                    "total": time.perf_counter() - t0},
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    return summary


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("results/cantilever_on_plane"), metavar="DIR")
    parser.add_argument("--quick", action="store_true", help="a coarser mesh (what the tests run)")
    args = parser.parse_args(argv)
    try:
        summary = run(args.out, quick=args.quick)
    except sf.ConvergenceError as exc:
        print(f"error: the solver did not converge: {exc}", file=sys.stderr)
        return 3
    print(f"free tip sag {summary['free_tip_sag']:.4f} m; on the floor: floor force "
          f"{np.round(summary['floor_force'], 4).tolist()} N; Newton iterations {summary['iterations']}")
    for name, check in summary["checks"].items():
        print(f"[{'ok' if check['passed'] else 'FAILED'}] {name}: {check['limit']}")
    print(f"{'all checks passed' if summary['passed'] else 'SOME CHECKS FAILED'}; wrote {', '.join(summary['files'])} "
          f"to {args.out} in {summary['timings']['total']:.1f} s")
    return 0 if summary["passed"] else 1


if __name__ == "__main__":
    sys.exit(main())
