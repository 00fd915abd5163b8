"""The peer: the same static cantilevers in scikit-fem (benchmarks/peers/skfem_neohookean.py),
and the section comparing the two codes on identical meshes."""

from __future__ import annotations

from functools import partial
from pathlib import Path

import numpy as np

from harness import TABLES, Column, Row, Table, case, col, fmt, load_array, mib, phase, save_array, section, status

from .common import GRAVITY, MATERIAL, TOLERANCE, cantilever_name, tip_deflection

COMPARISON_TITLE = "sorofem vs scikit-fem on identical meshes"

TABLES["peer"] = Table(
    "scikit-fem peer (benchmarks/peers/skfem_neohookean.py)",
    "The same discrete problem in scikit-fem (P1 tets, same energy, same mesh arrays, same stopping rule) "
    "with plain Newton as in scikit-fem's hyperelasticity example and SciPy's sparse direct solver. "
    "It tries 1, 2, 4, ... load steps until Newton converges; time = the converging run "
    "(mesh and basis construction included), the failed tries listed separately.",
    (
        col("case", "case", str),
        col("tets", "tets"),
        col("free DOFs", "dofs"),
        Column("conv.", status),
        col("load steps", "load_steps"),
        col("Newton it.", "iterations"),
        col("time [s]", "seconds"),
        col("incl. failed tries [s]", "seconds_all_attempts"),
        Column("assembly [ms]", phase("assembly")),
        Column("solve [ms]", phase("solve")),
        col("w_tip [m]", "tip_deflection", lambda x: fmt(x, 6)),
        Column("peak RSS [MiB]", mib),
    ),
)


def skfem_cantilever(length: float, cells: tuple[int, int, int]) -> Row:
    """The static cantilever solved by scikit-fem on sorofem's mesh (the peer's own box_mesh
    helper is checked against it)."""
    import sorofem as sf
    from peers.skfem_neohookean import box_mesh, solve_with_load_steps

    mesh = sf.Mesh.box(size=(length, 0.1, 0.1), cells=cells)
    points, tets, source = np.asarray(mesh.points), np.asarray(mesh.tets), "sorofem.Mesh.box"
    helper_points, helper_tets = box_mesh((length, 0.1, 0.1), cells)
    helper_matches = bool(np.array_equal(helper_tets, tets) and np.allclose(helper_points, points, rtol=0, atol=1e-15))
    fixed = np.flatnonzero(np.abs(points[:, 0]) <= 1e-9)
    result = solve_with_load_steps(
        points, tets, fixed, MATERIAL["youngs_modulus"], MATERIAL["poisson_ratio"], MATERIAL["density"],
        GRAVITY, tol=TOLERANCE,
    )
    save_array("displacement", result["displacement"])
    tries = ", ".join(f"{steps} ({'converged' if ok else 'failed'} after {it} it., {fmt(sec)} s)"
                      for steps, ok, it, sec in result["attempts"])
    note = f"load steps tried: {tries}; mesh from {source}"
    if not helper_matches:
        note += "; **the peer's box_mesh helper differs from sorofem.Mesh.box**"
    return {
        "note": note,
        "tets": len(tets),
        "nodes": len(points),
        "dofs": 3 * (len(points) - fixed.size),
        "mesh_source": source,
        "helper_mesh_matches_core": helper_matches,
        "converged": result["converged"],
        "iterations": result["newton_iterations"],
        "load_steps": result["load_steps"],
        "attempts": result["attempts"],
        "seconds": result["seconds"],
        "seconds_all_attempts": result["seconds_all_attempts"],
        "timings": result["timings"],
        "residual_history": result["residual_history"],
        "failure": result["failure"],
        "tip_deflection": tip_deflection(points, result["displacement"], length),
    }


# (length m, cells, quick, last). The 1 m 48x8x8 peer needs 128 load steps of plain Newton
# (~15 minutes): it runs after every other case and never with --quick.
PEER_CANTILEVERS = [(0.4, (8, 2, 2), True, False), (1.0, (16, 4, 4), True, False), (1.0, (48, 8, 8), False, True)]
for _length, _cells, _quick, _last in PEER_CANTILEVERS:
    case(cantilever_name("skfem", _length, _cells), "peer", _quick, _last)(partial(skfem_cantilever, _length, _cells))



def speedup(rows: dict[str, Row], peer_name: str) -> float | None:
    """Time of the peer case ``peer_name`` over the time of sorofem's case on the same mesh."""
    peer, ours = rows.get(peer_name), rows.get(_ours(peer_name))
    if peer is None or ours is None or peer.get("error") or ours.get("error") or not ours.get("seconds"):
        return None
    return peer["seconds"] / ours["seconds"]


def _ours(peer_name: str) -> str:
    return "sorofem/" + peer_name.split("/", 1)[1]


@section(COMPARISON_TITLE)
def comparison(rows: dict[str, Row], array_dir: Path) -> str:
    """sorofem vs scikit-fem on the same meshes: speed ratio and agreement of the solutions."""
    out = [
        "| mesh | tets | sorofem it. | sorofem [s] | skfem it. (load steps) | skfem [s] | skfem / sorofem "
        "| incl. failed tries | w_tip sorofem [m] | w_tip skfem [m] | rel. diff w_tip | max abs(du) / max abs(u) |",
        "|" + "---|" * 12,
    ]
    for name, peer in rows.items():
        if not name.startswith("skfem/"):
            continue
        ours = rows.get(_ours(name))
        if ours is None or peer.get("error") or ours.get("error"):
            continue
        ratio = speedup(rows, name)
        speedup_all = peer["seconds_all_attempts"] / ours["seconds"] if ours.get("seconds") else None
        w_a, w_b = ours.get("tip_deflection"), peer.get("tip_deflection")
        rel_w = abs(w_a - w_b) / abs(w_a) if w_a and w_b is not None else None
        u_a = load_array(_ours(name), "displacement", array_dir)
        u_b = load_array(name, "displacement", array_dir)
        rel_u = None
        if u_a is not None and u_b is not None and u_a.shape == u_b.shape:
            rel_u = float(np.abs(u_a - u_b).max() / np.abs(u_a).max())
        elif peer.get("reused") and ours.get("reused"):
            rel_u = peer.get("rel_diff_u")  # both rows from one earlier run (run.py --reuse)
        peer["speedup"], ours["speedup_vs_skfem"] = ratio, ratio  # for --json
        peer["rel_diff_tip"], peer["rel_diff_u"] = rel_w, rel_u
        out.append(
            f"| {name.split('/', 1)[1]} | {ours['tets']} | {ours['iterations']} | {fmt(ours['seconds'])} "
            f"| {peer['iterations']} ({peer['load_steps']}) | {fmt(peer['seconds'])} | **{fmt(ratio)}x** "
            f"| {fmt(speedup_all)}x | {fmt(w_a, 8)} | {fmt(w_b, 8)} | {fmt(rel_w, 2)} | {fmt(rel_u, 2)} |"
        )
    if len(out) == 2:
        return "No pair of sorofem and scikit-fem cases ran.\n"
    return "\n".join(out) + "\n"
