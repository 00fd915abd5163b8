"""The SolidFEM hammerbot hanging under gravity, bent by one of its two cables, with physics checks.

The mesh is ``hammerbot_fine.tet`` from the SolidFEM samples (``../shared/data/solidfem``, beside
the repository), scaled by 0.01 to metres without the sample's y-z axis swap: 2346 nodes,
9011 tets. It is an H-shaped slab, 2 cm thick (z in [-1, 1] cm): two flanges 2 cm wide across the
whole width (x in [-5, -3] and [3, 5] cm, y in [-2.5, 2.5] cm) joined by a web 1.5 cm wide
(|y| < 0.75 cm). The 92 nodes of the face x = -5 cm are clamped (the sample's ``hammerbot.xml``
lists the same nodes); material as in ``hammerbot.xml``: Neo-Hookean, E = 100 kPa, nu = 0.4,
rho = 1070 kg/m^3; gravity (0, -9.8, 0) m/s^2, so the robot sags in its own plane towards -y.

Cable routing (both in the mid-plane z = 0, from x = -4.5 to +4.5 cm, 18 segments of 5 mm,
segment stiffness 50 kN/m): cable 0 at y = +6 mm and cable 1 at y = -6 mm, i.e. 1.5 mm inside
the web's two long faces, through both flanges. Every point lies inside a tetrahedron
(``body.cable_placements()`` reports all 19 points of each cable as "embedded"; the check
``cables_embedded`` asserts it). Cable 0 is pulled to alpha = 0.82, cable 1 is paid out to
alpha = 1.2.

The script exits with status 1 unless every check passes:

* ``cables_embedded``: every cable point lies inside the mesh (none snapped or free).
* ``converged``: both solves converged.
* ``pulled_cable_taut``: every segment of the alpha = 0.82 cable carries tension, and its
  deformed length is below its rest length (the +y side shortens).
* ``paid_out_cable_slack``: the alpha = 1.2 cable carries no tension at all.
* ``bends_towards_pulled_side``: the free end (x = +5 cm) rises above where gravity alone
  leaves it, and above its rest position (u_y > 0).
* ``force_balance``: the cables are internal, so the support reactions balance the weight alone
  (relative 1e-6).
* ``virtual_work``: the derivative of the total potential energy at equilibrium with respect to
  the pulled cable's alpha (central differences, two more solves at alpha +- 1e-4) equals
  ``-sum_s T_s l_s``, the work of its reported tensions on the rest lengths (envelope theorem),
  to 1e-6: the tensions against the energy the body actually minimises.

Outputs in ``--out DIR`` (default ``results/hammerbot``): ``result.vtu``, ``cables.vtu``,
``shape.png`` (rest and deformed shape, cables in red), ``gravity_only.png`` and ``summary.json``.

Run::

    python examples/04_hammerbot_cables.py --out results/hammerbot
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

DATA = Path(__file__).resolve().parent.parent.parent / "shared" / "data" / "solidfem"
MESH_FILE = DATA / "hammerbot_fine.tet"
#: Files the example needs; tests/test_examples.py skips it when one is missing.
REQUIRED_FILES = (MESH_FILE,)

SCALE = 0.01  # the .tet file is in centimetres
YOUNGS_MODULUS = 100e3  # Pa
POISSON_RATIO = 0.4
DENSITY = 1070.0  # kg/m^3
GRAVITY = np.array([0.0, -9.8, 0.0])  # m/s^2
CLAMP_X = -0.05  # m
TIP_X = 0.05  # m
CABLE_Y = 0.006  # m: cables at y = +-6 mm, 1.5 mm inside the web's faces
CABLE_X = (-0.045, 0.045)  # m
CABLE_DIVISIONS = 18
CABLE_STIFFNESS = 50e3  # N/m per segment
ALPHAS = (0.82, 1.2)
TOLERANCE = 1e-8

BALANCE_TOLERANCE = 1e-6
VIRTUAL_WORK_STEP = 1e-4  # alpha
VIRTUAL_WORK_TOLERANCE = 1e-6


def build() -> sf.Body:
    if not MESH_FILE.is_file():
        raise FileNotFoundError(
            f"this example needs the SolidFEM sample mesh {MESH_FILE} (../shared/data/solidfem beside the repository)"
        )
    mesh = sf.Mesh.read(MESH_FILE, scale=SCALE)
    material = sf.NeoHookean(youngs_modulus=YOUNGS_MODULUS, poisson_ratio=POISSON_RATIO, density=DENSITY)
    body = sf.Body(mesh, material)
    body.fix(mesh.nodes_on_plane((CLAMP_X, 0.0, 0.0), (1.0, 0.0, 0.0)))
    return body


def cables() -> list[sf.Cable]:
    length = CABLE_X[1] - CABLE_X[0]
    return [
        sf.Cable.line((CABLE_X[0], y, 0.0), (1.0, 0.0, 0.0), length, CABLE_DIVISIONS,
                      stiffness=CABLE_STIFFNESS, actuation=alpha)
        for y, alpha in ((CABLE_Y, ALPHAS[0]), (-CABLE_Y, ALPHAS[1]))
    ]


def virtual_work_error(body: sf.Body, cable: int, result: sf.StaticResult) -> float:
    """``|dPi/dalpha + sum_s T_s l_s| / sum_s T_s l_s`` for one cable at ``result``,
    ``dPi/dalpha`` by central differences of the equilibrium energy; leaves the body as it was."""
    alpha = result.actuations[cable]
    energies = []
    for a in (alpha + VIRTUAL_WORK_STEP, alpha - VIRTUAL_WORK_STEP):
        body.set_actuation(cable, a)
        moved = sf.solve_static(body, gravity=GRAVITY, tolerance=1e-10, initial=result)
        energies.append(moved.report.energy_history[-1])
    body.set_actuation(cable, alpha)
    derivative = (energies[0] - energies[1]) / (2 * VIRTUAL_WORK_STEP)
    work = float(result.cable_tensions[cable] @ body.cables[cable].rest_lengths)
    return abs(derivative + work) / work


def run(out_dir: str | Path = "results/hammerbot") -> dict[str, Any]:
    """Simulate, write the outputs to ``out_dir`` and return the summary (``checks`` inside)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    body = build()
    mesh = body.mesh
    gravity_only = sf.solve_static(body, gravity=GRAVITY, tolerance=TOLERANCE)
    t1 = time.perf_counter()
    pulled, paid_out = cables()
    body.add_cable(pulled)
    body.add_cable(paid_out)
    placements = body.cable_placements()
    result = sf.solve_static(body, gravity=GRAVITY, tolerance=TOLERANCE, initial=gravity_only)
    t2 = time.perf_counter()

    tip = mesh.nodes_on_plane((TIP_X, 0.0, 0.0), (1.0, 0.0, 0.0))
    u_tip = result.displacement[tip].mean(axis=0)
    u_tip_gravity = gravity_only.displacement[tip].mean(axis=0)
    lengths = [float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum()) for p in result.cable_points]
    tensions = result.cable_tensions

    weight = float(DENSITY * mesh.volumes.sum()) * GRAVITY
    force_error = float(np.linalg.norm(result.reactions.sum(axis=0) + weight) / np.linalg.norm(weight))
    work_error = virtual_work_error(body, 0, result)
    kinds = [[p.kind for p in cable] for cable in placements]

    checks = {
        "cables_embedded": {
            "passed": all(k == "embedded" for cable in kinds for k in cable),
            "value": [{kind: cable.count(kind) for kind in sorted(set(cable))} for cable in kinds],
            "limit": "every cable point inside a tetrahedron",
        },
        "converged": {
            "passed": gravity_only.report.converged and result.report.converged,
            "value": {"gravity_only": gravity_only.report.iterations, "with_cables": result.report.iterations},
            "limit": "Newton converged",
        },
        "pulled_cable_taut": {
            "passed": bool(np.all(tensions[0] > 0) and lengths[0] < pulled.length),
            "value": {"min_tension": float(tensions[0].min()), "length_over_rest": lengths[0] / pulled.length},
            "limit": "all tensions > 0 N and length < rest length",
        },
        "paid_out_cable_slack": {
            "passed": bool(np.all(tensions[1] == 0)),
            "value": float(tensions[1].max()),
            "limit": "max tension = 0 N",
        },
        "bends_towards_pulled_side": {
            "passed": bool(u_tip[1] > u_tip_gravity[1] and u_tip[1] > 0),
            "value": {"tip_uy": float(u_tip[1]), "gravity_only_tip_uy": float(u_tip_gravity[1])},
            "limit": "u_y(tip) > u_y(tip, gravity only) and > 0",
        },
        "force_balance": {
            "passed": force_error < BALANCE_TOLERANCE,
            "value": force_error,
            "limit": f"|sum R + W| / |W| < {BALANCE_TOLERANCE:g}",
        },
        "virtual_work": {
            "passed": work_error < VIRTUAL_WORK_TOLERANCE,
            "value": work_error,
            "limit": f"|dPi/dalpha + sum T l| / sum T l < {VIRTUAL_WORK_TOLERANCE:g} (pulled cable)",
        },
    }

    sf.io.write_result(out / "result.vtu", result)
    sf.cables.write_cables(out / "cables.vtu", result)
    sf.plot.plot_rest_and_deformed(
        result, out / "shape.png",
        title=f"hammerbot, cables at alpha = {ALPHAS[0]} (+y) and {ALPHAS[1]} (-y): tip u_y = {u_tip[1] * 100:.2f} cm",
    )
    sf.plot.plot_rest_and_deformed(
        gravity_only, out / "gravity_only.png", title=f"hammerbot under gravity alone: tip u_y = {u_tip_gravity[1] * 100:.2f} cm"
    )
    summary = {
        "example": "04_hammerbot_cables",
        "mesh": str(MESH_FILE),
        "n_nodes": mesh.n_nodes,
        "n_tets": mesh.n_tets,
        "n_fixed": int(body.fixed_nodes.size),
        "cables": [c.to_dict() | {"actuation": a} for c, a in zip(body.cables, ALPHAS)],
        "placements": kinds,
        "tip_displacement": u_tip.tolist(),
        "gravity_only_tip_displacement": u_tip_gravity.tolist(),
        "tensions": [t.tolist() for t in tensions],
        "cable_lengths": lengths,
        "newton_iterations": {"gravity_only": gravity_only.report.iterations, "with_cables": result.report.iterations},
        "min_J": float(result.J.min()),
        "checks": checks,
        "passed": all(c["passed"] for c in checks.values()),
        "files": ["result.vtu", "cables.vtu", "shape.png", "gravity_only.png", "summary.json"],
        "timings": {"gravity_only": t1 - t0, "with_cables": t2 - t1, "solver": dict(result.report.timings),
                    "total": time.perf_counter() - t0},
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    return summary


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("results/hammerbot"), metavar="DIR")
    args = parser.parse_args(argv)
    try:
        summary = run(args.out)
    except FileNotFoundError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except sf.ConvergenceError as exc:
        print(f"error: the solver did not converge: {exc}", file=sys.stderr)
        return 3
    print(f"{summary['n_nodes']} nodes, {summary['n_tets']} tets, {summary['n_fixed']} clamped; Newton "
          f"{summary['newton_iterations']}")
    print(f"tip displacement {np.round(summary['tip_displacement'], 4).tolist()} m "
          f"(gravity only {np.round(summary['gravity_only_tip_displacement'], 4).tolist()} m)")
    for c, t in enumerate(summary["tensions"]):
        print(f"cable {c}: tension {min(t):.3f} .. {max(t):.3f} N, length {summary['cable_lengths'][c] * 100:.3f} cm")
    for name, check in summary["checks"].items():
        print(f"[{'ok' if check['passed'] else 'FAILED'}] {name}: {check['limit']}")
    print(f"{'all checks passed' if summary['passed'] else 'SOME CHECKS FAILED'}; wrote {', '.join(summary['files'])} "
          f"to {args.out} in {summary['timings']['total']:.1f} s")
    return 0 if summary["passed"] else 1


if __name__ == "__main__":
    sys.exit(main())
