"""Contact: the 0.4 m cantilever sagging onto a floor below its tip, against the same solve
without the floor; the paired runner and columns other contact families share."""

from __future__ import annotations

import time
from typing import Callable

from harness import TABLES, Column, Row, Table, case, col, fmt, mib, ms, ratio, status

from .common import GRAVITY, MATERIAL, TOLERANCE

FLOOR = -0.12  # m: the tip would sag to about -0.13 m without it


def paired_columns(*extra: Column) -> tuple[Column, ...]:
    """The columns of a with / without contact pair (:func:`paired`), ``extra`` before the repeats."""
    return (
        col("case", "case", str),
        col("tets", "tets"),
        Column("conv.", status),
        Column("Newton it. with / without", lambda r: f"{fmt(r.get('iterations'))} / {fmt(r.get('iterations_without'))}"),
        Column("time with / without [s]", lambda r: f"{fmt(r.get('seconds'))} / {fmt(r.get('seconds_without'))}"),
        Column("time ratio", lambda r: fmt(ratio(r.get("seconds"), r.get("seconds_without")))),
        Column("t/it ratio", lambda r: fmt(ratio(r.get("seconds_per_iteration"),
                                                  r.get("seconds_per_iteration_without")))),
        Column("contact pass [ms]", lambda r: ms((r.get("timings") or {}).get("contact"))),
        Column("share", lambda r: fmt(ratio((r.get("timings") or {}).get("contact"),
                                            (r.get("timings") or {}).get("total")))),
        Column("CCD [ms]", lambda r: ms((r.get("timings") or {}).get("step_bound"))),
        col("active contacts", "active_contacts"),
        *extra,
        col("repeats", "repeats"),
        Column("peak RSS [MiB]", mib),
    )


TABLES["contact"] = Table(
    "Contact (sorofem)",
    "The 0.4 m cantilever of the static table (0.1 x 0.1 m, clamped at x = 0, gravity (0, 0, -9.81), "
    "E = 66 kPa, nu = 0.45, rho = 1080 kg/m^3, one load step, tolerance 1e-8) above a frictionless floor "
    "z = -0.12 m (sf.Plane) that stops its tip, against the same solve without the floor; both run in the "
    "same process, alternating, so that they see the same machine load. Times = `Body`, `fix`, "
    "`add_obstacle` and `solve_static`, medians. t/it = the solver's own Newton time (report total) / "
    "Newton iterations. contact pass = the solver's `timings['contact']` (broad phase, barrier and its "
    "derivatives, their scatter into the free DOFs, the collision-bounded step), share = contact pass / "
    "report total; CCD = `timings['step_bound']` (continuous collision detection of the line search).",
    paired_columns(col("floor force [N]", "floor_force")),
)


def _solve(cells: tuple[int, int, int], floor: bool) -> Row:
    import sorofem as sf

    mesh = sf.Mesh.box(size=(0.4, 0.1, 0.1), cells=cells)
    body = sf.Body(mesh, sf.NeoHookean(**MATERIAL))
    body.fix(mesh.nodes_on_plane((0.0, 0.0, 0.0), (1.0, 0.0, 0.0)))
    if floor:
        body.add_obstacle(sf.Plane(point=(0.0, 0.0, FLOOR), normal=(0.0, 0.0, 1.0)))
    try:
        result = sf.solve_static(body, gravity=GRAVITY, tolerance=TOLERANCE, load_steps=1)
    except sf.ConvergenceError as err:
        return {"converged": False, "failure": str(err), "tets": mesh.n_tets}
    report = result.report
    row: Row = {"converged": bool(report.converged), "iterations": report.iterations,
                "timings": dict(report.timings), "tets": mesh.n_tets}
    if floor:
        row["active_contacts"] = result.active_contacts
        row["floor_force"] = float(result.obstacle_forces[0][2])
    return row


def paired(solve: Callable[[bool], Row], budget_s: float, api: str) -> Row:
    """``solve(True)`` (with contact) and ``solve(False)`` (without) alternating in this process,
    up to 7 pairs within ``budget_s``; the row of the median run of each, side by side (the
    ``_without`` keys: the run without contact)."""
    times: dict[bool, list[float]] = {True: [], False: []}
    results: dict[bool, list[Row]] = {True: [], False: []}
    start = time.perf_counter()
    while len(times[True]) < 7 and (not times[True] or time.perf_counter() - start < budget_s):
        for on in (True, False):
            t0 = time.perf_counter()
            results[on].append(solve(on))
            times[on].append(time.perf_counter() - t0)

    def median(on: bool) -> tuple[float, Row]:
        ts = times[on]
        i = sorted(range(len(ts)), key=ts.__getitem__)[(len(ts) - 1) // 2]
        return ts[i], results[on][i]

    def per_iteration(res: Row) -> float | None:
        total = (res.get("timings") or {}).get("total")
        return total / res["iterations"] if total and res.get("iterations") else None

    (sec, res), (sec0, res0) = median(True), median(False)
    row: Row = {
        "api": api,
        "tets": res["tets"], "converged": res["converged"] and res0["converged"],
        "iterations": res.get("iterations"), "iterations_without": res0.get("iterations"),
        "seconds": sec, "seconds_without": sec0, "seconds_first": times[True][0],
        "all_seconds": times[True], "all_seconds_without": times[False], "repeats": len(times[True]),
        "timings": res.get("timings"), "timings_without": res0.get("timings"),
        "seconds_per_iteration": per_iteration(res), "seconds_per_iteration_without": per_iteration(res0),
        **{key: value for key, value in res.items() if key not in ("converged", "iterations", "timings", "tets")},
    }
    if res.get("failure") or res0.get("failure"):
        row["failure"] = res.get("failure") or res0.get("failure")
    return row


def _paired(cells: tuple[int, int, int], budget_s: float) -> Row:
    return paired(lambda floor: _solve(cells, floor), budget_s, "sorofem.Plane / Body.add_obstacle / solve_static")


@case("sorofem/contact-cantilever-on-plane-16x4x4", "contact", quick=True)
def contact_cantilever_small() -> Row:
    return _paired((16, 4, 4), budget_s=4.0)


@case("sorofem/contact-cantilever-on-plane-32x8x8", "contact")
def contact_cantilever() -> Row:
    return _paired((32, 8, 8), budget_s=8.0)
