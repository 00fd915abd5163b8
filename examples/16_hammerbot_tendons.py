"""The paper's hammerbot bent by a sliding tendon, beside the spring chain it replaces: the
tension the motor holds, and how the spring chain approaches the tendon as its stiffness grows.

Model: example 04's hammerbot (SolidFEM's ``hammerbot_fine.tet`` from ``../shared/data/solidfem``
beside the repository, skipped when missing; 2346 nodes, 9011 tets, scaled by 0.01 to metres;
the 92 nodes of the face x = -5 cm clamped; Neo-Hookean E = 100 kPa, nu = 0.4, rho = 1070
kg/m^3; gravity (0, -9.8, 0) m/s^2) with example 04's two cable routes (mid-plane z = 0, from
x = -4.5 to +4.5 cm at y = +6 mm and y = -6 mm, 18 segments of 5 mm, L0 = 9 cm), now as the
issue-16 tendons: each runs from its motor (a world anchor at its first point, x = -4.5 cm,
inside the clamped flange) through 17 guide points to where it is tied (x = +4.5 cm), sliding
freely. The paper drives its spring cables by alpha1 = 0.82 (pulled) and alpha2 = 1.2 (paid
out); the motors here command the lengths those give: pull ``d = (1 - alpha) L0``, i.e. 16.2 mm
on the +y tendon and -18 mm (paid out) on the -y one, which therefore stays slack.

The pull is reached by continuation from the gravity-only equilibrium in 1 mm steps
(``sf.actuate``, each step warm-started from the last). Beside it, the same two routes as
spring chains (``model="springs"``, the paper's cable, bonded to the body at every point, also
anchored at their first point) at alpha = 0.82 / 1.2 with k = 5e3, 5e4 (example 04's and
the cables benchmark's) and 5e5 N/m per segment.

**What the spring chain converges to.** As k grows, a spring chain does not become the sliding
tendon: its points are bonded to the body, so it tends to the chain whose every segment is held
at its taut length ``alpha l + w / 2`` (``w = transition l``, the end of the springs' smooth
slack-to-taut transition), not to a line held only in total length. That limit is computed
exactly here too, as 18 one-segment tendons (``bonded``: each pulled ``(1 - alpha) l - w / 2``);
the spring chain converges to it like 1/k, while its distance to the sliding tendon levels off
at the distance between the bonded and the sliding limit: sliding moves the tip by millimetres
that no spring stiffness recovers (``summary.json``: ``springs``, ``sliding_vs_bonded``). The
tendon's one tension lets its segments in the stiff clamped flange shorten by 7 to 8 % and those
in the web by up to 26 % (``segment_length_ratios``), where the bonded chain shortens each by 18 %.

The script exits with status 1 unless every check passes:

* ``converged``: every solve converged.
* ``pull_achieved``: the pulled tendon's pull ``L0 - L`` equals the command to 1e-9 relative.
* ``tension_positive``: the pulled tendon is taut, T > 0 (a tendon never pushes: T >= 0).
* ``slack_tendon``: the paid-out tendon carries T = 0 exactly and is shorter than its allowed
  length ``L0 - d`` (it is slack, not just at its limit).
* ``balance``: clamp reactions + the motors' forces + weight = 0, relative to the weight, to
  1e-8, at the tendon's equilibrium, the bonded limit's and every spring chain's.
* ``tension_is_energy_slope``: the tension equals the derivative of the equilibrium's potential
  energy (strain + gravity) with respect to the pull (central differences at d +- 0.01 mm,
  two more solves) to 1e-6 relative: the multiplier is the force the motor works against.
* ``continuation_warm_started``: every 1 mm step after the first takes at most 5 Newton
  iterations.
* ``springs_converge_like_1_over_k``: the distance between the spring chain's and the bonded
  limit's mean tip displacement shrinks at every tenfold k by a factor between 3 and 30.

Outputs in ``--out DIR`` (default ``results/hammerbot_tendons``): ``result.vtu`` and
``cables.vtu`` (tendon solution), ``shape.png``, ``continuation.png`` (tension and Newton
iterations along the pull) and ``summary.json``. ``--quick`` (what the test suite runs) pulls in
1 mm steps only over the last 3.2 mm (its first step goes from gravity alone to 13 mm).

Run::

    python examples/16_hammerbot_tendons.py --out results/hammerbot_tendons [--quick]
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
CABLE_Y = 0.006  # m: the routes at y = +-6 mm, 1.5 mm inside the web's faces (example 04)
CABLE_X = (-0.045, 0.045)  # m
CABLE_LENGTH = CABLE_X[1] - CABLE_X[0]
CABLE_DIVISIONS = 18
ALPHAS = (0.82, 1.2)  # the paper's
PULLS = tuple((1.0 - a) * CABLE_LENGTH for a in ALPHAS)  # m
SPRING_STIFFNESSES = (5e3, 5e4, 5e5)  # N/m per segment; 5e4 is example 04's
PULL_STEP = 1e-3  # m
QUICK_FIRST_PULL = 13e-3  # m
TOLERANCE = 1e-8

PULL_TOLERANCE = 1e-9
BALANCE_TOLERANCE = 1e-8
WARM_ITERATIONS = 5
DECADE_FACTOR = (3.0, 30.0)  # 1/k convergence: each tenfold k divides the distance by about 10
ENERGY_STEP = 1e-5  # m
ENERGY_TOLERANCE = 1e-6


def build(mesh: sf.Mesh) -> sf.Body:
    material = sf.NeoHookean(youngs_modulus=YOUNGS_MODULUS, poisson_ratio=POISSON_RATIO, density=DENSITY)
    body = sf.Body(mesh, material)
    body.fix(mesh.nodes_on_plane((CLAMP_X, 0.0, 0.0), (1.0, 0.0, 0.0)))
    return body


def routes(**options: Any) -> list[sf.Cable]:
    """Example 04's two routes (+y first), anchored at their first point (the motor); spring
    chains get the paper's alphas, tendons the ``options`` they are given."""
    springs = options.get("model", "springs") == "springs"
    return [sf.Cable.line((CABLE_X[0], y, 0.0), (1.0, 0.0, 0.0), CABLE_LENGTH, CABLE_DIVISIONS, anchor_first=True,
                          **options, **({"actuation": alpha} if springs else {}))
            for y, alpha in ((CABLE_Y, ALPHAS[0]), (-CABLE_Y, ALPHAS[1]))]


def bonded(route: sf.Cable, transition: float) -> list[sf.Cable]:
    """The limit of a spring chain along ``route`` as its stiffness grows: one tendon per
    segment, each held at the taut springs' length ``alpha l + w / 2`` (``w = transition l``),
    the first anchored like the route."""
    alpha = ALPHAS[0]
    return [sf.Cable(route.points[i:i + 2], model="tendon", anchor_first=route.anchor_first and i == 0,
                     pull=(1.0 - alpha) * l - transition * l / 2)
            for i, l in enumerate(route.rest_lengths)]


def balance_error(result: sf.StaticResult) -> float:
    """``|sum R + sum F_motors + W| / |W|``: clamp reactions, the forces of the cables' world
    anchors and the weight."""
    weight = float(DENSITY * result.mesh.volumes.sum()) * GRAVITY
    motors = np.sum([f for f in result.anchor_reactions if f is not None], axis=0)
    return float(np.linalg.norm(result.reactions.sum(axis=0) + motors + weight) / np.linalg.norm(weight))


def tip_displacement(result: sf.StaticResult) -> np.ndarray:
    """Mean displacement (m) of the nodes of the free face x = +5 cm."""
    tip = result.mesh.nodes_on_plane((TIP_X, 0.0, 0.0), (1.0, 0.0, 0.0))
    return result.displacement[tip].mean(axis=0)


def potential_energy(body: sf.Body, result: sf.StaticResult) -> float:
    """Strain energy plus the potential of gravity, ``-rho g . sum_e V_e c_e`` (c_e the deformed
    centroid; exact for linear tetrahedra), J."""
    centroids = result.positions[body.mesh.tets].mean(axis=1)
    gravity = -DENSITY * float(body.mesh.volumes @ (centroids @ GRAVITY))
    return body.core_model().strain_energy(result.positions) + gravity


def pull_path(quick: bool) -> list[float]:
    """The pulls of the continuation, m: 1 mm steps to the command (the last step shorter);
    ``quick`` starts at 13 mm."""
    target = PULLS[0]
    steps = np.arange(PULL_STEP, target, PULL_STEP)
    path = [float(p) for p in steps if not np.isclose(p, target, rtol=0, atol=1e-12)] + [target]
    return [p for p in path if p >= QUICK_FIRST_PULL - 1e-12] if quick else path


def run(out_dir: str | Path = "results/hammerbot_tendons", quick: bool = False) -> dict[str, Any]:
    """Solve, write the outputs to ``out_dir`` and return the summary (``checks`` inside)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    if not MESH_FILE.is_file():
        raise FileNotFoundError(
            f"this example needs the SolidFEM sample mesh {MESH_FILE} (../shared/data/solidfem beside the repository)"
        )
    mesh = sf.Mesh.read(MESH_FILE, scale=SCALE)
    body = build(mesh)
    gravity_only = sf.solve_static(body, gravity=GRAVITY, tolerance=TOLERANCE)

    # Tendons: the pulled one by continuation in its pull, the other paid out (slack) throughout.
    pulled, paid_out = routes(model="tendon")
    body.add_cable(pulled)
    body.add_cable(paid_out)
    body.pull(1, displacement=PULLS[1])
    placements = [[p.kind for p in cable] for cable in body.cable_placements()]
    path = pull_path(quick)
    steps = sf.actuate(body, 0, path, gravity=GRAVITY, initial=gravity_only, tolerance=TOLERANCE)
    result = steps[-1]
    iterations = [s.report.iterations for s in steps]
    tension = [float(t) for t in result.cable_tension]
    pull = [float(p) for p in result.cable_pull]

    # The tension against the slope of the equilibrium's energy in the pull.
    energies = []
    for d in (PULLS[0] + ENERGY_STEP, PULLS[0] - ENERGY_STEP):
        body.pull(0, displacement=d)
        energies.append(potential_energy(body, sf.solve_static(body, gravity=GRAVITY, tolerance=TOLERANCE,
                                                               initial=result)))
    body.pull(0, displacement=PULLS[0])
    slope = (energies[0] - energies[1]) / (2 * ENERGY_STEP)

    # The spring chains at growing k, and their limit: the bonded segments.
    u_tendon = tip_displacement(result)
    transition = routes(stiffness=1.0)[0].transition
    limit_body = build(mesh)
    for cable in bonded(pulled, transition) + routes(model="tendon", pull=PULLS[1])[1:]:
        limit_body.add_cable(cable)
    limit = sf.solve_static(limit_body, gravity=GRAVITY, tolerance=TOLERANCE, initial=gravity_only)
    u_limit = tip_displacement(limit)
    springs, balances = [], {"tendon": balance_error(result), "bonded_limit": balance_error(limit)}
    for k in SPRING_STIFFNESSES:
        chain_body = build(mesh)
        for cable in routes(stiffness=k):
            chain_body.add_cable(cable)
        chain = sf.solve_static(chain_body, gravity=GRAVITY, tolerance=TOLERANCE, initial=gravity_only)
        u = tip_displacement(chain)
        balances[f"springs_{k:g}"] = balance_error(chain)
        springs.append({
            "stiffness": k, "converged": bool(chain.report.converged), "newton_iterations": chain.report.iterations,
            "tip_displacement": u.tolist(), "to_tendon": float(np.linalg.norm(u - u_tendon)),
            "to_bonded_limit": float(np.linalg.norm(u - u_limit)),
            "tensions": chain.cable_tensions[0].tolist(),
            "tension_range": [float(chain.cable_tensions[0].min()), float(chain.cable_tensions[0].max())],
            "pull": [float(p) for p in chain.cable_pull],
        })
    to_limit = [s["to_bonded_limit"] for s in springs]
    factors = [a / b for a, b in zip(to_limit, to_limit[1:])]

    checks = {
        "converged": {
            "passed": bool(gravity_only.report.converged and all(s.report.converged for s in steps)
                           and limit.report.converged and all(s["converged"] for s in springs)),
            "value": {"continuation_steps": len(steps), "bonded_limit_iterations": limit.report.iterations,
                      "springs": [s["converged"] for s in springs]},
            "limit": "every solve converged",
        },
        "pull_achieved": {
            "passed": abs(pull[0] - PULLS[0]) <= PULL_TOLERANCE * PULLS[0],
            "value": {"pull": pull[0], "command": PULLS[0], "relative_error": abs(pull[0] - PULLS[0]) / PULLS[0]},
            "limit": f"|L0 - L - d| / d <= {PULL_TOLERANCE:g}",
        },
        "tension_positive": {
            "passed": tension[0] > 0,
            "value": tension[0],
            "limit": "T > 0 N on the pulled tendon",
        },
        "slack_tendon": {
            "passed": tension[1] == 0.0 and pull[1] > PULLS[1],
            "value": {"tension": tension[1], "pull": pull[1], "command": PULLS[1]},
            "limit": "T = 0 N and L < L0 - d (pull above its negative command)",
        },
        "balance": {
            "passed": max(balances.values()) < BALANCE_TOLERANCE,
            "value": balances,
            "limit": f"|sum R + F_motors + W| / |W| < {BALANCE_TOLERANCE:g} at every equilibrium",
        },
        "tension_is_energy_slope": {
            "passed": abs(slope - tension[0]) <= ENERGY_TOLERANCE * tension[0],
            "value": {"dPi_dd": slope, "tension": tension[0], "relative_difference": abs(slope / tension[0] - 1)},
            "limit": f"|dPi/dd - T| / T <= {ENERGY_TOLERANCE:g} (central differences, step {ENERGY_STEP:g} m)",
        },
        "continuation_warm_started": {
            "passed": all(n <= WARM_ITERATIONS for n in iterations[1:]),
            "value": {"pulls_mm": [1e3 * p for p in path], "newton_iterations": iterations},
            "limit": f"<= {WARM_ITERATIONS} Newton iterations per further {1e3 * PULL_STEP:g} mm step",
        },
        "springs_converge_like_1_over_k": {
            "passed": all(DECADE_FACTOR[0] <= f <= DECADE_FACTOR[1] for f in factors),
            "value": {"stiffness": list(SPRING_STIFFNESSES), "to_bonded_limit": to_limit, "decade_factors": factors},
            "limit": f"|u_tip(springs, k) - u_tip(bonded limit)| divided by {DECADE_FACTOR[0]:g} .. "
                     f"{DECADE_FACTOR[1]:g} at every tenfold k",
        },
    }

    sf.io.write_result(out / "result.vtu", result)
    sf.cables.write_cables(out / "cables.vtu", result)
    sf.plot.plot_rest_and_deformed(
        result, out / "shape.png",
        title=f"hammerbot, tendon pulled {1e3 * PULLS[0]:.1f} mm: T = {tension[0]:.2f} N, tip u_y = "
              f"{1e2 * u_tendon[1]:.2f} cm",
    )
    _plot_continuation(path, steps, out / "continuation.png")
    summary = {
        "example": "16_hammerbot_tendons",
        "quick": quick,
        "mesh": str(MESH_FILE),
        "n_nodes": mesh.n_nodes,
        "n_tets": mesh.n_tets,
        "tendons": [c.to_dict() for c in body.cables],
        "placements": placements,
        "pulls_commanded": list(PULLS),
        "tension": tension,
        "pull": pull,
        "tip_displacement": u_tendon.tolist(),
        "segment_length_ratios": (np.linalg.norm(np.diff(result.cable_points[0], axis=0), axis=1)
                                  / pulled.rest_lengths).tolist(),
        "gravity_only_tip_displacement": tip_displacement(gravity_only).tolist(),
        "motor_forces": [None if f is None else f.tolist() for f in result.anchor_reactions],
        "continuation": {"pulls": path, "tensions": [float(s.cable_tension[0]) for s in steps],
                         "newton_iterations": iterations},
        "springs": springs,
        "bonded_limit": {"tip_displacement": u_limit.tolist(), "tensions": limit.cable_tension[:-1],
                         "pull": float(sum(limit.cable_pull[:-1])), "newton_iterations": limit.report.iterations},
        "sliding_vs_bonded": float(np.linalg.norm(u_limit - u_tendon)),
        "checks": checks,
        "passed": all(c["passed"] for c in checks.values()),
        "files": ["result.vtu", "cables.vtu", "shape.png", "continuation.png", "summary.json"],
        "timings": {"total": time.perf_counter() - t0},
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    return summary


def _plot_continuation(path: list[float], steps: list[sf.StaticResult], file: Path) -> None:
    """The tension and the Newton iterations of each step along the pull."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.0, 3.6), layout="constrained")
    pulls = 1e3 * np.asarray(path)
    ax.plot(pulls, [s.cable_tension[0] for s in steps], "o-", label="tension")
    ax.set_xlabel("pull d [mm]")
    ax.set_ylabel("tension T [N]")
    twin = ax.twinx()
    twin.bar(pulls, [s.report.iterations for s in steps], width=0.4, alpha=0.3, color="C1", label="Newton iterations")
    twin.set_ylabel("Newton iterations")
    ax.set_zorder(twin.get_zorder() + 1)  # the tension in front of the bars
    ax.patch.set_visible(False)
    ax.set_title("hammerbot tendon: continuation in the pull", fontsize="medium")
    fig.savefig(file)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("results/hammerbot_tendons"), metavar="DIR")
    parser.add_argument("--quick", action="store_true", help="the continuation from 13 mm on")
    args = parser.parse_args(argv)
    missing = [str(f) for f in REQUIRED_FILES if not f.is_file()]
    if missing:
        print(f"skipped: missing data {', '.join(missing)}", file=sys.stderr)
        return 0
    try:
        summary = run(args.out, quick=args.quick)
    except sf.ConvergenceError as exc:
        print(f"error: the solver did not converge: {exc}", file=sys.stderr)
        return 3
    t, d = summary["tension"], summary["pull"]
    print(f"pulled tendon: d = {1e3 * d[0]:.4f} mm, T = {t[0]:.4f} N; paid-out tendon: T = {t[1]:g} N "
          f"(pull {1e3 * d[1]:.3f} mm, command {1e3 * summary['pulls_commanded'][1]:.1f} mm)")
    print(f"tip displacement {np.round(np.asarray(summary['tip_displacement']) * 1e3, 3).tolist()} mm")
    print("Newton iterations along the pull: " + ", ".join(
        f"{1e3 * p:.1f} mm: {n}" for p, n in zip(summary["continuation"]["pulls"],
                                                  summary["continuation"]["newton_iterations"])))
    limit = summary["bonded_limit"]
    print(f"bonded limit (one tendon per segment): tip {np.round(np.asarray(limit['tip_displacement']) * 1e3, 3).tolist()}"
          f" mm, tensions {min(limit['tensions']):.3f} .. {max(limit['tensions']):.3f} N; "
          f"{1e3 * summary['sliding_vs_bonded']:.3f} mm from the sliding tendon's tip")
    for s in summary["springs"]:
        lo, hi = s["tension_range"]
        print(f"springs k = {s['stiffness']:.0e} N/m: tip {np.round(np.asarray(s['tip_displacement']) * 1e3, 3).tolist()}"
              f" mm, {1e3 * s['to_tendon']:.3f} mm from the tendon's, {1e3 * s['to_bonded_limit']:.4f} mm from the "
              f"bonded limit's; tensions {lo:.3f} .. {hi:.3f} N, pull {1e3 * s['pull'][0]:.3f} mm, "
              f"{s['newton_iterations']} Newton it.")
    for name, check in summary["checks"].items():
        print(f"[{'ok' if check['passed'] else 'FAILED'}] {name}: {check['limit']}")
    print(f"{'all checks passed' if summary['passed'] else 'SOME CHECKS FAILED'} in {summary['timings']['total']:.1f} s; "
          f"wrote {', '.join(summary['files'])} to {args.out}")
    return 0 if summary["passed"] else 1


if __name__ == "__main__":
    sys.exit(main())
