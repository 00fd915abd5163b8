"""A silicone cantilever bent by an internal cable pulled to half its length, with physics checks.

The 0.4 x 0.1 x 0.1 m beam of example 01 (16 x 4 x 4 hexahedral cells, 6 tets each; E = 66 kPa,
nu = 0.45, rho = 1080 kg/m^3, clamped at x = 0, gravity (0, 0, -9.81) m/s^2) with one cable along
its lower edge on the y = 0 side: 1 cm inside both the bottom face and the side face, from x = 0
to x = 0.4 m, 10 segments of stiffness 1e5 N/m (SolidFEM's ``cantilever_cable.xml`` uses the same
stiffness and division). The motor sits in the clamp: the first point is a world anchor
(``anchor_first=True``) on the clamped face, so its pull reaches the world through the anchor
rather than through the clamped nodes (the same equilibrium as a cable bonded there). The cable is pulled from alpha = 1 (rest) to alpha = 0.5 (half its rest
length) by continuation: ten solves with alpha decreasing by 0.05, each warm-started from the
previous equilibrium (``sf.actuate``). Gravity alone bends the beam in the x-z plane only; the
cable, off-centre in y, curls it towards the y = 0 side.

The cable points are bonded to the material (they do not slide), so the tension may differ from
segment to segment; in a beam bent uniformly it is uniform away from the two ends.

The script exits with status 1 unless every check passes:

* ``continuation_converged``: every continuation step converged, to alpha = 0.5.
* ``bends_towards_cable``: the tip moves towards the cable side (u_y < -0.1 L) while the
  gravity-only tip stays in the x-z plane (|u_y| < 1e-3 L); the cable's chord shortens to
  < 0.8 of its rest length.
* ``force_balance`` / ``moment_balance``: the support reactions, the weight and the anchor's
  pull on the cable (``-T_0`` along the first segment, ``result.anchor_reactions``) balance,
  force and moment, to 1e-6 of the weight. Every other segment pulls its two ends together, so
  this ties the force the cable exerts on the body to the tension the solver reports.
* ``tensions_positive``: every segment is taut.
* ``virtual_work``: the derivative of the total potential energy at equilibrium with respect to
  alpha (by central differences, two more solves at alpha +- 1e-4) equals ``-sum_s T_s l_s``, the
  work of the reported tensions on the rest lengths (envelope theorem), to 1e-6: every
  segment's tension against the energy the body actually minimises.
* ``interior_tension_uniform``: the tensions of the eight interior segments lie within 20 % of
  their mean (the end segments feel the clamp and the free end).

Outputs in ``--out DIR`` (default ``results/cable_cantilever``): ``result.vtu``, ``cable.vtu``
(the cable as line cells with tension), ``shape.png`` (rest and deformed, cable in red),
``tension.png`` (tension per segment) and ``summary.json``.

Run::

    python examples/03_cable_cantilever.py --out results/cable_cantilever
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

YOUNGS_MODULUS = 66e3  # Pa
POISSON_RATIO = 0.45
DENSITY = 1080.0  # kg/m^3
GRAVITY = np.array([0.0, 0.0, -9.81])  # m/s^2
SIZE = (0.4, 0.1, 0.1)  # m
CELLS = (16, 4, 4)
CABLE_START = (0.0, 0.01, 0.01)  # m: 1 cm inside the bottom (z = 0) and side (y = 0) faces
CABLE_DIVISIONS = 10
CABLE_STIFFNESS = 1e5  # N/m per segment
TARGET_ALPHA = 0.5
ALPHA_STEP = 0.05
TOLERANCE = 1e-8
VIRTUAL_WORK_STEP = 1e-4  # alpha
VIRTUAL_WORK_TOLERANCE = 1e-6

BALANCE_TOLERANCE = 1e-6
UNIFORMITY = 0.2


def build() -> tuple[sf.Body, sf.Cable]:
    mesh = sf.Mesh.box(size=SIZE, cells=CELLS)
    material = sf.NeoHookean(youngs_modulus=YOUNGS_MODULUS, poisson_ratio=POISSON_RATIO, density=DENSITY)
    body = sf.Body(mesh, material)
    body.fix(mesh.nodes_on_plane((0.0, 0.0, 0.0), (1.0, 0.0, 0.0)))
    cable = sf.Cable.line(CABLE_START, (1.0, 0.0, 0.0), SIZE[0], CABLE_DIVISIONS, stiffness=CABLE_STIFFNESS,
                          anchor_first=True)
    body.add_cable(cable)
    return body, cable


def virtual_work_error(body: sf.Body, cable: sf.Cable, result: sf.StaticResult) -> float:
    """``|dPi/dalpha + sum_s T_s l_s| / sum_s T_s l_s`` at ``result`` (alpha = its actuation),
    ``dPi/dalpha`` by central differences of the equilibrium energy; leaves the body at alpha."""
    alpha = result.actuations[0]
    energies = []
    for a in (alpha + VIRTUAL_WORK_STEP, alpha - VIRTUAL_WORK_STEP):
        body.set_actuation(cable, a)
        moved = sf.solve_static(body, gravity=GRAVITY, tolerance=1e-10, initial=result)
        energies.append(moved.report.energy_history[-1])
    body.set_actuation(cable, alpha)
    derivative = (energies[0] - energies[1]) / (2 * VIRTUAL_WORK_STEP)
    work = float(result.cable_tensions[0] @ cable.rest_lengths)
    return abs(derivative + work) / work


def lumped_weight(mesh: sf.Mesh) -> np.ndarray:
    """``rho V g / 4`` per tet and node, ``(n_nodes, 3)``, N."""
    forces = np.zeros((mesh.n_nodes, 3))
    for a in range(4):
        np.add.at(forces, mesh.tets[:, a], (DENSITY * mesh.volumes / 4.0)[:, None] * GRAVITY[None, :])
    return forces


def plot_tensions(tensions: list[np.ndarray], alphas: list[float], path: Path) -> None:
    from matplotlib.figure import Figure  # no pyplot: no window, no global state

    fig = Figure(figsize=(6.0, 4.0), dpi=120)
    ax = fig.add_subplot()
    for t, alpha in zip(tensions, alphas):
        ax.plot(np.arange(1, t.size + 1), t, "o-", markersize=3, label=f"alpha = {alpha:.2f}")
    ax.set_xlabel("segment (from the clamp)")
    ax.set_ylabel("tension [N]")
    ax.set_title("cable tension along the cable")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(path)


def run(out_dir: str | Path = "results/cable_cantilever") -> dict[str, Any]:
    """Simulate, write the outputs to ``out_dir`` and return the summary (``checks`` inside)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    body, cable = build()
    mesh = body.mesh
    gravity_only = sf.solve_static(body, gravity=GRAVITY, tolerance=TOLERANCE)
    t1 = time.perf_counter()
    path = sf.actuate(body, cable, TARGET_ALPHA, gravity=GRAVITY, max_step=ALPHA_STEP, tolerance=TOLERANCE,
                      initial=gravity_only)
    t2 = time.perf_counter()
    final = path[-1]

    tip = mesh.nodes_on_plane((SIZE[0], 0.0, 0.0), (1.0, 0.0, 0.0))
    u_tip = final.displacement[tip].mean(axis=0)
    u_tip_gravity = gravity_only.displacement[tip].mean(axis=0)
    points = final.cable_points[0]
    tensions = final.cable_tensions[0]
    chord = float(np.linalg.norm(points[-1] - points[0]))

    f_grav = lumped_weight(mesh)
    weight = f_grav.sum(axis=0)
    w_norm = float(np.linalg.norm(weight))
    fixed = body.fixed_nodes
    anchor = final.anchor_reactions[0]
    force_error = float(np.linalg.norm(final.reactions.sum(axis=0) + weight + anchor)) / w_norm
    moment = (np.cross(final.positions[fixed], final.reactions).sum(axis=0)
              + np.cross(final.positions, f_grav).sum(axis=0) + np.cross(points[0], anchor))
    moment_error = float(np.linalg.norm(moment)) / (w_norm * SIZE[0])
    work_error = virtual_work_error(body, cable, final)
    interior = tensions[1:-1]
    spread = float(np.abs(interior / interior.mean() - 1).max())

    length = SIZE[0]
    checks = {
        "continuation_converged": {
            "passed": all(r.report.converged for r in path) and final.actuations[0] == TARGET_ALPHA,
            "value": {"steps": len(path), "iterations": [r.report.iterations for r in path]},
            "limit": f"every step converged, final alpha = {TARGET_ALPHA}",
        },
        "bends_towards_cable": {
            "passed": bool(u_tip[1] < -0.1 * length and abs(u_tip_gravity[1]) < 1e-3 * length
                           and chord < 0.8 * cable.length),
            "value": {"tip_uy": float(u_tip[1]), "gravity_only_tip_uy": float(u_tip_gravity[1]),
                      "chord_over_rest_length": chord / cable.length},
            "limit": "u_y(tip) < -0.1 L, |u_y(tip, gravity only)| < 1e-3 L, chord < 0.8 rest length",
        },
        "force_balance": {
            "passed": force_error < BALANCE_TOLERANCE,
            "value": {"error": force_error, "anchor_pull": float(np.linalg.norm(anchor)), "weight": w_norm},
            "limit": f"|sum R + W + A| / |W| < {BALANCE_TOLERANCE:g}",
        },
        "moment_balance": {
            "passed": moment_error < BALANCE_TOLERANCE,
            "value": moment_error,
            "limit": f"|sum x x (R + f_g) + y_0 x A| / (|W| L) < {BALANCE_TOLERANCE:g}",
        },
        "tensions_positive": {
            "passed": bool(np.all(tensions > 0)),
            "value": float(tensions.min()),
            "limit": "min tension > 0 N",
        },
        "virtual_work": {
            "passed": work_error < VIRTUAL_WORK_TOLERANCE,
            "value": work_error,
            "limit": f"|dPi/dalpha + sum T l| / sum T l < {VIRTUAL_WORK_TOLERANCE:g}",
        },
        "interior_tension_uniform": {
            "passed": spread < UNIFORMITY,
            "value": spread,
            "limit": f"interior segments within {UNIFORMITY:.0%} of their mean",
        },
    }

    sf.io.write_result(out / "result.vtu", final)
    sf.cables.write_cables(out / "cable.vtu", final)
    sf.plot.plot_rest_and_deformed(
        final, out / "shape.png",
        title=f"cable pulled to alpha = {TARGET_ALPHA}: tip u = ({u_tip[0]:.3f}, {u_tip[1]:.3f}, {u_tip[2]:.3f}) m",
    )
    plot_tensions([r.cable_tensions[0] for r in path[1::3]] + [tensions], [r.actuations[0] for r in path[1::3]]
                  + [TARGET_ALPHA], out / "tension.png")
    summary = {
        "example": "03_cable_cantilever",
        "n_nodes": mesh.n_nodes,
        "n_tets": mesh.n_tets,
        "cable": cable.to_dict(),
        "placements": [p.kind for p in body.cable_placements()[0]],
        "path": [
            {"alpha": r.actuations[0], "iterations": r.report.iterations,
             "max_tension": float(r.cable_tensions[0].max()),
             "tip_displacement": r.displacement[tip].mean(axis=0).tolist()}
            for r in path
        ],
        "gravity_only_tip_displacement": u_tip_gravity.tolist(),
        "tip_displacement": u_tip.tolist(),
        "tensions": tensions.tolist(),
        "min_J": float(final.J.min()),
        "checks": checks,
        "passed": all(c["passed"] for c in checks.values()),
        "files": ["result.vtu", "cable.vtu", "shape.png", "tension.png", "summary.json"],
        "timings": {"setup_and_gravity": t1 - t0, "continuation": t2 - t1, "total": time.perf_counter() - t0},
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    return summary


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("results/cable_cantilever"), metavar="DIR")
    args = parser.parse_args(argv)
    try:
        summary = run(args.out)
    except sf.ConvergenceError as exc:
        print(f"error: the solver did not converge: {exc}", file=sys.stderr)
        return 3
    for step in summary["path"]:
        print(f"alpha {step['alpha']:.2f}: {step['iterations']:2d} Newton iterations, max tension {step['max_tension']:.1f} N")
    print(f"tip displacement {np.round(summary['tip_displacement'], 4).tolist()} m "
          f"(gravity only {np.round(summary['gravity_only_tip_displacement'], 4).tolist()} m)")
    print(f"tensions {np.round(summary['tensions'], 1).tolist()} N")
    for name, check in summary["checks"].items():
        print(f"[{'ok' if check['passed'] else 'FAILED'}] {name}: {check['limit']}")
    print(f"{'all checks passed' if summary['passed'] else 'SOME CHECKS FAILED'}; wrote {', '.join(summary['files'])} "
          f"to {args.out} in {summary['timings']['total']:.1f} s")
    return 0 if summary["passed"] else 1


if __name__ == "__main__":
    sys.exit(main())
