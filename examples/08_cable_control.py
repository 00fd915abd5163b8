"""Cable control of the silicone cantilever: find the pull that puts the tip where we want it, with checks.

The cantilever and cable of example 03: 0.4 x 0.1 x 0.1 m, 16 x 4 x 4 cells (6 tets each),
E = 66 kPa, nu = 0.45, rho = 1080 kg/m^3, clamped at x = 0, gravity (0, 0, -9.81) m/s^2; one
cable 1 cm inside the bottom (z = 0) and side (y = 0) faces from x = 0 to 0.4 m, 10 segments of
stiffness 1e5 N/m. The controlled point is the centre of the tip face, (0.4, 0.05, 0.05) m at
rest, embedded barycentrically in the mesh (``sf.Target.points``).

1. **Recovery.** The cable is pulled to alpha = 0.5 (continuation, ``sf.actuate``) and the tip
   centre's equilibrium position becomes the goal. ``sf.control`` starts from alpha = 0.548
   (the middle of the bounds [0.3, 1] in log alpha) and minimises 1/2 |tip - goal|^2 with the
   adjoint gradient d/d alpha (L-BFGS-B); it must find alpha = 0.5 again.
2. **Moving the goal along +x.** The goal is shifted by 2, 5 and 10 cm along +x. One cable has
   one degree of freedom, so the tip moves on a curve and these goals are off it: ``control``
   reports them as not reachable and returns the closest reachable configuration.

The script exits with status 1 unless every check passes:

* ``recovers_actuation``: |alpha - 0.5| < 1e-6 and the tip within 1e-6 m of the goal
  (``reachable``).
* ``shifted_goals_unreachable``: every shifted goal is reported as not reachable (the distance
  exceeds the 1 mm tolerance) with a message saying so.
* ``closest_is_optimal``: for each shifted goal, no alpha of a scan over [0.3, 1] (step 0.05,
  continuation) brings the tip closer than the returned configuration (to 1e-9 m), and the
  adjoint derivative of the misfit vanishes there (``|dO/dalpha| * 0.05 < 1e-3 O``) unless
  alpha sits on a bound.
* ``closest_point_consistent``: the returned tip position lies on the scanned curve: within
  2 mm of the straight line between the two nearest scanned tip positions.

Outputs in ``--out DIR`` (default ``results/cable_control``): ``summary.json``, ``control.png``
(the tip curve over alpha in the x-z and x-y planes, goals and closest points) and
``result.vtu`` (the recovered pose).

Run::

    python examples/08_cable_control.py --out results/cable_control
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
GRAVITY = (0.0, 0.0, -9.81)  # m/s^2
SIZE = (0.4, 0.1, 0.1)  # m
CELLS = (16, 4, 4)
CABLE_START = (0.0, 0.01, 0.01)  # m
CABLE_DIVISIONS = 10
CABLE_STIFFNESS = 1e5  # N/m per segment
TRUE_ALPHA = 0.5
BOUNDS = (0.3, 1.0)
SHIFTS = (0.02, 0.05, 0.10)  # m along +x
TIP_CENTRE = np.array([[0.4, 0.05, 0.05]])  # m, rest
SCAN = np.round(np.arange(1.0, 0.3 - 1e-9, -0.05), 10)
TOLERANCE = 1e-10


def build() -> tuple[sf.Body, sf.Cable]:
    mesh = sf.Mesh.box(size=SIZE, cells=CELLS)
    material = sf.NeoHookean(youngs_modulus=YOUNGS_MODULUS, poisson_ratio=POISSON_RATIO, density=DENSITY)
    body = sf.Body(mesh, material)
    body.fix(mesh.nodes_on_plane((0.0, 0.0, 0.0), (1.0, 0.0, 0.0)))
    cable = sf.Cable.line(CABLE_START, (1.0, 0.0, 0.0), SIZE[0], CABLE_DIVISIONS, stiffness=CABLE_STIFFNESS)
    body.add_cable(cable)
    return body, cable


def run(out_dir: str | Path = "results/cable_control") -> dict[str, Any]:
    """Control, write the outputs to ``out_dir`` and return the summary (``checks`` inside)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    body, cable = build()
    tip = sf.Target.points(TIP_CENTRE, TIP_CENTRE).bind(body.mesh)

    # The scan doubles as the ground truth of the pose at alpha = 0.5 (continuation from rest).
    scan = sf.actuate(body, cable, list(SCAN), gravity=GRAVITY, tolerance=TOLERANCE)
    scan_alpha = np.array([r.actuations[0] for r in scan])
    scan_tip = np.array([tip.points(r.positions)[0] for r in scan])
    body.set_actuation(cable, 1.0)
    goal = scan_tip[np.flatnonzero(np.isclose(scan_alpha, TRUE_ALPHA))[0]][None, :]
    t1 = time.perf_counter()

    recovered = sf.control(body, sf.Target.points(TIP_CENTRE, goal), cables=[cable], bounds=[BOUNDS], gravity=GRAVITY)
    t2 = time.perf_counter()
    shifted = []
    previous = recovered.result
    for dx in SHIFTS:
        shifted_goal = goal + [dx, 0.0, 0.0]
        target = sf.Target.points(TIP_CENTRE, shifted_goal)
        ctl = sf.control(body, target, cables=[cable], bounds=[BOUNDS], gravity=GRAVITY, initial=previous)
        previous = ctl.result
        scan_distance = np.linalg.norm(scan_tip - shifted_goal, axis=1)
        on_bound = bool(ctl.active_bounds)
        body.set_actuation(cable, float(ctl.actuation[0]))
        grad = sf.gradient(body, target, ["cable_actuation"], gravity=GRAVITY, initial=ctl.result)
        body.set_actuation(cable, 1.0)
        d_alpha = float(grad.gradient["cable_actuation"][0])
        # Nearest two scanned tip positions: the returned tip must lie near the segment between them.
        i, j = np.argsort(np.abs(scan_alpha - ctl.actuation[0]))[:2]
        a, b = scan_tip[i], scan_tip[j]
        u = np.clip(np.dot(ctl.points[0] - a, b - a) / np.dot(b - a, b - a), 0.0, 1.0)
        off_curve = float(np.linalg.norm(ctl.points[0] - (a + u * (b - a))))
        shifted.append({
            "shift": dx,
            "goal": shifted_goal[0].tolist(),
            **ctl.to_dict(),
            "best_scanned_distance": float(scan_distance.min()),
            "best_scanned_alpha": float(scan_alpha[np.argmin(scan_distance)]),
            "misfit": grad.value,
            "d_misfit_d_alpha": d_alpha,
            "on_bound": on_bound,
            "off_scanned_curve": off_curve,
        })
    t3 = time.perf_counter()

    checks = {
        "recovers_actuation": {
            "passed": bool(abs(recovered.actuation[0] - TRUE_ALPHA) < 1e-6 and recovered.reachable
                           and recovered.distance < 1e-6),
            "value": {"alpha": float(recovered.actuation[0]), "distance": recovered.distance,
                      "forward_solves": recovered.forward_solves},
            "limit": f"|alpha - {TRUE_ALPHA}| < 1e-6, distance < 1e-6 m, reachable",
        },
        "shifted_goals_unreachable": {
            "passed": all(not s["reachable"] and "not reachable" in s["message"] for s in shifted),
            "value": {f"{s['shift']:g} m": s["distance"] for s in shifted},
            "limit": "distance > 1 mm tolerance, reported as not reachable",
        },
        "closest_is_optimal": {
            "passed": all(
                s["distance"] <= s["best_scanned_distance"] + 1e-9
                and (s["on_bound"] or abs(s["d_misfit_d_alpha"]) * 0.05 < 1e-3 * s["misfit"])
                for s in shifted
            ),
            "value": [{"distance": s["distance"], "best_scanned": s["best_scanned_distance"],
                       "dO_dalpha_x_0.05_over_O": abs(s["d_misfit_d_alpha"]) * 0.05 / s["misfit"]} for s in shifted],
            "limit": "distance <= best scanned distance + 1e-9 m; |dO/dalpha| 0.05 < 1e-3 O (interior)",
        },
        "closest_point_consistent": {
            "passed": all(s["off_scanned_curve"] < 2e-3 for s in shifted),
            "value": [s["off_scanned_curve"] for s in shifted],
            "limit": "< 2 mm from the chord of the scanned tip curve",
        },
    }
    sf.io.write_result(out / "result.vtu", recovered.result)
    _plot(scan_alpha, scan_tip, goal[0], shifted, out / "control.png")
    summary = {
        "true_alpha": TRUE_ALPHA,
        "goal": goal[0].tolist(),
        "recovered": recovered.to_dict(),
        "shifted": shifted,
        "scan": {"alpha": scan_alpha.tolist(), "tip": scan_tip.tolist()},
        "checks": checks,
        "passed": all(c["passed"] for c in checks.values()),
        "files": ["summary.json", "control.png", "result.vtu"],
        "timings": {"scan": t1 - t0, "recovery": t2 - t1, "shifted": t3 - t2, "total": time.perf_counter() - t0},
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    return summary


def _plot(alpha: np.ndarray, tip: np.ndarray, goal: np.ndarray, shifted: list[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4.2))
    for ax, (k, label) in zip(axes, ((2, "z"), (1, "y"))):
        ax.plot(tip[:, 0], tip[:, k], "-o", ms=3, color="0.5", label="tip over alpha in [0.3, 1]")
        ax.plot(goal[0], goal[k], "k*", ms=12, label="goal (alpha = 0.5)")
        for s in shifted:
            g, p = np.array(s["goal"]), np.array(s["points"][0])
            ax.plot(g[0], g[k], "rx")
            ax.plot(p[0], p[k], "bo", mfc="none")
            ax.plot([g[0], p[0]], [g[k], p[k]], "r:", lw=1)
        ax.set_xlabel("x [m]")
        ax.set_ylabel(f"{label} [m]")
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(alpha=0.3)
    axes[0].plot([], [], "rx", label="shifted goals")
    axes[0].plot([], [], "bo", mfc="none", label="closest reachable")
    axes[0].legend(fontsize=8)
    fig.subplots_adjust(left=0.09, right=0.98, bottom=0.12, top=0.95, wspace=0.3)
    fig.savefig(path)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("results/cable_control"), metavar="DIR")
    args = parser.parse_args(argv)
    try:
        summary = run(args.out)
    except sf.ConvergenceError as exc:
        print(f"error: the solver did not converge: {exc}", file=sys.stderr)
        return 3
    r = summary["recovered"]
    print(f"recovered alpha {r['actuation'][0]:.8f} (true {TRUE_ALPHA}), distance {r['distance']:.2e} m, "
          f"{r['forward_solves']} forward solves, {r['time']:.2f} s")
    for s in summary["shifted"]:
        print(f"goal +{s['shift'] * 100:.0f} cm in x: closest alpha {s['actuation'][0]:.4f}, tip "
              f"{np.round(s['points'][0], 4).tolist()} m, {s['distance'] * 1000:.1f} mm away "
              f"(best scanned {s['best_scanned_distance'] * 1000:.1f} mm); {s['forward_solves']} solves")
    for name, check in summary["checks"].items():
        print(f"[{'ok' if check['passed'] else 'FAILED'}] {name}: {check['limit']}")
    print(f"{'all checks passed' if summary['passed'] else 'SOME CHECKS FAILED'} in {summary['timings']['total']:.1f} s; "
          f"wrote {', '.join(summary['files'])} to {args.out}")
    return 0 if summary["passed"] else 1


if __name__ == "__main__":
    sys.exit(main())
