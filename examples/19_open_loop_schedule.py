"""Open-loop schedule: lift the cantilever's tip to a target height at T = 0.5 s and hold it, with checks.

The cable cantilever on the coarse 8 x 2 x 2 mesh (0.4 x 0.1 x 0.1 m, E = 66 kPa, nu = 0.45,
rho = 1080 kg/m^3, clamped at x = 0, gravity (0, 0, -9.81) m/s^2), with its cable 1 cm under the
top face (y = 5 cm, z = 9 cm) from x = 0 to 0.4 m, 10 segments of 1e5 N/m: pulling it (alpha < 1)
lifts the sagging tip. The run starts at rest in the static equilibrium at alpha = 1 (tip centre
14 cm below its rest height) and lasts 1.5 s (implicit Euler, dt = 10 ms, Rayleigh damping
alpha_M = 1 1/s, beta_K = 2 ms: about two and a half periods of the pulled beam's first mode,
0.57 s, lightly damped).

The goal is the tip centre where the static equilibrium at alpha = 0.85 puts it, 13 cm higher.

1. **Static control.** ``sf.control`` finds the command that holds the tip at the goal.
2. **Naive step.** That command applied at once (from the first step): the tip overshoots and
   swings about the goal.
3. **Schedule.** ``sf.control(..., dynamics=...)`` optimises alpha at the keyframes t = 0.1,
   0.2, 0.3, 0.4 and 0.5 s (from alpha = 1 at t = 0, piecewise linear, held after 0.5 s) so that
   the tip reaches the goal at T = 0.5 s and stays there to 1.5 s: it minimises the mean over
   the frames from T to the end of 1/2 |tip - goal|^2, from the static command at every keyframe,
   with the adjoint gradient through the time steps (L-BFGS-B).

The script exits with status 1 unless every check passes:

* ``static_control``: the static control finds alpha = 0.85 to 1e-6, the goal reachable.
* ``reaches_target``: the schedule's tip is within 1 mm (RMS) of the goal at T.
* ``holds_target``: after T it strays at most 1 mm from the goal, and at most 1/20 of the naive
  step's largest distance after T.
* ``holds_still``: the kinetic energy after T stays below 1e-2 of the naive step's largest one
  after T (the beam is held, not swinging through the goal).
* ``settles_to_static``: the final state is the static equilibrium of the final command
  (solved directly) to 1e-3 of its largest displacement from the start, and that command is the
  static control's to 1e-3.
* ``schedule_replays``: the schedule fed to ``sf.simulate`` (its default modified Newton, a
  different Newton iteration) gives the same distance at T and swing to 1e-5 m.

Outputs in ``--out DIR`` (default ``results/open_loop_schedule``): ``summary.json``,
``schedule.png`` (alpha and the tip's height over time, naive and scheduled) and
``trajectory.pvd`` with ``trajectory/frame_NNNNN.vtu`` (the scheduled motion).

Run::

    python examples/19_open_loop_schedule.py --out results/open_loop_schedule
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
CELLS = (8, 2, 2)
CABLE_START = (0.0, 0.05, 0.09)  # m
CABLE_DIVISIONS = 10
CABLE_STIFFNESS = 1e5  # N/m per segment
GOAL_ALPHA = 0.85
BOUNDS = (0.5, 1.0)
TIP_CENTRE = np.array([[0.4, 0.05, 0.05]])  # m, rest
DT = 0.01  # s
STEPS = 150
DAMPING = (1.0, 0.002)  # Rayleigh alpha_M (1/s), beta_K (s)
KEYFRAME_TIMES = [0.1, 0.2, 0.3, 0.4, 0.5]  # s
REACH_TIME = 0.5  # s
TOLERANCE = 1e-3  # m
SOLVE_TOLERANCE = 1e-10

SWING_RATIO = 1 / 20
ENERGY_RATIO = 1e-2
SETTLE_TOLERANCE = 1e-3
REPLAY_TOLERANCE = 1e-5  # m


def build() -> tuple[sf.Body, sf.Cable]:
    mesh = sf.Mesh.box(size=SIZE, cells=CELLS)
    material = sf.NeoHookean(youngs_modulus=YOUNGS_MODULUS, poisson_ratio=POISSON_RATIO, density=DENSITY)
    body = sf.Body(mesh, material)
    body.fix(mesh.nodes_on_plane((0.0, 0.0, 0.0), (1.0, 0.0, 0.0)))
    cable = sf.Cable.line(CABLE_START, (1.0, 0.0, 0.0), SIZE[0], CABLE_DIVISIONS, stiffness=CABLE_STIFFNESS)
    body.add_cable(cable)
    return body, cable


def equilibrium(body: sf.Body, cable: sf.Cable, alpha: float, initial: Any = None) -> sf.StaticResult:
    """The static equilibrium at ``alpha``; the body's own command stays alpha = 1."""
    body.set_actuation(cable, alpha)
    try:
        return sf.solve_static(body, gravity=GRAVITY, tolerance=SOLVE_TOLERANCE, initial=initial)
    finally:
        body.set_actuation(cable, 1.0)


def run(out_dir: str | Path = "results/open_loop_schedule") -> dict[str, Any]:
    """Plan, write the outputs to ``out_dir`` and return the summary (``checks`` inside)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    body, cable = build()
    start = equilibrium(body, cable, 1.0)
    tip = sf.Target.points(TIP_CENTRE, TIP_CENTRE).bind(body.mesh)
    goal = tip.points(equilibrium(body, cable, GOAL_ALPHA, start).positions)
    target = sf.Target.points(TIP_CENTRE, goal)
    static = sf.control(body, target, cables=[cable], bounds=[BOUNDS], gravity=GRAVITY, initial=start)
    t1 = time.perf_counter()

    reach = round(REACH_TIME / DT)
    naive = sf.simulate(body, DT, STEPS, actuation={cable: float(static.actuation[0])}, gravity=GRAVITY,
                        damping=DAMPING, initial=start, tolerance=SOLVE_TOLERANCE)
    bound = target.bind(body.mesh)
    naive_distance = np.array([bound.rms(x) for x in naive.positions])
    t2 = time.perf_counter()

    dynamics = dict(dt=DT, steps=STEPS, keyframe_times=KEYFRAME_TIMES, reach_time=REACH_TIME, damping=DAMPING,
                    initial=start)
    # ftol: the search stops once an iteration lowers J by less than 1e-9 of its start value.
    plan = sf.control(body, target, cables=[cable], bounds=[BOUNDS], x0=static.actuation, gravity=GRAVITY,
                      solve_tolerance=SOLVE_TOLERANCE, tolerance=TOLERANCE, ftol=1e-9, dynamics=dynamics)
    t3 = time.perf_counter()
    traj = plan.trajectory
    distance = np.array([bound.rms(x) for x in traj.positions])
    final_alpha = float(plan.actuation[-1, 0])
    settled = equilibrium(body, cable, final_alpha, start)
    settle_error = float(np.abs(traj.final_positions - settled.positions).max()
                         / np.abs(settled.positions - start.positions).max())
    replay = sf.simulate(body, DT, STEPS, actuation=plan.schedule, gravity=GRAVITY, damping=DAMPING, initial=start)
    replay_distance = np.array([bound.rms(x) for x in replay.positions])
    naive_swing = float(naive_distance[reach + 1:].max())
    naive_energy = float(naive.kinetic_energy[reach + 1:].max())
    plan_energy = float(traj.kinetic_energy[reach + 1:].max())

    checks = {
        "static_control": {
            "passed": bool(static.reachable and abs(static.actuation[0] - GOAL_ALPHA) < 1e-6),
            "value": {"alpha": float(static.actuation[0]), "distance": static.distance},
            "limit": f"|alpha - {GOAL_ALPHA}| < 1e-6, reachable",
        },
        "reaches_target": {
            "passed": plan.distance <= TOLERANCE,
            "value": {"distance_at_T": plan.distance, "naive_distance_at_T": float(naive_distance[reach])},
            "limit": f"RMS distance at T = {REACH_TIME} s <= {TOLERANCE:g} m",
        },
        "holds_target": {
            "passed": bool(plan.reachable and plan.swing <= SWING_RATIO * naive_swing),
            "value": {"swing": plan.swing, "naive_swing": naive_swing},
            "limit": f"largest RMS distance after T <= {TOLERANCE:g} m and <= {SWING_RATIO:g} of the naive step's",
        },
        "holds_still": {
            "passed": plan_energy < ENERGY_RATIO * naive_energy,
            "value": {"max_kinetic_energy_after_T": plan_energy, "naive": naive_energy},
            "limit": f"max KE after T < {ENERGY_RATIO:g} of the naive step's",
        },
        "settles_to_static": {
            "passed": bool(settle_error < SETTLE_TOLERANCE
                           and abs(final_alpha - static.actuation[0]) < SETTLE_TOLERANCE * static.actuation[0]),
            "value": {"state_error": settle_error, "final_alpha": final_alpha, "static_alpha": float(static.actuation[0])},
            "limit": f"max |x(end) - x_static(final alpha)| / max |x_static - x(0)| < {SETTLE_TOLERANCE:g}, final alpha "
                     f"= static alpha to {SETTLE_TOLERANCE:g}",
        },
        "schedule_replays": {
            "passed": bool(abs(replay_distance[reach] - plan.distance) < REPLAY_TOLERANCE
                           and abs(replay_distance[reach + 1:].max() - plan.swing) < REPLAY_TOLERANCE),
            "value": {"distance_at_T": float(replay_distance[reach]), "swing": float(replay_distance[reach + 1:].max())},
            "limit": f"sf.simulate(actuation=schedule) agrees to {REPLAY_TOLERANCE:g} m",
        },
    }
    pvd = traj.write_pvd(out)
    alphas = np.r_[1.0, traj.actuation[:, 0]]
    naive_alphas = np.r_[1.0, naive.actuation[:, 0]]
    plot(traj.times, alphas, naive_alphas, tip.points, traj, naive, goal[0], out / "schedule.png")
    naive_objective = float(np.mean(0.5 * naive_distance[reach:] ** 2))  # one point: |r| is its RMS distance
    summary = {
        "example": "19_open_loop_schedule",
        "n_nodes": body.mesh.n_nodes,
        "n_tets": body.mesh.n_tets,
        "goal": goal[0].tolist(),
        "start_tip": tip.points(start.positions)[0].tolist(),
        "static": static.to_dict(),
        "plan": plan.to_dict(),
        "naive": {"alpha": float(static.actuation[0]), "distance_at_T": float(naive_distance[reach]),
                  "swing": naive_swing, "objective": naive_objective},
        "checks": checks,
        "passed": all(c["passed"] for c in checks.values()),
        "files": ["summary.json", "schedule.png", pvd.name, "trajectory/"],
        "timings": {"static": t1 - t0, "naive": t2 - t1, "schedule": t3 - t2, "total": time.perf_counter() - t0},
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    return summary


def plot(times: np.ndarray, alphas: np.ndarray, naive_alphas: np.ndarray, points: Any, traj: sf.Trajectory,
         naive: sf.Trajectory, goal: np.ndarray, path: Path) -> None:
    from matplotlib.figure import Figure  # no pyplot: no window, no global state

    fig = Figure(figsize=(7.0, 5.5), dpi=120)
    ax_a, ax_z = fig.add_subplot(2, 1, 1), fig.add_subplot(2, 1, 2)
    ax_a.plot(times, naive_alphas, color="0.5", label="naive step")
    ax_a.plot(times, alphas, color="C0", label="schedule")
    ax_a.plot(KEYFRAME_TIMES, np.interp(KEYFRAME_TIMES, times, alphas), "o", color="C0", ms=4)
    ax_a.set_ylabel("cable alpha")
    ax_a.legend()
    ax_a.grid(True, alpha=0.3)
    for label, run, colour in (("naive step", naive, "0.5"), ("schedule", traj, "C0")):
        ax_z.plot(run.times, [points(x)[0, 2] for x in run.positions], color=colour, label=label)
    ax_z.axhline(goal[2], color="k", linestyle="--", linewidth=0.8, label="goal height")
    ax_z.axvline(REACH_TIME, color="r", linestyle=":", linewidth=0.8, label="T")
    ax_z.set_xlabel("time [s]")
    ax_z.set_ylabel("tip centre z [m]")
    ax_z.legend()
    ax_z.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("results/open_loop_schedule"), metavar="DIR")
    args = parser.parse_args(argv)
    try:
        summary = run(args.out)
    except sf.ConvergenceError as exc:
        print(f"error: the solver did not converge: {exc}", file=sys.stderr)
        return 3
    plan, naive = summary["plan"], summary["naive"]
    print(f"static control: alpha {summary['static']['actuation'][0]:.6f}; naive step: {naive['distance_at_T'] * 1e3:.1f} mm "
          f"at T, swing {naive['swing'] * 1e3:.1f} mm")
    print(f"schedule {np.round(np.ravel(plan['actuation']), 4).tolist()} at {plan['keyframe_times']} s: "
          f"{plan['distance'] * 1e3:.3f} mm at T, swing {plan['swing'] * 1e3:.3f} mm, {plan['simulations']} simulations, "
          f"{plan['time']:.1f} s")
    for name, check in summary["checks"].items():
        print(f"[{'ok' if check['passed'] else 'FAILED'}] {name}: {check['limit']}")
    print(f"{'all checks passed' if summary['passed'] else 'SOME CHECKS FAILED'} in {summary['timings']['total']:.1f} s; "
          f"wrote {', '.join(summary['files'])} to {args.out}")
    return 0 if summary["passed"] else 1


if __name__ == "__main__":
    sys.exit(main())
