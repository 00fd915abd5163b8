"""Benchmarks behind `make bench`: run every case in a fresh process and write BENCHMARKS.md.

    python benchmarks/run.py --write BENCHMARKS.md            # all cases
    python benchmarks/run.py --write BENCHMARKS.md --quick    # small cases only
    python benchmarks/run.py --list
    python benchmarks/run.py --only 'sorofem/cantilever-0.4m-*'

Each case is one function registered with :func:`case`; it runs in a child process of its own
(``run.py --child NAME``), so its peak memory is that child's ``ru_maxrss`` (taken by the parent
with ``os.wait4``) and no case warms the caches of the next. A case returns a JSON-able row and
may save arrays (``save_array``) that report sections compare across cases, e.g. sorofem's and
scikit-fem's displacements on the same mesh.

Adding a benchmark for a later issue is: one case function, registered under a table (add a
``Table`` if it needs new columns), and, if it has a target, one line in ``targets()``.
"""

from __future__ import annotations

import argparse
import datetime as dt
import fnmatch
import json
import math
import os
import platform
import re
import shlex
import statistics
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any, Callable

import numpy as np

BENCH_DIR = Path(__file__).resolve().parent
REPO = BENCH_DIR.parent
SOLIDFEM_DATA = REPO.parent / "shared" / "data" / "solidfem"
CASE_TIMEOUT_S = 3600.0

# ---------------------------------------------------------------------------
# Registry


@dataclass(frozen=True)
class Column:
    header: str
    format: Callable[[dict[str, Any]], str]


@dataclass(frozen=True)
class Table:
    title: str
    description: str
    columns: tuple[Column, ...]


@dataclass(frozen=True)
class Case:
    name: str
    table: str
    run: Callable[[], dict[str, Any]]
    quick: bool


TABLES: dict[str, Table] = {}
CASES: dict[str, Case] = {}


def case(name: str, table: str, quick: bool = False) -> Callable[[Callable[[], dict[str, Any]]], Callable]:
    """Register ``func`` (no arguments, returns a JSON-able row) as the benchmark ``name``."""

    def register(func: Callable[[], dict[str, Any]]) -> Callable:
        if name in CASES:
            raise ValueError(f"benchmark case {name!r} registered twice")
        if table not in TABLES:
            raise ValueError(f"benchmark case {name!r}: unknown table {table!r}")
        CASES[name] = Case(name, table, func, quick)
        return func

    return register


# ---------------------------------------------------------------------------
# Helpers for case functions (they run in the child process)

_ARRAY_DIR: Path | None = None


def save_array(key: str, value: np.ndarray) -> None:
    """Keep an array of the current case for cross-case comparisons (``load_array``)."""
    if _ARRAY_DIR is not None:
        np.save(_ARRAY_DIR / f"{_safe(_CURRENT_CASE)}--{key}.npy", np.asarray(value))


def load_array(case_name: str, key: str, array_dir: Path) -> np.ndarray | None:
    path = array_dir / f"{_safe(case_name)}--{key}.npy"
    return np.load(path) if path.exists() else None


_CURRENT_CASE = ""


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name)


def repeat_timed(fn: Callable[[], Any], budget_s: float = 2.0, max_repeats: int = 7) -> dict[str, Any]:
    """Call ``fn`` once, then again while the time spent is under ``budget_s``.

    Returns the wall times, the first (cold) one, the median and the result of the median run.
    """
    times: list[float] = []
    results: list[Any] = []
    spent = 0.0
    while len(times) < max_repeats and (not times or spent + times[-1] < budget_s):
        t0 = time.perf_counter()
        results.append(fn())
        times.append(time.perf_counter() - t0)
        spent += times[-1]
    order = sorted(range(len(times)), key=times.__getitem__)
    mid = order[(len(order) - 1) // 2]
    return {"times": times, "first": times[0], "median": times[mid], "result": results[mid]}


def box_points_tets(size: tuple[float, float, float], cells: tuple[int, int, int]) -> tuple[np.ndarray, np.ndarray, str]:
    """Points and tets of the box mesh: sorofem's own when the extension is built, else the peer's copy."""
    try:
        import sorofem as sf

        mesh = sf.Mesh.box(size=size, cells=cells)
        return np.asarray(mesh.points), np.asarray(mesh.tets), "sorofem.Mesh.box"
    except ImportError:
        from peers.skfem_neohookean import box_mesh

        points, tets = box_mesh(size, cells)
        return points, tets, "peers.skfem_neohookean.box_mesh (sorofem not built)"


# ---------------------------------------------------------------------------
# Formatting


def _g(x: Any, digits: int = 3) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "-"
    if isinstance(x, (int, np.integer)):
        return str(x)
    x = float(x)
    if x == 0:
        return "0"
    if abs(x) >= 10 ** digits or abs(x) < 1e-3:
        return f"{x:.{digits - 1}e}"
    return f"{x:.{digits}g}"


def _ms(x: Any) -> str:
    return "-" if x is None else f"{1e3 * float(x):.3g}"


def _col(header: str, key: str, fmt: Callable[[Any], str] = _g) -> Column:
    return Column(header, lambda r: fmt(r.get(key)))


def _phase(key: str) -> Callable[[dict[str, Any]], str]:
    return lambda r: _ms((r.get("timings") or {}).get(key))


def _status(r: dict[str, Any]) -> str:
    if r.get("error"):
        return "ERROR"
    return "yes" if r.get("converged") else "**no**"


def _mib(r: dict[str, Any]) -> str:
    return _g(r.get("peak_rss_mib"), 4)


def _per_iteration_ratio(r: dict[str, Any]) -> float | None:
    """(time per Newton iteration) / (numeric factorisation time per iteration) = total / factorisation."""
    t = r.get("timings") or {}
    if not t.get("factorization"):
        return None
    return t["total"] / t["factorization"]


# ---------------------------------------------------------------------------
# Tables and cases: issue 2 (static Neo-Hookean solves)

MATERIAL = dict(youngs_modulus=66e3, poisson_ratio=0.45, density=1080.0)
GRAVITY = (0.0, 0.0, -9.81)
TOLERANCE = 1e-8

TABLES["static"] = Table(
    "Static solves (sorofem)",
    "Cantilever b x h = 0.1 x 0.1 m clamped at x = 0 under gravity (0, 0, -9.81) m/s^2, Neo-Hookean "
    "E = 66 kPa, nu = 0.45, rho = 1080 kg/m^3, one load step, tolerance 1e-8 on "
    "||r_free|| / ||f_ext_free||. Time = wall time of `Body(...)`, `fix` and `solve_static` (building "
    "the model, i.e. the symbolic analysis, included), median of the repeats; phases are the solver's "
    "own `report.timings` of that run, in ms. t/it / fact/it = time per Newton iteration over numeric "
    "factorisation time per iteration. w_tip = mean z-displacement of the x = L face.",
    (
        _col("case", "case", str),
        _col("tets", "tets"),
        _col("free DOFs", "dofs"),
        Column("conv.", _status),
        _col("Newton it.", "iterations"),
        _col("time [s]", "seconds"),
        _col("first run [s]", "seconds_first"),
        _col("repeats", "repeats"),
        Column("assembly [ms]", _phase("assembly")),
        Column("factor. [ms]", _phase("factorization")),
        Column("solve [ms]", _phase("solve")),
        Column("line search [ms]", _phase("line_search")),
        Column("report total [ms]", _phase("total")),
        Column("t/it / fact/it", lambda r: _g(_per_iteration_ratio(r))),
        _col("w_tip [m]", "tip_deflection", lambda x: _g(x, 6)),
        Column("peak RSS [MiB]", _mib),
    ),
)

TABLES["robot"] = Table(
    "Hammerbot (sorofem)",
    "`hammerbot_fine.tet` (shared/data/solidfem) read with scale 0.01, fixed on its 92 nodes at x = -5 cm "
    "(checked against hammerbot.xml), E = 100 kPa, nu = 0.4, rho = 1070 kg/m^3, gravity (0, -9.8, 0) "
    "in the file's own axes, one load step, tolerance 1e-8. Tip = the nodes of the x = +5 cm face.",
    (
        _col("case", "case", str),
        _col("tets", "tets"),
        _col("free DOFs", "dofs"),
        Column("conv.", _status),
        _col("Newton it.", "iterations"),
        _col("time [s]", "seconds"),
        _col("first run [s]", "seconds_first"),
        Column("factor. [ms]", _phase("factorization")),
        Column("report total [ms]", _phase("total")),
        Column("tip u (mean) [mm]", lambda r: "-" if r.get("tip_displacement") is None
               else "(" + ", ".join(f"{1e3 * c:.3f}" for c in r["tip_displacement"]) + ")"),
        _col("max abs(u) [mm]", "max_displacement_mm", lambda x: _g(x, 4)),
        Column("peak RSS [MiB]", _mib),
    ),
)

TABLES["peer"] = Table(
    "scikit-fem peer (benchmarks/peers/skfem_neohookean.py)",
    "The same discrete problem in scikit-fem (P1 tets, same energy, same mesh arrays, same stopping rule) "
    "with plain Newton as in scikit-fem's hyperelasticity example and SciPy's sparse direct solver. "
    "It tries 1, 2, 4, ... load steps until Newton converges; time = the converging run "
    "(mesh and basis construction included), the failed tries listed separately.",
    (
        _col("case", "case", str),
        _col("tets", "tets"),
        _col("free DOFs", "dofs"),
        Column("conv.", _status),
        _col("load steps", "load_steps"),
        _col("Newton it.", "iterations"),
        _col("time [s]", "seconds"),
        _col("incl. failed tries [s]", "seconds_all_attempts"),
        Column("assembly [ms]", _phase("assembly")),
        Column("solve [ms]", _phase("solve")),
        _col("w_tip [m]", "tip_deflection", lambda x: _g(x, 6)),
        Column("peak RSS [MiB]", _mib),
    ),
)


def _cantilever_name(solver: str, length: float, cells: tuple[int, int, int]) -> str:
    return f"{solver}/cantilever-{length:g}m-{'x'.join(map(str, cells))}"


def _tip_deflection(points: np.ndarray, displacement: np.ndarray, length: float) -> float:
    tip = np.abs(points[:, 0] - length) < 1e-9 * max(1.0, length)
    return float(displacement[tip, 2].mean())


def sorofem_cantilever(length: float, cells: tuple[int, int, int]) -> dict[str, Any]:
    import sorofem as sf

    mesh = sf.Mesh.box(size=(length, 0.1, 0.1), cells=cells)
    material = sf.NeoHookean(**MATERIAL)

    def run() -> Any:
        body = sf.Body(mesh, material)
        body.fix(mesh.nodes_in_box(min=(-1e-9, -1, -1), max=(1e-9, 1, 1)))
        try:
            return body, sf.solve_static(body, gravity=GRAVITY, tolerance=TOLERANCE, load_steps=1)
        except sf.ConvergenceError as err:
            return body, err

    timed = repeat_timed(run, budget_s=2.0 if mesh.n_tets < 50_000 else 0.0)
    body, result = timed["result"]
    row = _sorofem_row(mesh, body, result, timed)
    if not isinstance(result, Exception):
        row["tip_deflection"] = _tip_deflection(mesh.points, result.displacement, length)
        save_array("displacement", result.displacement)
    return row


def _sorofem_row(mesh: Any, body: Any, result: Any, timed: dict[str, Any]) -> dict[str, Any]:
    report = result.report
    row = {
        "tets": mesh.n_tets,
        "nodes": mesh.n_nodes,
        "dofs": 3 * (mesh.n_nodes - body.fixed_nodes.size),
        "converged": bool(report.converged) and not isinstance(result, Exception),
        "iterations": report.iterations,
        "load_steps": report.load_steps,
        "cutbacks": report.cutbacks,
        "projected_steps": report.projected_steps,
        "residual_history": report.residual_history,
        "timings": dict(report.timings),
        "seconds": timed["median"],
        "seconds_first": timed["first"],
        "repeats": len(timed["times"]),
        "all_seconds": timed["times"],
    }
    if isinstance(result, Exception):
        row["failure"] = str(result)
    return row


STATIC_CANTILEVERS = [
    # (length m, cells, quick): 6 nx ny nz tets ~ 200, 1.5k, 12k, 100k for 0.4 m
    (0.4, (8, 2, 2), True),
    (0.4, (16, 4, 4), True),
    (0.4, (32, 8, 8), False),
    (0.4, (64, 16, 16), False),
    (1.0, (8, 2, 2), True),
    (1.0, (16, 4, 4), True),
    (1.0, (48, 8, 8), False),
]
for _length, _cells, _quick in STATIC_CANTILEVERS:
    case(_cantilever_name("sorofem", _length, _cells), "static", _quick)(
        partial(sorofem_cantilever, _length, _cells)
    )


HAMMERBOT_FIXED_COUNT = 92


@case("sorofem/hammerbot", "robot", quick=True)
def sorofem_hammerbot() -> dict[str, Any]:
    import sorofem as sf

    mesh = sf.Mesh.read(SOLIDFEM_DATA / "hammerbot_fine.tet", scale=0.01)
    fixed = mesh.nodes_in_box(min=(-0.05 - 1e-6, -1, -1), max=(-0.05 + 1e-6, 1, 1))
    assert fixed.size == HAMMERBOT_FIXED_COUNT, f"expected {HAMMERBOT_FIXED_COUNT} nodes at x = -5 cm, found {fixed.size}"
    dirichlet = ET.parse(SOLIDFEM_DATA / "hammerbot.xml").getroot().find("model/dirichlet")
    listed = np.array(sorted(int(i) for i in dirichlet.text.split()))
    assert np.array_equal(fixed, listed), "the x = -5 cm nodes differ from hammerbot.xml's <dirichlet> list"
    material = sf.NeoHookean(youngs_modulus=100e3, poisson_ratio=0.4, density=1070.0)

    def run() -> Any:
        body = sf.Body(mesh, material)
        body.fix(fixed)
        try:
            return body, sf.solve_static(body, gravity=(0.0, -9.8, 0.0), tolerance=TOLERANCE, load_steps=1)
        except sf.ConvergenceError as err:
            return body, err

    timed = repeat_timed(run, budget_s=3.0)
    body, result = timed["result"]
    row = _sorofem_row(mesh, body, result, timed)
    if not isinstance(result, Exception):
        tip = np.abs(mesh.points[:, 0] - mesh.points[:, 0].max()) < 1e-9
        row["tip_nodes"] = int(tip.sum())
        row["tip_displacement"] = result.displacement[tip].mean(axis=0).tolist()
        row["max_displacement_mm"] = 1e3 * result.max_displacement
    return row


def skfem_cantilever(length: float, cells: tuple[int, int, int]) -> dict[str, Any]:
    from peers.skfem_neohookean import solve_with_load_steps

    from peers.skfem_neohookean import box_mesh

    points, tets, source = box_points_tets((length, 0.1, 0.1), cells)
    helper_points, helper_tets = box_mesh((length, 0.1, 0.1), cells)
    helper_matches = bool(np.array_equal(helper_tets, tets) and np.allclose(helper_points, points, rtol=0, atol=1e-15))
    fixed = np.flatnonzero(np.abs(points[:, 0]) <= 1e-9)
    result = solve_with_load_steps(
        points, tets, fixed, MATERIAL["youngs_modulus"], MATERIAL["poisson_ratio"], MATERIAL["density"],
        GRAVITY, tol=TOLERANCE,
    )
    save_array("displacement", result["displacement"])
    tries = ", ".join(f"{steps} ({'converged' if ok else 'failed'} after {it} it., {_g(sec)} s)"
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
        "tip_deflection": _tip_deflection(points, result["displacement"], length),
    }


PEER_CANTILEVERS = [(0.4, (8, 2, 2), True), (1.0, (16, 4, 4), True), (1.0, (48, 8, 8), False)]
for _length, _cells, _quick in PEER_CANTILEVERS:
    case(_cantilever_name("skfem", _length, _cells), "peer", _quick)(partial(skfem_cantilever, _length, _cells))


# ---------------------------------------------------------------------------
# Sections computed from all rows


def comparison(rows: dict[str, dict[str, Any]], array_dir: Path) -> str:
    """sorofem vs scikit-fem on the same meshes: speed ratio and agreement of the solutions."""
    out = [
        "| mesh | tets | sorofem it. | sorofem [s] | skfem it. (load steps) | skfem [s] | skfem / sorofem "
        "| incl. failed tries | w_tip sorofem [m] | w_tip skfem [m] | rel. diff w_tip | max abs(du) / max abs(u) |",
        "|" + "---|" * 12,
    ]
    for name, peer in rows.items():
        if not name.startswith("skfem/"):
            continue
        ours = rows.get("sorofem/" + name.split("/", 1)[1])
        if ours is None or peer.get("error") or ours.get("error"):
            continue
        speedup = peer["seconds"] / ours["seconds"] if ours.get("seconds") else None
        speedup_all = peer["seconds_all_attempts"] / ours["seconds"] if ours.get("seconds") else None
        w_a, w_b = ours.get("tip_deflection"), peer.get("tip_deflection")
        rel_w = abs(w_a - w_b) / abs(w_a) if w_a and w_b is not None else None
        u_a = load_array("sorofem/" + name.split("/", 1)[1], "displacement", array_dir)
        u_b = load_array(name, "displacement", array_dir)
        rel_u = None
        if u_a is not None and u_b is not None and u_a.shape == u_b.shape:
            rel_u = float(np.abs(u_a - u_b).max() / np.abs(u_a).max())
        peer["speedup"], ours["speedup_vs_skfem"] = speedup, speedup
        peer["rel_diff_tip"], peer["rel_diff_u"] = rel_w, rel_u
        out.append(
            f"| {name.split('/', 1)[1]} | {ours['tets']} | {ours['iterations']} | {_g(ours['seconds'])} "
            f"| {peer['iterations']} ({peer['load_steps']}) | {_g(peer['seconds'])} | **{_g(speedup)}x** "
            f"| {_g(speedup_all)}x | {_g(w_a, 8)} | {_g(w_b, 8)} | {_g(rel_w, 2)} | {_g(rel_u, 2)} |"
        )
    if len(out) == 2:
        return "No pair of sorofem and scikit-fem cases ran.\n"
    return "\n".join(out) + "\n"


def targets(rows: dict[str, dict[str, Any]]) -> str:
    """Issue 2's targets against the measured numbers."""
    lines = ["| target | case | measured | limit | met |", "|---|---|---|---|---|"]

    def add(target: str, case_name: str, value: float | None, limit: float, unit: str = "") -> None:
        if value is None:
            lines.append(f"| {target} | {case_name} | not measured | {limit:g}{unit} | - |")
        else:
            ok = "yes" if value <= limit else "**NO**"
            lines.append(f"| {target} | {case_name} | {_g(value)}{unit} | {limit:g}{unit} | {ok} |")

    def ok_row(name: str) -> dict[str, Any] | None:
        r = rows.get(name)
        return r if r and not r.get("error") and r.get("converged") else None

    r = ok_row("sorofem/hammerbot")
    add("hammerbot static solve time", "sorofem/hammerbot", r and r["seconds"], 0.25, " s")
    for name, limit in [("sorofem/cantilever-0.4m-8x2x2", 12), ("sorofem/cantilever-1m-8x2x2", 25),
                        ("sorofem/cantilever-1m-16x4x4", 25), ("sorofem/cantilever-1m-48x8x8", 25)]:
        if name in rows:
            r = rows[name]
            add("Newton iterations, one load step", name, None if r.get("error") else r.get("iterations"), limit)
    for name, r in rows.items():
        if name.startswith("sorofem/") and r.get("tets", 0) >= 10_000 and not r.get("error"):
            add("time per iteration / numeric factorisation per iteration", name, _per_iteration_ratio(r), 1.3)
    for name, r in rows.items():
        if name.startswith("sorofem/") and r.get("tets", 0) >= 90_000:
            add("peak memory, ~100k tets", name, r.get("peak_rss_mib") and r["peak_rss_mib"] / 1024, 8.0, " GiB")
    for name, r in rows.items():
        if name.startswith("skfem/") and r.get("speedup"):
            # Stated as time ratio skfem / sorofem >= 50, i.e. sorofem / skfem <= 1/50.
            ratio = r["speedup"]
            ok = "yes" if ratio >= 50 else "**NO**"
            lines.append(f"| speed-up over scikit-fem | {name} | {_g(ratio)}x | >= 50x | {ok} |")
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------
# Machine and provenance


def _run_text(cmd: list[str]) -> str:
    try:
        return subprocess.run(cmd, capture_output=True, text=True, cwd=REPO, timeout=30).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return ""


def machine() -> dict[str, str]:
    cpu = "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    ram = "unknown"
    try:
        kib = int(re.search(r"MemTotal:\s+(\d+)", Path("/proc/meminfo").read_text()).group(1))
        ram = f"{kib / 1024**2:.1f} GiB"
    except (OSError, AttributeError):
        pass
    os_name = platform.platform()
    try:
        pretty = re.search(r'PRETTY_NAME="([^"]+)"', Path("/etc/os-release").read_text())
        if pretty:
            os_name = f"{pretty.group(1)} (kernel {platform.release()})"
    except OSError:
        pass
    versions = []
    for module in ("numpy", "scipy", "skfem", "sorofem"):
        try:
            versions.append(f"{module} {__import__(module).__version__}")
        except Exception:  # noqa: BLE001 - any import failure just means "not available"
            versions.append(f"{module} not importable")
    commit = _run_text(["git", "rev-parse", "--short=12", "HEAD"]) or "no commit yet"
    if _run_text(["git", "status", "--porcelain", "--untracked-files=no"]) or commit == "no commit yet":
        commit += " (with uncommitted changes)"
    return {
        "CPU": cpu,
        "cores": f"{os.cpu_count()} logical (affinity: {len(os.sched_getaffinity(0))})",
        "RAM": ram,
        "OS": os_name,
        "Python": f"{platform.python_version()} ({sys.executable})",
        "rustc": _run_text(["rustc", "--version"]) or "not found",
        "packages": ", ".join(versions),
        "date (start)": dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "git commit": commit,
        "sorofem extension": extension_stamp(),
        "load average at start (1, 5, 15 min)": ", ".join(f"{x:.2f}" for x in os.getloadavg()),
    }


def extension_stamp() -> str:
    """Path and modification time of the compiled extension, to notice a rebuild during the run."""
    try:
        import sorofem._core as core

        path = Path(core.__file__)
        when = dt.datetime.fromtimestamp(path.stat().st_mtime, dt.timezone.utc)
        return f"{path.name}, built {when:%Y-%m-%d %H:%M:%S} UTC"
    except (ImportError, OSError, AttributeError):
        return "not built"


def _command() -> str:
    exe = Path(sys.executable)
    try:
        exe = exe.relative_to(Path.cwd())
    except ValueError:
        pass
    script = Path(sys.argv[0])
    try:
        script = script.resolve().relative_to(Path.cwd())
    except ValueError:
        pass
    return shlex.join([str(exe), str(script), *sys.argv[1:]])


# ---------------------------------------------------------------------------
# Parent: run cases in children, write the report


@dataclass
class Run:
    rows: dict[str, dict[str, Any]] = field(default_factory=dict)
    array_dir: Path = Path(".")


def run_child(name: str, workdir: Path) -> dict[str, Any]:
    """Run one case in a fresh interpreter; its peak RSS comes from ``wait4``'s rusage."""
    out_json = workdir / f"{_safe(name)}.json"
    log = workdir / f"{_safe(name)}.log"
    cmd = [sys.executable, str(Path(__file__).resolve()), "--child", name, "--workdir", str(workdir)]
    start = time.perf_counter()
    with open(log, "wb") as log_file:
        proc = subprocess.Popen(cmd, stdout=log_file, stderr=subprocess.STDOUT, cwd=REPO)
        while True:
            pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
            if pid:
                break
            if time.perf_counter() - start > CASE_TIMEOUT_S:
                proc.kill()
                pid, status, usage = os.wait4(proc.pid, 0)
                break
            time.sleep(0.02)
    proc.returncode = os.waitstatus_to_exitcode(status)
    wall = time.perf_counter() - start
    row: dict[str, Any] = {}
    if out_json.exists():
        row = json.loads(out_json.read_text())
    if proc.returncode != 0 or not row:
        lines = log.read_text(errors="replace").strip().splitlines() or ["(no output)"]
        row.setdefault("error", f"child exited with {proc.returncode}: {lines[-1]} (log: {log.name})")
        row["log_tail"] = lines[-30:]
    row["case"] = name
    row["peak_rss_mib"] = usage.ru_maxrss / 1024  # KiB on Linux
    row["child_wall_s"] = wall
    return row


def child_main(name: str, workdir: Path) -> int:
    global _ARRAY_DIR, _CURRENT_CASE
    _ARRAY_DIR, _CURRENT_CASE = workdir, name
    row = CASES[name].run()
    if "sorofem" in sys.modules:
        row["extension"] = extension_stamp()
    (workdir / f"{_safe(name)}.json").write_text(json.dumps(row, default=_json_default))
    return 0


def _json_default(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def render(run: Run, info: dict[str, str], command: str, quick: bool) -> str:
    parts = [
        "# Benchmarks",
        "",
        "Written by `benchmarks/run.py`; do not edit by hand. Every case ran in a fresh Python process; "
        "peak RSS is that process's `ru_maxrss` (interpreter, numpy and the extension included).",
        "",
        f"Command: `{command}`" + (" (quick: small cases only)" if quick else ""),
        "",
        "| machine | |",
        "|---|---|",
        *(f"| {k} | {v} |" for k, v in info.items()),
        "",
    ]
    for key, table in TABLES.items():
        rows = [r for r in run.rows.values() if CASES[r["case"]].table == key]
        if not rows:
            continue
        parts += [f"## {table.title}", "", table.description, ""]
        parts.append("| " + " | ".join(c.header for c in table.columns) + " |")
        parts.append("|" + "---|" * len(table.columns))
        for r in rows:
            parts.append("| " + " | ".join(c.format(r) for c in table.columns) + " |")
        notes = [f"- {r['case']}: {r.get('error') or r.get('failure') or r.get('note')}"
                 for r in rows if r.get("error") or r.get("failure") or r.get("note")]
        parts += ["", *notes, ""] if notes else [""]
    parts += ["## sorofem vs scikit-fem on identical meshes", "", comparison(run.rows, run.array_dir)]
    parts += ["## Targets (issue 2)", "", targets(run.rows)]
    return "\n".join(parts)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--write", metavar="PATH", help="write the Markdown report here")
    parser.add_argument("--quick", action="store_true", help="small cases only")
    parser.add_argument("--only", metavar="GLOB", action="append", help="run the cases matching (repeatable)")
    parser.add_argument("--list", action="store_true", help="list the cases and exit")
    parser.add_argument("--json", metavar="PATH", help="also dump the raw rows as JSON")
    parser.add_argument("--child", metavar="CASE", help=argparse.SUPPRESS)
    parser.add_argument("--workdir", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)

    if args.child:
        return child_main(args.child, args.workdir)

    selected = [c for c in CASES.values() if (c.quick or not args.quick)]
    if args.only:
        selected = [c for c in selected if any(fnmatch.fnmatch(c.name, p) for p in args.only)]
    if args.list:
        for c in selected:
            print(f"{c.name:40s} table={c.table:8s} {'quick' if c.quick else ''}")
        return 0
    if not selected:
        print("no case selected", file=sys.stderr)
        return 2

    command = _command()
    info = machine()
    with tempfile.TemporaryDirectory(prefix="sorofem-bench-") as tmp:
        run = Run(array_dir=Path(tmp))
        for c in selected:
            print(f"[bench] {c.name} ...", end=" ", flush=True)
            row = run_child(c.name, Path(tmp))
            run.rows[c.name] = row
            if row.get("error"):
                print("ERROR:", row["error"][-400:], flush=True)
            else:
                print(
                    f"{'converged' if row.get('converged') else 'NOT converged'}, "
                    f"{row.get('iterations')} it., {_g(row.get('seconds'))} s, "
                    f"peak RSS {row['peak_rss_mib']:.0f} MiB (child {row['child_wall_s']:.1f} s)",
                    flush=True,
                )
        report = render(run, info, command, args.quick)
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    report = report.replace("\n\n## ", f"\n| load average at end (1, 5, 15 min) | {load} |\n\n## ", 1)
    # Only the rows that time sorofem itself must share one build (the peers use it for meshes only).
    builds = sorted({r["extension"] for n, r in run.rows.items() if n.startswith("sorofem/") and "extension" in r})
    if len(builds) > 1:
        warning = (f"**Warning: the extension was rebuilt during this run ({' -> '.join(builds)}); "
                   "the sorofem rows come from different builds. Run again.**")
        print("[bench]", warning, file=sys.stderr)
        report = report.replace("\n| machine | |", f"\n{warning}\n\n| machine | |", 1)
    if args.write:
        path = Path(args.write)
        tmp_path = path.with_suffix(path.suffix + ".tmp")
        tmp_path.write_text(report)
        tmp_path.replace(path)
        print(f"[bench] wrote {path}")
    else:
        print(report)
    if args.json:
        Path(args.json).write_text(json.dumps(run.rows, indent=1, default=_json_default))
    return 1 if any(r.get("error") for r in run.rows.values()) else 0


if __name__ == "__main__":
    sys.exit(main())
