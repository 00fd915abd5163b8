"""From a CAD-style surface (STL) to a simulated cable-driven finger, with physics checks.

Many soft robots exist only as the closed triangle surface of their mould cavity. This example
makes such a surface itself, a tapered silicone finger, writes it as a binary STL with meshio,
fills it with tetrahedra through ``sf.tetrahedralize`` (fTetWild, the optional extra:
``pip install ".[mesh]"`` from a checkout), clamps its base and pulls a cable threaded through it.

The finger: 120 mm long along x, its cross-section a rounded square (the superellipse
``|y/a|^4 + |z/a|^4 = 1`` sampled at 24 points) whose half-width ``a`` tapers linearly from
12.5 mm at the base (x = 0) to 7.5 mm at the tip, with flat end caps: 96 triangles, every side
facet planar (a CAD export of a lofted body looks like this). Silicone like Dragon Skin 10:
Neo-Hookean, E = 150 kPa, nu = 0.49, rho = 1070 kg/m^3, in the **mixed** formulation (nu = 0.49
locks standard linear tetrahedra). Gravity (0, 0, -9.81) m/s^2. The base face is clamped.

The cable runs on the upper (dorsal, +z) side at half the local half-height, from 5 mm inside
the base to 6 mm short of the tip, 12 segments bonded to the silicone (stiffness 1e5 N/m each),
and leaves through the base to a motor 10 mm behind the clamp: its first point is a world
anchor (``anchor_first=True``). The motor winds it in, alpha = 1 -> 0.94 by continuation
(``sf.actuate``), which curls the finger upwards against gravity.

The script exits with status 1 unless every check passes:

* ``surface_volume``: the divergence-theorem volume of the STL, ``1/6 sum a . (b x c)``, equals
  the frustum formula ``A0 L (1 + s + s^2) / 3`` of this polyhedron (cross-section area A0,
  taper ratio s = 0.6) to 1e-6 (binary STL stores float32 coordinates; observed 1e-8).
* ``mesh_volume``: at every refinement level the tetrahedra fill the volume the surface
  encloses, within the envelope fTetWild works in: its mesh boundary lies within
  ``eps = envelope x diagonal`` of the surface, so the two volumes differ at most by the
  envelope's volume ``2 eps A`` (A the surface area; 5.1 % of V here). The observed difference
  is far smaller, 0.1-0.3 % (fTetWild flattens the rounded corners a little within the
  envelope); the summary reports both.
* ``converged``: every Newton solve converged.
* ``tip_deflection_converges``: the gravity-only tip deflection (area average of u_z over the
  tip face) on three meshes, target edge length h, h/2, h/4: the change between successive
  levels shrinks, by more than 1.2x. Linear tetrahedra in bending converge like h^1..h^2, so
  2x..4x is expected; fTetWild's meshes differ from run to run, which moves the coarsest
  quick-mode deflection by about 1 mm (standard deviation) against level-to-level changes of
  8 and 4 mm: over 15 quick runs the ratio was 1.4 to 3.3 (mean 2.2), and 1.2 keeps a false
  failure below 1e-3 (normal estimate). The observed order and a Richardson extrapolation are reported.
* ``gravity_force_balance``: under gravity alone the clamp reactions carry the weight
  ``rho V g`` (relative 1e-6).
* ``cable_anchor_balance``: with the cable pulled, the only external loads are the weight, the
  clamp reactions and the motor's pull ``A = result.anchor_reactions[0]``, which the anchored
  segment passes on to the body at its first embedded point: force and moment balance to 1e-6
  of ``|W| + T0`` (times the length), and ``A`` equals ``T0`` (that segment's tension) along
  the segment, recomputed here from the cable points.
* ``cable_embedded``: every cable point but the anchor lies inside a tetrahedron.
* ``cable_lifts_tip``: the pulled finger's tip rises above where gravity alone leaves it by
  more than 10 % of the length, and every segment is taut.

Outputs in ``--out DIR`` (default ``results/surface_to_robot``): ``finger.stl`` (the surface),
``mesh.vtu`` (the finest tetrahedral mesh), ``result.vtu`` and ``cables.vtu`` (cable pulled),
``shape.png`` (rest and deformed), ``convergence.png`` (tip deflection against mesh size) and
``summary.json``. ``--quick`` (what the test suite runs) uses coarser meshes (h = 12, 6, 3 mm
instead of 8, 4, 2 mm) and larger continuation steps.

If the mesher is not installed the script says so and exits with status 2 (the test suite
skips it). Run::

    pip install ".[mesh]"
    python examples/10_surface_to_robot.py --out results/surface_to_robot [--quick]
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

#: Python modules the example needs beyond sorofem's own; tests/test_examples.py skips it
#: when one is missing.
REQUIRED_MODULES = (sf.meshing.MESHER,)

LENGTH = 0.12  # m, along x
HALF_WIDTH = (0.0125, 0.0075)  # m, base and tip
EXPONENT = 4.0  # superellipse |y/a|^p + |z/a|^p = 1: a rounded square
N_AROUND = 24
YOUNGS_MODULUS = 150e3  # Pa (Dragon Skin 10-like)
POISSON_RATIO = 0.49
DENSITY = 1070.0  # kg/m^3
GRAVITY = np.array([0.0, 0.0, -9.81])  # m/s^2
ENVELOPE = 1e-3  # fTetWild's envelope, fraction of the bounding-box diagonal
LEVELS = {True: (0.012, 0.006, 0.003), False: (0.008, 0.004, 0.002)}  # target edge lengths, m
CABLE_HEIGHT = 0.5  # cable at z = 0.5 a(x): half-way up the upper half
CABLE_X = (0.005, LENGTH - 0.006)  # m, embedded part
MOTOR_X = -0.01  # m, the anchor behind the clamp
CABLE_DIVISIONS = 12
CABLE_STIFFNESS = 1e5  # N/m per segment
TARGET_ALPHA = 0.94
ALPHA_STEP = {True: 0.03, False: 0.02}
TOLERANCE = 1e-8

BALANCE_TOLERANCE = 1e-6
MIN_SHRINK = 1.2  # successive changes of the tip deflection must shrink by more than this
MIN_LIFT = 0.1  # the cable lifts the tip by more than this fraction of the length


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
    base = np.c_[np.full(n, 2 * n), k, j]  # normal -x
    tip = np.c_[np.full(n, 2 * n + 1), j + n, k + n]  # normal +x
    return points, np.r_[sides, base, tip].astype(np.int64)


def frustum_volume(points: np.ndarray) -> float:
    """Exact volume of the polyhedron: cross-sections are the base polygon scaled by s(x)."""
    ring = points[:N_AROUND, 1:]
    area = 0.5 * float(np.sum(ring[:, 0] * np.roll(ring[:, 1], -1) - np.roll(ring[:, 0], -1) * ring[:, 1]))
    ratio = HALF_WIDTH[1] / HALF_WIDTH[0]
    return area * LENGTH * (1.0 + ratio + ratio**2) / 3.0


def clamp_and_tip(mesh: sf.Mesh, length: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Boundary nodes on the base plane; boundary faces of the tip and their areas.

    fTetWild's boundary lies within the envelope of the surface, so both are found with that
    tolerance (relative to the bounding-box diagonal, like ``nodes_on_plane``'s ``tol``)."""
    faces = mesh.boundary_faces()
    on_boundary = np.unique(faces)
    base = np.intersect1d(mesh.nodes_on_plane((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), tol=ENVELOPE), on_boundary)
    corners = mesh.points[faces]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    areas = 0.5 * np.linalg.norm(normals, axis=1)
    tip = (normals[:, 0] / (2 * areas) > 0.99) & (corners[:, :, 0].min(axis=1) > length - ENVELOPE * mesh.size)
    return base, faces[tip], areas[tip]


def face_average(values: np.ndarray, faces: np.ndarray, areas: np.ndarray) -> np.ndarray:
    """Area average over the faces of a P1 field (exact: the mean of a linear function on a
    triangle is the mean of its corner values)."""
    return (values[faces].mean(axis=1) * areas[:, None]).sum(axis=0) / areas.sum()


def lumped_weight(mesh: sf.Mesh) -> np.ndarray:
    """``rho V g / 4`` per tet and node (exact for linear tets), ``(n_nodes, 3)``, N."""
    forces = np.zeros((mesh.n_nodes, 3))
    for a in range(4):
        np.add.at(forces, mesh.tets[:, a], (DENSITY * mesh.volumes / 4.0)[:, None] * GRAVITY[None, :])
    return forces


def make_cable() -> sf.Cable:
    x = np.linspace(CABLE_X[0], CABLE_X[1], CABLE_DIVISIONS + 1)
    inside = np.c_[x, np.zeros_like(x), CABLE_HEIGHT * half_width(x)]
    motor = [MOTOR_X, 0.0, CABLE_HEIGHT * HALF_WIDTH[0]]
    return sf.Cable(np.vstack([motor, inside]), stiffness=CABLE_STIFFNESS, anchor_first=True)


def plot_convergence(levels: list[dict[str, Any]], extrapolated: float, path: Path) -> None:
    from matplotlib.figure import Figure  # no pyplot: no window, no global state

    fig = Figure(figsize=(6.0, 4.0), dpi=120)
    ax = fig.add_subplot()
    h = np.array([lv["edge_length"] for lv in levels]) * 1e3
    u = -np.array([lv["tip_uz"] for lv in levels]) * 1e3
    ax.plot(h, u, "o-", label="fTetWild mesh, mixed P1-P1")
    for hi, ui, lv in zip(h, u, levels):
        ax.annotate(f"{lv['n_tets']} tets", (hi, ui), textcoords="offset points", xytext=(5, -12), fontsize=8)
    ax.axhline(-extrapolated * 1e3, color="grey", ls="--", label="Richardson extrapolation")
    ax.set_xlabel("target edge length h [mm]")
    ax.set_ylabel("tip deflection under gravity [mm]")
    ax.set_title("tapered finger: gravity-only tip deflection vs mesh size")
    ax.invert_xaxis()
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)


def run(out_dir: str | Path = "results/surface_to_robot", quick: bool = False) -> dict[str, Any]:
    """Make the surface, mesh, simulate, write the outputs to ``out_dir`` and return the summary."""
    import meshio

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    timings: dict[str, float] = {}

    # The surface, as a CAD tool would hand it over.
    points, triangles = finger_surface()
    stl = out / "finger.stl"
    meshio.write(stl, meshio.Mesh(points, [("triangle", triangles)]), file_format="stl", binary=True)
    surf_points, surf_triangles = sf.meshing.check_surface(*sf.meshing.read_surface(stl))
    enclosed = sf.meshing.surface_volume(surf_points, surf_triangles)
    area = sf.meshing.surface_area(surf_points, surf_triangles)
    diagonal = float(np.linalg.norm(surf_points.max(axis=0) - surf_points.min(axis=0)))
    length = float(surf_points[:, 0].max())
    frustum = frustum_volume(points)
    volume_bound = 2.0 * ENVELOPE * diagonal * area  # the envelope's volume

    material = sf.NeoHookean(youngs_modulus=YOUNGS_MODULUS, poisson_ratio=POISSON_RATIO, density=DENSITY)
    levels: list[dict[str, Any]] = []
    for h in LEVELS[quick]:
        t = time.perf_counter()
        mesh = sf.tetrahedralize(stl, edge_length=h, envelope=ENVELOPE)
        t_mesh = time.perf_counter() - t
        body = sf.Body(mesh, material, formulation="mixed")
        base, tip_faces, tip_areas = clamp_and_tip(mesh, length)
        body.fix(base)
        t = time.perf_counter()
        result = sf.solve_static(body, gravity=GRAVITY, tolerance=TOLERANCE)
        t_solve = time.perf_counter() - t
        weight = float(DENSITY * mesh.volumes.sum()) * GRAVITY
        levels.append({
            "edge_length": h,
            "n_nodes": mesh.n_nodes,
            "n_tets": mesh.n_tets,
            "n_clamped": int(base.size),
            "volume": float(mesh.volumes.sum()),
            "volume_error": float(mesh.volumes.sum() - enclosed),
            "tip_area": float(tip_areas.sum()),
            "tip_uz": float(face_average(result.displacement, tip_faces, tip_areas)[2]),
            "newton_iterations": result.report.iterations,
            "converged": result.report.converged,
            "force_balance_error": float(np.linalg.norm(result.reactions.sum(axis=0) + weight) / np.linalg.norm(weight)),
            "min_J": float(result.J.min()),
            "timings": {"mesh": t_mesh, "solve": t_solve},
        })
    timings["meshing_and_gravity"] = time.perf_counter() - t0

    # The finest mesh, with the cable: gravity alone, then the motor winds the cable in.
    finest = levels[-1]
    cable = make_cable()
    body.add_cable(cable)
    placements = [p.kind for p in body.cable_placements()[0]]
    t = time.perf_counter()
    path = sf.actuate(body, cable, TARGET_ALPHA, gravity=GRAVITY, max_step=ALPHA_STEP[quick], tolerance=TOLERANCE,
                      initial=result)
    timings["cable"] = time.perf_counter() - t
    final = path[-1]
    u_tip = face_average(final.displacement, tip_faces, tip_areas)
    tensions = final.cable_tensions[0]
    cable_points = final.cable_points[0]

    # Balance with the cable: reactions + weight + the anchor's pull, which the anchored
    # segment passes on to the body at the first embedded point.
    f_grav = lumped_weight(mesh)
    weight = f_grav.sum(axis=0)
    pull = final.anchor_reactions[0]
    recomputed = tensions[0] * (cable_points[0] - cable_points[1]) / np.linalg.norm(cable_points[0] - cable_points[1])
    pull_error = float(np.linalg.norm(pull - recomputed)) / float(tensions[0])
    scale = float(np.linalg.norm(weight)) + float(tensions[0])
    fixed = body.fixed_nodes
    force_error = float(np.linalg.norm(final.reactions.sum(axis=0) + weight + pull)) / scale
    moment = (np.cross(final.positions[fixed], final.reactions).sum(axis=0)
              + np.cross(final.positions, f_grav).sum(axis=0) + np.cross(cable_points[1], pull))
    moment_error = float(np.linalg.norm(moment)) / (scale * length)

    # Convergence of the gravity-only tip deflection.
    u = np.array([lv["tip_uz"] for lv in levels])
    changes = np.abs(np.diff(u))
    shrink = float(changes[0] / changes[1])
    order = float(np.log2(shrink))  # the levels halve h
    extrapolated = float(u[-1] + (u[-1] - u[-2]) / (shrink - 1.0)) if shrink > 1 else float("nan")
    volume_errors = [abs(lv["volume_error"]) / enclosed for lv in levels]

    checks = {
        "surface_volume": {
            "passed": abs(enclosed / frustum - 1.0) < 1e-6,
            "value": {"divergence_theorem": enclosed, "frustum_formula": frustum, "relative_difference": enclosed / frustum - 1.0},
            "limit": "|V_surface / V_frustum - 1| < 1e-6",
        },
        "mesh_volume": {
            "passed": all(abs(lv["volume_error"]) <= volume_bound for lv in levels),
            "value": {"relative_errors": volume_errors, "bound_relative": volume_bound / enclosed},
            "limit": f"|V_mesh - V_surface| <= 2 eps A = {volume_bound:.3e} m^3 ({volume_bound / enclosed:.1%} of V) at every level",
        },
        "converged": {
            "passed": all(lv["converged"] for lv in levels) and all(r.report.converged for r in path)
            and final.actuations[0] == TARGET_ALPHA,
            "value": {"gravity": [lv["newton_iterations"] for lv in levels], "cable": [r.report.iterations for r in path]},
            "limit": f"every Newton solve converged, final alpha = {TARGET_ALPHA}",
        },
        "tip_deflection_converges": {
            "passed": bool(changes[1] > 0 and shrink > MIN_SHRINK),
            "value": {"tip_uz": u.tolist(), "changes": changes.tolist(), "shrink": shrink, "order": order,
                      "relative_change_last": float(changes[1] / abs(u[-1])), "extrapolated": extrapolated},
            "limit": f"|u3 - u2| < |u2 - u1| / {MIN_SHRINK}",
        },
        "gravity_force_balance": {
            "passed": all(lv["force_balance_error"] < BALANCE_TOLERANCE for lv in levels),
            "value": max(lv["force_balance_error"] for lv in levels),
            "limit": f"|sum R + W| / |W| < {BALANCE_TOLERANCE:g} at every level",
        },
        "cable_anchor_balance": {
            "passed": force_error < BALANCE_TOLERANCE and moment_error < BALANCE_TOLERANCE and pull_error < 1e-12,
            "value": {"force": force_error, "moment": moment_error, "anchor_tension": float(tensions[0]),
                      "anchor_reaction": pull.tolist(), "anchor_reaction_vs_T0_e0": pull_error,
                      "reaction_sum": final.reactions.sum(axis=0).tolist()},
            "limit": f"|sum R + W + A| / (|W| + T0) < {BALANCE_TOLERANCE:g}, same for moments / L; "
                     "A = result.anchor_reactions[0] = T0 e0 (anchored segment) to 1e-12",
        },
        "cable_embedded": {
            "passed": placements[0] == "anchor" and all(k == "embedded" for k in placements[1:]),
            "value": {kind: placements.count(kind) for kind in sorted(set(placements))},
            "limit": "first point the anchor, every other point inside a tetrahedron",
        },
        "cable_lifts_tip": {
            "passed": bool(u_tip[2] - u[-1] > MIN_LIFT * LENGTH and np.all(tensions > 0)),
            "value": {"tip_uz": float(u_tip[2]), "gravity_only_tip_uz": float(u[-1]), "min_tension": float(tensions.min())},
            "limit": f"u_z(tip) - u_z(tip, gravity only) > {MIN_LIFT} L, all tensions > 0",
        },
    }

    t = time.perf_counter()
    sf.io.write_mesh(out / "mesh.vtu", mesh)
    sf.io.write_result(out / "result.vtu", final)
    sf.cables.write_cables(out / "cables.vtu", final)
    sf.plot.plot_rest_and_deformed(
        final, out / "shape.png",
        title=f"finger from an STL, {mesh.n_tets} tets, cable at alpha = {TARGET_ALPHA}: tip u_z = {u_tip[2] * 1e3:+.1f} mm",
    )
    plot_convergence(levels, extrapolated, out / "convergence.png")
    timings["write"] = time.perf_counter() - t
    timings["total"] = time.perf_counter() - t0

    summary = {
        "example": "10_surface_to_robot",
        "quick": quick,
        "surface": {"file": stl.name, "n_points": int(len(surf_points)), "n_triangles": int(len(surf_triangles)),
                    "volume": enclosed, "frustum_volume": frustum, "area": area, "diagonal": diagonal,
                    "envelope": ENVELOPE, "volume_bound": volume_bound},
        "material": material.to_dict(),
        "formulation": "mixed",
        "levels": levels,
        "extrapolated_tip_uz": extrapolated,
        "cable": cable.to_dict() | {"actuation": TARGET_ALPHA},
        "placements": placements,
        "path": [{"alpha": r.actuations[0], "iterations": r.report.iterations, "max_tension": float(r.cable_tensions[0].max())}
                 for r in path],
        "tip_displacement": u_tip.tolist(),
        "tensions": tensions.tolist(),
        "min_J": float(final.J.min()),
        "checks": checks,
        "passed": all(c["passed"] for c in checks.values()),
        "files": ["finger.stl", "mesh.vtu", "result.vtu", "cables.vtu", "shape.png", "convergence.png", "summary.json"],
        "timings": timings,
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    return summary


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("results/surface_to_robot"), metavar="DIR")
    parser.add_argument("--quick", action="store_true", help="meshes of 12, 6, 3 mm instead of 8, 4, 2 mm")
    args = parser.parse_args(argv)
    try:
        sf.meshing.require_mesher()
    except ImportError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    try:
        summary = run(args.out, quick=args.quick)
    except sf.ConvergenceError as exc:
        print(f"error: the solver did not converge: {exc}", file=sys.stderr)
        return 3
    s = summary["surface"]
    print(f"surface: {s['n_triangles']} triangles, V = {s['volume'] * 1e6:.4f} cm^3 (divergence theorem), "
          f"{s['frustum_volume'] * 1e6:.4f} cm^3 (frustum formula), A = {s['area'] * 1e4:.3f} cm^2")
    for lv in summary["levels"]:
        print(f"h = {lv['edge_length'] * 1e3:4.1f} mm: {lv['n_nodes']:5d} nodes, {lv['n_tets']:6d} tets, "
              f"V_mesh / V_surface - 1 = {lv['volume_error'] / s['volume']:+.2e}, tip u_z = {lv['tip_uz'] * 1e3:8.3f} mm "
              f"({lv['newton_iterations']} Newton iterations; mesh {lv['timings']['mesh']:.1f} s, solve {lv['timings']['solve']:.1f} s)")
    conv = summary["checks"]["tip_deflection_converges"]["value"]
    print(f"tip deflection changes {np.round(np.array(conv['changes']) * 1e3, 3).tolist()} mm (shrink x{conv['shrink']:.2f}, "
          f"order {conv['order']:.2f}); Richardson extrapolation {summary['extrapolated_tip_uz'] * 1e3:.3f} mm")
    last = summary["path"][-1]
    print(f"cable at alpha = {last['alpha']:.2f}: tip u = {np.round(np.array(summary['tip_displacement']) * 1e3, 2).tolist()} mm, "
          f"tensions {min(summary['tensions']):.2f} .. {max(summary['tensions']):.2f} N")
    for name, check in summary["checks"].items():
        print(f"[{'ok' if check['passed'] else 'FAILED'}] {name}: {check['limit']}")
    print(f"{'all checks passed' if summary['passed'] else 'SOME CHECKS FAILED'}; wrote {', '.join(summary['files'])} "
          f"to {args.out} in {summary['timings']['total']:.1f} s")
    return 0 if summary["passed"] else 1


if __name__ == "__main__":
    sys.exit(main())
