"""The benchmark harness: registry, timing, child processes, machine information, the report.

Case families (``benchmarks/cases/``) register their tables with :data:`TABLES`, their cases with
:func:`case` and report sections computed from all rows with :func:`section`; ``run.py`` is the
command line. Nothing here knows a particular case.

A case runs in a child process of its own (``run.py --child NAME``), so its peak memory is that
child's ``ru_maxrss`` (taken by the parent with ``os.wait4``) and no case warms the caches of the
next. A case returns a JSON-able row and may save arrays (:func:`save_array`) that report sections
compare across cases (:func:`load_array`).
"""

from __future__ import annotations

import datetime as dt
import json
import math
import os
import platform
import re
import shlex
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

BENCH_DIR = Path(__file__).resolve().parent
REPO = BENCH_DIR.parent
RUNNER = BENCH_DIR / "run.py"
CASE_TIMEOUT_S = 3600.0

Row = dict[str, Any]

# ---------------------------------------------------------------------------
# Registry


@dataclass(frozen=True)
class Column:
    header: str
    format: Callable[[Row], str]


@dataclass(frozen=True)
class Table:
    title: str
    description: str
    columns: tuple[Column, ...]


@dataclass(frozen=True)
class Case:
    name: str
    table: str
    run: Callable[[], Row]
    quick: bool
    last: bool = False


TABLES: dict[str, Table] = {}
CASES: dict[str, Case] = {}
#: Report sections after the tables, in registration order: title -> f(rows, array_dir) -> Markdown.
SECTIONS: dict[str, Callable[[dict[str, Row], Path], str]] = {}
RUN_LOG_TITLE = "Run log"
# Titles this runner wrote in earlier versions: replaced, not kept, when the file is rewritten.
FORMER_TITLES = {"Targets (issue 2)"}


def case(name: str, table: str, quick: bool = False, last: bool = False) -> Callable[[Callable[[], Row]], Callable]:
    """Register ``func`` (no arguments, returns a JSON-able row) as the benchmark ``name``.

    ``quick``: also run by ``--quick``. ``last``: run after every other case (slow ones).
    """

    def register(func: Callable[[], Row]) -> Callable:
        if name in CASES:
            raise ValueError(f"benchmark case {name!r} registered twice")
        if table not in TABLES:
            raise ValueError(f"benchmark case {name!r}: unknown table {table!r}")
        CASES[name] = Case(name, table, func, quick, last)
        return func

    return register


def section(title: str) -> Callable[[Callable[[dict[str, Row], Path], str]], Callable]:
    """Register ``func(rows, array_dir) -> Markdown`` as the report section ``## title``."""

    def register(func: Callable[[dict[str, Row], Path], str]) -> Callable:
        if title in SECTIONS:
            raise ValueError(f"report section {title!r} registered twice")
        SECTIONS[title] = func
        return func

    return register


def in_table(name: str, table: str) -> bool:
    return name in CASES and CASES[name].table == table


# ---------------------------------------------------------------------------
# Helpers for case functions (they run in the child process)

_ARRAY_DIR: Path | None = None
_CURRENT_CASE = ""


def save_array(key: str, value: np.ndarray) -> None:
    """Keep an array of the current case for cross-case comparisons (``load_array``)."""
    if _ARRAY_DIR is not None:
        np.save(_ARRAY_DIR / f"{_safe(_CURRENT_CASE)}--{key}.npy", np.asarray(value))


def load_array(case_name: str, key: str, array_dir: Path) -> np.ndarray | None:
    path = array_dir / f"{_safe(case_name)}--{key}.npy"
    return np.load(path) if path.exists() else None


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name)


def repeat_timed(
    fn: Callable[[], Any],
    budget_s: float = 2.0,
    max_repeats: int = 7,
    after: Callable[[Any], Any] | None = None,
) -> dict[str, Any]:
    """Call ``fn`` once, then again while the time spent is under ``budget_s``.

    ``after``, when given, is called (untimed) with each run's result right after it: for
    measurements that must be paired with that run (taken under the same machine state).

    Returns the wall times, the first (cold) one, the median, the result of the median run and
    the ``after`` outputs of every run.
    """
    times: list[float] = []
    results: list[Any] = []
    afterwards: list[Any] = []
    spent = 0.0
    while len(times) < max_repeats and (not times or spent + times[-1] < budget_s):
        t0 = time.perf_counter()
        results.append(fn())
        times.append(time.perf_counter() - t0)
        spent += times[-1]
        if after is not None:
            afterwards.append(after(results[-1]))
    order = sorted(range(len(times)), key=times.__getitem__)
    mid = order[(len(order) - 1) // 2]
    return {"times": times, "first": times[0], "median": times[mid], "result": results[mid], "after": afterwards}


# ---------------------------------------------------------------------------
# Formatting of table cells


def fmt(x: Any, digits: int = 3) -> str:
    """A number with ``digits`` significant digits (scientific outside 1e-3 .. 10^digits), or "-"."""
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


def ms(x: Any) -> str:
    """Seconds shown in milliseconds."""
    return "-" if x is None else f"{1e3 * float(x):.3g}"


def col(header: str, key: str, format: Callable[[Any], str] = fmt) -> Column:
    """The column ``header`` showing ``row[key]``."""
    return Column(header, lambda r: format(r.get(key)))


def phase(key: str) -> Callable[[Row], str]:
    """A phase of the solver's own ``report.timings``, in ms."""
    return lambda r: ms((r.get("timings") or {}).get(key))


def status(r: Row) -> str:
    if r.get("error"):
        return "ERROR"
    return "yes" if r.get("converged") else "**no**"


def mib(r: Row) -> str:
    return fmt(r.get("peak_rss_mib"), 4)


def mm3(key: str) -> Callable[[Row], str]:
    """A 3-vector in metres, shown in mm."""
    return lambda r: "-" if r.get(key) is None else "(" + ", ".join(f"{1e3 * c:.3f}" for c in r[key]) + ")"


def ratio(a: Any, b: Any) -> float | None:
    return float(a) / float(b) if a is not None and b else None


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


def command_line() -> str:
    """The command that started this run, with paths relative to the working folder."""
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
# Parent: run cases in children


@dataclass
class Run:
    rows: dict[str, Row] = field(default_factory=dict)
    array_dir: Path = Path(".")


def run_child(name: str, workdir: Path) -> Row:
    """Run one case in a fresh interpreter; its peak RSS comes from ``wait4``'s rusage."""
    out_json = workdir / f"{_safe(name)}.json"
    log = workdir / f"{_safe(name)}.log"
    cmd = [sys.executable, str(RUNNER), "--child", name, "--workdir", str(workdir)]
    load_at_start = list(os.getloadavg())
    start = time.perf_counter()
    with open(log, "wb") as log_file:
        proc = subprocess.Popen(cmd, stdout=log_file, stderr=subprocess.STDOUT, cwd=REPO)
        while True:
            pid, wait_status, usage = os.wait4(proc.pid, os.WNOHANG)
            if pid:
                break
            if time.perf_counter() - start > CASE_TIMEOUT_S:
                proc.kill()
                pid, wait_status, usage = os.wait4(proc.pid, 0)
                break
            time.sleep(0.02)
    proc.returncode = os.waitstatus_to_exitcode(wait_status)
    wall = time.perf_counter() - start
    row: Row = {}
    if out_json.exists():
        row = json.loads(out_json.read_text())
    if proc.returncode != 0 or not row:
        lines = log.read_text(errors="replace").strip().splitlines() or ["(no output)"]
        row.setdefault("error", f"child exited with {proc.returncode}: {lines[-1]} (log: {log.name})")
        row["log_tail"] = lines[-30:]
    row["case"] = name
    row["peak_rss_mib"] = usage.ru_maxrss / 1024  # KiB on Linux
    row["child_wall_s"] = wall
    row["load_at_start"] = load_at_start
    return row


def child_main(name: str, workdir: Path) -> int:
    """The child process: run the case ``name`` and write its row to ``workdir``."""
    global _ARRAY_DIR, _CURRENT_CASE
    _ARRAY_DIR, _CURRENT_CASE = workdir, name
    row = CASES[name].run()
    if "sorofem" in sys.modules:
        row["extension"] = extension_stamp()
    (workdir / f"{_safe(name)}.json").write_text(json.dumps(row, default=json_default))
    return 0


def json_default(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


# ---------------------------------------------------------------------------
# The report (BENCHMARKS.md)


def run_log(rows: dict[str, Row]) -> str:
    """Order, wall time and machine load of each case (other jobs may share the machine)."""
    out = ["| # | case | child wall time [s] | load average at case start (1, 5, 15 min) |", "|---|---|---|---|"]
    for i, (name, r) in enumerate(rows.items(), 1):
        load = r.get("load_at_start")
        label = f"{name} (earlier run)" if r.get("reused") else name
        out.append(f"| {i} | {label} | {fmt(r.get('child_wall_s'))} | "
                   f"{'-' if load is None else ', '.join(f'{x:.2f}' for x in load)} |")
    return "\n".join(out) + "\n"


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
    for title, write in SECTIONS.items():
        parts += [f"## {title}", "", write(run.rows, run.array_dir)]
    parts += [f"## {RUN_LOG_TITLE}", "", "Cases in the order they ran, each in its own process.", "",
              run_log(run.rows)]
    return "\n".join(parts)


def owned_titles() -> set[str]:
    """The ``## `` sections written by this runner (whether or not this run renders them)."""
    return {t.title for t in TABLES.values()} | set(SECTIONS) | {RUN_LOG_TITLE} | FORMER_TITLES


def foreign_sections(text: str) -> list[str]:
    """The ``## `` sections of an existing report that this runner does not own (e.g. "Locking
    study", written by examples/02_locking_study.py), verbatim, in their order."""
    chunks = re.split(r"(?m)^(?=## )", text)
    kept = []
    for chunk in chunks[1:]:  # chunks[0] is the preamble, which the runner owns
        title = chunk.splitlines()[0][3:].strip()
        if title not in owned_titles():
            kept.append(chunk.rstrip("\n") + "\n")
    return kept
