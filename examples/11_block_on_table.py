"""A soft block, not clamped, resting on a table under gravity with friction, with physics checks.

A 0.1 m silicone cube (8 x 8 x 8 hexahedral cells, 6 tets each; E = 66 kPa, rho = 1080 kg/m^3)
starts 0.1 mm above a table (the plane z = 0, friction coefficient 0.8) and settles on it under
gravity (0, 0, -9.81) m/s^2, in a static solve: nothing holds the block but the table. Contact
is Incremental Potential Contact: a barrier on the distance between the block's boundary and
the table, active below ``dhat`` (1 % of the mean boundary edge here, 0.125 mm), so the block
rests a fraction of ``dhat`` above the table and never touches it; friction is lagged (its
normal forces and directions from the previous state) and solved again until it settles. It
is solved twice: standard linear tetrahedra with nu = 0.45, and the mixed formulation with
nu = 0.49 (nearly incompressible silicone).

The script exits with status 1 unless every check passes:

* ``weight_carried``: the table's total normal force equals the block's weight ``rho V g``
  (relative 1e-6), in both formulations.
* ``no_tangential_force``: the table's total tangential force vanishes (1e-6 of the weight):
  friction only acts where the bottom would spread.
* ``no_penetration``: every node stays above the table, the smallest gap is positive and below
  ``dhat``, and so was the smallest gap at every accepted Newton iterate.
* ``friction_holds_the_bottom``: the bottom face, which carries the weight, spreads sideways
  (Poisson); friction resists it: with the friction coefficient 0.8 it spreads less than a
  quarter as much as on a nearly frictionless table (coefficient 0.02; without any friction
  nothing would hold the block sideways and the static problem would be singular).
* ``sags_by_its_weight``: the top face comes down by about the uniaxial estimate
  ``rho g H^2 / (2 E)`` of a column under its own weight (between 0.5 and 1.5 times it: the
  friction at the bottom and the edges stiffen the block).

Outputs in ``--out DIR`` (default ``results/block_on_table``): ``result.vtu`` (with
``contact_force``), ``shape.png`` and ``summary.json``.

Run::

    python examples/11_block_on_table.py --out results/block_on_table
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

SIZE = 0.1  # m
CELLS = 8
LIFT = 1e-4  # m: the block starts this far above the table
YOUNGS_MODULUS = 66e3  # Pa
DENSITY = 1080.0  # kg/m^3
GRAVITY = np.array([0.0, 0.0, -9.81])  # m/s^2
FRICTION = 0.8
SLIPPERY = 0.02  # the nearly frictionless table the spreading is compared with
FORMULATIONS = {"standard": 0.45, "mixed": 0.49}  # formulation: Poisson's ratio
TOLERANCE = 1e-10

BALANCE_TOLERANCE = 1e-6
STICK_FRACTION = 0.25


def build(formulation: str, cells: int = CELLS, friction: float = FRICTION) -> sf.Body:
    mesh = sf.Mesh.box(size=(SIZE, SIZE, SIZE), cells=(cells, cells, cells), origin=(0.0, 0.0, LIFT))
    material = sf.NeoHookean(youngs_modulus=YOUNGS_MODULUS, poisson_ratio=FORMULATIONS[formulation], density=DENSITY)
    body = sf.Body(mesh, material, formulation=formulation)
    body.add_obstacle(sf.Plane(point=(0.0, 0.0, 0.0), normal=(0.0, 0.0, 1.0)), friction=friction)
    return body


def lateral_spread(result: sf.StaticResult, z: float) -> float:
    """Largest outward displacement (m) of the nodes of the face at height ``z`` (rest)."""
    points = result.mesh.points
    face = np.abs(points[:, 2] - z) < 1e-9
    centre = np.array([SIZE / 2, SIZE / 2])
    outward = points[face, :2] - centre
    outward /= np.maximum(np.linalg.norm(outward, axis=1, keepdims=True), 1e-12)
    return float(np.max(np.sum(result.displacement[face, :2] * outward, axis=1)))


def run(out_dir: str | Path = "results/block_on_table", quick: bool = False) -> dict[str, Any]:
    """Solve, write the outputs to ``out_dir`` and return the summary (``checks`` inside)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    weight = DENSITY * SIZE**3 * abs(GRAVITY[2])
    cases = {}
    results = {}
    for formulation in FORMULATIONS:
        body = build(formulation, CELLS // 2 if quick else CELLS)
        result = sf.solve_static(body, gravity=GRAVITY, tolerance=TOLERANCE)
        contact = result.contact
        assert contact is not None
        total = result.obstacle_forces[0]
        lowest = float(result.positions[:, 2].min())
        results[formulation] = result
        cases[formulation] = {
            "poisson_ratio": FORMULATIONS[formulation],
            "iterations": result.report.iterations,
            "table_force": total.tolist(),
            "weight": weight,
            "min_distance": result.min_distance,
            "dhat": contact.dhat,
            "active_contacts": result.active_contacts,
            "min_iterate_distance": float(contact.iterate_min_distances.min(initial=np.inf)),
            "lowest_node": lowest,
            "top_sag": float(-result.displacement[np.abs(result.mesh.points[:, 2] - SIZE - LIFT) < 1e-9, 2].mean()),
            "bottom_spread": lateral_spread(result, LIFT),
            "top_spread": lateral_spread(result, SIZE + LIFT),
        }
    slippery = sf.solve_static(build("standard", CELLS // 2 if quick else CELLS, SLIPPERY), gravity=GRAVITY,
                               tolerance=TOLERANCE)
    slippery_spread = lateral_spread(slippery, LIFT)
    uniaxial = DENSITY * abs(GRAVITY[2]) * SIZE**2 / (2 * YOUNGS_MODULUS)
    checks = {
        "weight_carried": {
            "passed": all(abs(c["table_force"][2] - weight) < BALANCE_TOLERANCE * weight for c in cases.values()),
            "value": {f: abs(c["table_force"][2] - weight) / weight for f, c in cases.items()},
            "limit": f"|F_z - rho V g| / (rho V g) < {BALANCE_TOLERANCE:g}",
        },
        "no_tangential_force": {
            "passed": all(np.hypot(*c["table_force"][:2]) < BALANCE_TOLERANCE * weight for c in cases.values()),
            "value": {f: float(np.hypot(*c["table_force"][:2])) / weight for f, c in cases.items()},
            "limit": f"|(F_x, F_y)| / (rho V g) < {BALANCE_TOLERANCE:g}",
        },
        "no_penetration": {
            "passed": all(c["lowest_node"] > 0 and 0 < c["min_distance"] < c["dhat"] and c["min_iterate_distance"] > 0
                          for c in cases.values()),
            "value": {f: {"min_distance": c["min_distance"], "dhat": c["dhat"],
                          "min_iterate_distance": c["min_iterate_distance"]} for f, c in cases.items()},
            "limit": "0 < gap < dhat at the solution and gap > 0 at every accepted iterate",
        },
        "friction_holds_the_bottom": {
            "passed": cases["standard"]["bottom_spread"] < STICK_FRACTION * slippery_spread,
            "value": {"friction": cases["standard"]["bottom_spread"], "slippery": slippery_spread},
            "limit": f"bottom spread with mu = {FRICTION} < {STICK_FRACTION} x with mu = {SLIPPERY}",
        },
        "sags_by_its_weight": {
            "passed": all(0.5 * uniaxial < c["top_sag"] < 1.5 * uniaxial for c in cases.values()),
            "value": {f: c["top_sag"] / uniaxial for f, c in cases.items()},
            "limit": f"top sag within 0.5..1.5 x rho g H^2 / (2 E) = {uniaxial:.3e} m",
        },
    }
    final = results["mixed"]
    sf.io.write_result(out / "result.vtu", final)
    sf.plot.plot_rest_and_deformed(final, out / "shape.png",
                                   title=f"block resting on a table: F_z = {final.obstacle_forces[0, 2]:.4f} N")
    summary = {
        "example": "11_block_on_table",
        "n_nodes": final.mesh.n_nodes,
        "n_tets": final.mesh.n_tets,
        "cases": cases,
        "checks": checks,
        "passed": all(c["passed"] for c in checks.values()),
        "files": ["result.vtu", "shape.png", "summary.json"],
        "timings": {"total": time.perf_counter() - t0},
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    return summary


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("results/block_on_table"), metavar="DIR")
    parser.add_argument("--quick", action="store_true", help="a coarser mesh (what the tests run)")
    args = parser.parse_args(argv)
    try:
        summary = run(args.out, quick=args.quick)
    except sf.ConvergenceError as exc:
        print(f"error: the solver did not converge: {exc}", file=sys.stderr)
        return 3
    for formulation, case in summary["cases"].items():
        print(f"{formulation}: table force {np.round(case['table_force'], 6).tolist()} N (weight {case['weight']:.6f} N), "
              f"gap {case['min_distance']:.3e} m (dhat {case['dhat']:.3e} m), {case['iterations']} Newton iterations")
    for name, check in summary["checks"].items():
        print(f"[{'ok' if check['passed'] else 'FAILED'}] {name}: {check['limit']}")
    print(f"{'all checks passed' if summary['passed'] else 'SOME CHECKS FAILED'}; wrote {', '.join(summary['files'])} "
          f"to {args.out} in {summary['timings']['total']:.1f} s")
    return 0 if summary["passed"] else 1


if __name__ == "__main__":
    sys.exit(main())
