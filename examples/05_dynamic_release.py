"""Release of a pulled cable: the cantilever swings back and settles, with physics checks.

The cable cantilever of example 03 on the coarse 8 x 2 x 2 mesh (0.4 x 0.1 x 0.1 m, E = 66 kPa,
nu = 0.45, rho = 1080 kg/m^3, clamped at x = 0, gravity (0, 0, -9.81) m/s^2; cable along the lower
edge at y = z = 1 cm, 10 segments of 1e5 N/m, its first point anchored in the clamp as the motor).
First the cable is pulled quasi-statically to
alpha = 0.6 (``sf.actuate``, steps of 0.05): the beam curls towards the cable side (-y). Then,
starting from that equilibrium at rest, the cable is released at once (alpha = 1 from the first
time step) and the motion is integrated with implicit Euler (``sf.simulate``: dt = 10 ms, 400
steps = 4 s, lumped mass, Rayleigh damping alpha_M = 3 1/s, beta_K = 10 ms). The beam swings
through its gravity-only shape to the +y side, oscillates and settles.

The script exits with status 1 unless every check passes:

* ``pull_converged``: the quasi-static pull converged at every alpha.
* ``pulled_balance``: at the pulled equilibrium the support reactions, the weight and the
  anchor's pull on the cable (``-T_0`` along the first segment) balance to 1e-6 of the weight:
  the force the cable exerts on the body is the tension the solver reports.
* ``swings_through``: after the release the tip overshoots the gravity-only position towards +y
  by more than 2 cm (the motion is dynamic, not quasi-static).
* ``settles_to_static``: the final state matches the static gravity-only equilibrium (same body,
  alpha = 1, solved directly) to 1e-3 of its largest displacement.
* ``damping_rate``: from 1 s to 3.5 s the tip's sideways motion about the static position is one
  damped mode: fitting it with the two-term recurrence of implicit Euler,
  ``q_{n+1} = a_1 q_n + a_2 q_{n-1}`` per saved frame (5 steps), gives the per-step root ``z``
  of ``z^2 (1 + c h + w^2 h^2) - z (2 + c h) + 1 = 0`` and so the mode's frequency ``w`` and
  damping rate ``c`` (1/s). Rayleigh damping predicts ``c = alpha_M + beta_K w_K^2``, ``w_K^2``
  the mode's stiffness in the projected Hessian that beta_K multiplies; that Hessian is at least
  the exact one, so ``w_K >= w``, and in this bent, prestressed beam it is larger (about
  ``1.5 w^2``). The check asks ``alpha_M + beta_K w^2 <= c <= alpha_M + 2 beta_K w^2`` (2 %
  slack for the fit): doubling or halving either coefficient, or dropping beta_K, fails it.
* ``kinetic_energy_decays``: the largest kinetic energy of the last quarter of the simulation is
  below 1e-4 of that of the first quarter, and the final one below 1e-5 of the peak.
* ``released_cable_relaxed``: at the end the cable's tension (computed from its points with the
  spring law) is below 2 % of the pulled tension and equals the static gravity-only tension (zero
  along most of the lower edge, which gravity compresses; about 1 N in one segment near the tip)
  to 1e-3 of the pulled tension.
* ``no_cutbacks``: every time step converged at full length (Newton iterations per step are
  reported).

Outputs in ``--out DIR`` (default ``results/dynamic_release``): ``trajectory.pvd`` with
``trajectory/frame_NNNNN.vtu`` (every 5th step; the cable as line cells), ``pulled.png`` (the pulled
equilibrium, cable in red), ``release.png`` (tip displacement and kinetic energy against time) and
``summary.json``.

Run::

    python examples/05_dynamic_release.py --out results/dynamic_release
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
from sorofem.cables import segment_tensions

YOUNGS_MODULUS = 66e3  # Pa
POISSON_RATIO = 0.45
DENSITY = 1080.0  # kg/m^3
GRAVITY = np.array([0.0, 0.0, -9.81])  # m/s^2
SIZE = (0.4, 0.1, 0.1)  # m
CELLS = (8, 2, 2)
CABLE_START = (0.0, 0.01, 0.01)  # m
CABLE_DIVISIONS = 10
CABLE_STIFFNESS = 1e5  # N/m
PULL_ALPHA = 0.6
DT = 0.01  # s
STEPS = 400
DAMPING = (3.0, 0.01)  # Rayleigh alpha_M (1/s), beta_K (s)
SAVE_EVERY = 5
TOLERANCE = 1e-8

SETTLE_TOLERANCE = 1e-3
MIN_OVERSHOOT = 0.02  # m
BALANCE_TOLERANCE = 1e-6
FIT_FRAMES = (20, 70)  # saved frames (every SAVE_EVERY steps) of the damping fit: 1 s to 3.5 s
FIT_SLACK = 0.02


def build() -> tuple[sf.Body, sf.Cable]:
    mesh = sf.Mesh.box(size=SIZE, cells=CELLS)
    material = sf.NeoHookean(youngs_modulus=YOUNGS_MODULUS, poisson_ratio=POISSON_RATIO, density=DENSITY)
    body = sf.Body(mesh, material)
    body.fix(mesh.nodes_on_plane((0.0, 0.0, 0.0), (1.0, 0.0, 0.0)))
    cable = sf.Cable.line(CABLE_START, (1.0, 0.0, 0.0), SIZE[0], CABLE_DIVISIONS, stiffness=CABLE_STIFFNESS,
                          anchor_first=True)
    body.add_cable(cable)
    return body, cable


def damped_mode(q: np.ndarray, steps_per_frame: int, dt: float) -> tuple[float, float]:
    """Frequency ``w`` (rad/s) and damping rate ``c`` (1/s) of the one implicit Euler mode that
    best fits the samples ``q`` (every ``steps_per_frame`` steps of length ``dt``).

    Per step the mode obeys ``(q' - 2 q + q'') / h^2 + c (q' - q) / h + w^2 q' = 0``, whose roots
    ``z`` satisfy ``|z|^2 = 1 / (1 + c h + w^2 h^2)`` and ``z + conj(z) = (2 + c h) |z|^2``. Per
    frame the samples obey ``q_{k+1} = a_1 q_k + a_2 q_{k-1}`` with roots ``Z = z^steps_per_frame``.
    """
    (a1, a2), *_ = np.linalg.lstsq(np.column_stack([q[1:-1], q[:-2]]), q[2:], rcond=None)
    frame_root = np.roots([1.0, -a1, -a2])[0]
    z = frame_root ** (1.0 / steps_per_frame)  # the principal root: under a quarter turn per step
    ch = 2.0 * z.real / abs(z) ** 2 - 2.0
    w2h2 = 1.0 / abs(z) ** 2 - 1.0 - ch
    return float(np.sqrt(w2h2) / dt), float(ch / dt)


def lumped_weight(mesh: sf.Mesh) -> np.ndarray:
    """``rho V g / 4`` per tet and node, ``(n_nodes, 3)``, N."""
    forces = np.zeros((mesh.n_nodes, 3))
    for a in range(4):
        np.add.at(forces, mesh.tets[:, a], (DENSITY * mesh.volumes / 4.0)[:, None] * GRAVITY[None, :])
    return forces


def plot_release(traj: sf.Trajectory, tip: np.ndarray, reference: np.ndarray, path: Path) -> None:
    from matplotlib.figure import Figure  # no pyplot: no window, no global state

    fig = Figure(figsize=(7.0, 5.5), dpi=120)
    ax, ax_e = fig.add_subplot(2, 1, 1), fig.add_subplot(2, 1, 2)
    u = traj.displacement[:, tip].mean(axis=1)
    for k, name in ((1, "u_y"), (2, "u_z")):
        line, = ax.plot(traj.times, u[:, k], label=f"tip {name}")
        ax.axhline(reference[k], color=line.get_color(), linestyle="--", linewidth=0.8)
    ax.set_ylabel("tip displacement [m]")
    ax.set_title("cable released at t = 0 (dashed: static gravity-only equilibrium)")
    ax.legend()
    ax.grid(True, alpha=0.3)
    ax_e.semilogy(traj.times[1:], np.clip(traj.kinetic_energy[1:], 1e-300, None))
    ax_e.set_xlabel("time [s]")
    ax_e.set_ylabel("kinetic energy [J]")
    ax_e.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)


def run(out_dir: str | Path = "results/dynamic_release") -> dict[str, Any]:
    """Simulate, write the outputs to ``out_dir`` and return the summary (``checks`` inside)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    body, cable = build()
    mesh = body.mesh
    pull = sf.actuate(body, cable, PULL_ALPHA, gravity=GRAVITY, tolerance=TOLERANCE)
    pulled = pull[-1]
    t1 = time.perf_counter()
    traj = sf.simulate(body, DT, STEPS, actuation=1.0, gravity=GRAVITY, damping=DAMPING, initial=pulled,
                       save_every=SAVE_EVERY, tolerance=TOLERANCE)
    t2 = time.perf_counter()
    body.set_actuation(cable, 1.0)
    reference = sf.solve_static(body, gravity=GRAVITY, tolerance=TOLERANCE)

    tip = mesh.nodes_on_plane((SIZE[0], 0.0, 0.0), (1.0, 0.0, 0.0))
    u_tip = traj.displacement[:, tip].mean(axis=1)
    u_ref = reference.displacement[tip].mean(axis=0)
    overshoot = float(u_tip[:, 1].max() - u_ref[1])
    settle_error = float(np.abs(traj.final_positions - reference.positions).max() / reference.max_displacement)
    quarter = traj.n_frames // 4
    ke = traj.kinetic_energy
    decay = float(ke[-quarter:].max() / ke[:quarter].max())
    final_ke = float(ke[-1] / ke.max())
    final_tension = segment_tensions(cable, traj.cable_points[-1][0], 1.0)
    pulled_tension = float(pulled.cable_tensions[0].max())
    weight = lumped_weight(mesh).sum(axis=0)
    balance_error = float(np.linalg.norm(pulled.reactions.sum(axis=0) + weight + pulled.anchor_reactions[0])
                          / np.linalg.norm(weight))
    w, c = damped_mode(u_tip[FIT_FRAMES[0]:FIT_FRAMES[1], 1] - u_ref[1], SAVE_EVERY, DT)
    alpha_m, beta_k = DAMPING
    c_range = ((alpha_m + beta_k * w * w) * (1 - FIT_SLACK), (alpha_m + 2 * beta_k * w * w) * (1 + FIT_SLACK))

    checks = {
        "pull_converged": {
            "passed": all(r.report.converged for r in pull),
            "value": [r.report.iterations for r in pull],
            "limit": "Newton converged at every alpha",
        },
        "pulled_balance": {
            "passed": balance_error < BALANCE_TOLERANCE,
            "value": {"error": balance_error, "anchor_pull": float(np.linalg.norm(pulled.anchor_reactions[0]))},
            "limit": f"|sum R + W + A| / |W| < {BALANCE_TOLERANCE:g} at alpha = {PULL_ALPHA}",
        },
        "damping_rate": {
            "passed": c_range[0] < c < c_range[1],
            "value": {"c": c, "w": w, "c_range": list(c_range)},
            "limit": "alpha_M + beta_K w^2 <= c <= alpha_M + 2 beta_K w^2 (2 % slack), from frames "
                     f"{FIT_FRAMES[0]} to {FIT_FRAMES[1]}",
        },
        "swings_through": {
            "passed": overshoot > MIN_OVERSHOOT,
            "value": {"overshoot": overshoot, "pulled_tip_uy": float(u_tip[0, 1]), "static_tip_uy": float(u_ref[1])},
            "limit": f"max u_y(tip) - static u_y(tip) > {MIN_OVERSHOOT} m",
        },
        "settles_to_static": {
            "passed": settle_error < SETTLE_TOLERANCE,
            "value": settle_error,
            "limit": f"max |x(T) - x_static| / max |u_static| < {SETTLE_TOLERANCE:g}",
        },
        "kinetic_energy_decays": {
            "passed": decay < 1e-4 and final_ke < 1e-5,
            "value": {"last_over_first_quarter": decay, "final_over_peak": final_ke},
            "limit": "max KE(last quarter) / max KE(first quarter) < 1e-4, KE(T) / max KE < 1e-5",
        },
        "released_cable_relaxed": {
            "passed": bool(final_tension.max() < 0.02 * pulled_tension
                           and np.abs(final_tension - reference.cable_tensions[0]).max() < 1e-3 * pulled_tension),
            "value": {"final_max_tension": float(final_tension.max()), "pulled_max_tension": pulled_tension,
                      "static_max_tension": float(reference.cable_tensions[0].max())},
            "limit": "max T(T) < 2 % of the pulled max T, and T(T) = static T to 1e-3 of it",
        },
        "no_cutbacks": {
            "passed": traj.cutbacks == 0,
            "value": {"cutbacks": traj.cutbacks, "max_iterations_per_step": int(traj.iterations.max()),
                      "mean_iterations_per_step": float(traj.iterations.mean())},
            "limit": "no time step split",
        },
    }

    pvd = traj.write_pvd(out)
    sf.plot.plot_rest_and_deformed(pulled, out / "pulled.png",
                                   title=f"pulled to alpha = {PULL_ALPHA}: tip u_y = {u_tip[0, 1]:.3f} m")
    plot_release(traj, tip, u_ref, out / "release.png")
    summary = {
        "example": "05_dynamic_release",
        "n_nodes": mesh.n_nodes,
        "n_tets": mesh.n_tets,
        "cable": cable.to_dict(),
        "pull_alpha": PULL_ALPHA,
        "dt": DT,
        "steps": STEPS,
        "damping": {"alpha_M": DAMPING[0], "beta_K": DAMPING[1]},
        "trajectory": traj.to_dict(),
        "tip_uy_range": [float(u_tip[:, 1].min()), float(u_tip[:, 1].max())],
        "static_tip_displacement": u_ref.tolist(),
        "final_tip_displacement": u_tip[-1].tolist(),
        "checks": checks,
        "passed": all(c["passed"] for c in checks.values()),
        "files": [pvd.name, "trajectory/", "pulled.png", "release.png", "summary.json"],
        "timings": {"pull": t1 - t0, "simulate": t2 - t1, "total": time.perf_counter() - t0},
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    return summary


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("results/dynamic_release"), metavar="DIR")
    args = parser.parse_args(argv)
    try:
        summary = run(args.out)
    except sf.ConvergenceError as exc:
        print(f"error: the solver did not converge: {exc}", file=sys.stderr)
        return 3
    traj = summary["trajectory"]
    print(f"{summary['steps']} steps of {summary['dt'] * 1e3:g} ms: {traj['newton_iterations']} Newton iterations "
          f"(max {traj['max_iterations_per_step']} per step), {traj['cutbacks']} cutbacks, "
          f"{summary['timings']['simulate']:.2f} s")
    print(f"tip u_y from {summary['tip_uy_range'][0]:.4f} to {summary['tip_uy_range'][1]:.4f} m; final tip "
          f"{np.round(summary['final_tip_displacement'], 4).tolist()} m, static "
          f"{np.round(summary['static_tip_displacement'], 4).tolist()} m")
    for name, check in summary["checks"].items():
        print(f"[{'ok' if check['passed'] else 'FAILED'}] {name}: {check['limit']}")
    print(f"{'all checks passed' if summary['passed'] else 'SOME CHECKS FAILED'}; wrote {', '.join(summary['files'])} "
          f"to {args.out} in {summary['timings']['total']:.1f} s")
    return 0 if summary["passed"] else 1


if __name__ == "__main__":
    sys.exit(main())
