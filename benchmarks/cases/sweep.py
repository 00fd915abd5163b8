"""Sweeps (issue 21): many static cases of one scene through `sf.sweep` on a Dask LocalCluster,
against the same cases solved one after another in one process; the overhead of the sweep
machinery per case; and an estimate of the speed-up on a 100-worker cluster."""

from __future__ import annotations

import importlib
import os
import resource
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from harness import TABLES, Column, Row, Table, case, col, fmt, mib, section

from .common import HAMMERBOT_FIXED_COUNT, SOLIDFEM_DATA

TABLES["sweep"] = Table(
    "Sweeps (sorofem.sweeps on Dask)",
    "Static cases of one scene varying Young's modulus (evenly spread in the range), as `sf.sweep` "
    "runs them on a `LocalCluster` already started, its workers having imported sorofem (`client=`; the start-up is its own column) and as "
    "loops in this one process: the *case loop* is the sweep's own per-case code (`solve_batch`: scene "
    "built from its tables like the first, solved by `Scene.solve`, its row made), the *bare loop* a "
    "hand-written `body.material = ...; solve_static(...)` on one body. Sweep time = `sf.sweep` wall "
    "time (checks, Parquet writes and Dask included). Overhead per case = (sweep with 1 worker - case "
    "loop) / cases: what Dask and Parquet add. Solve = median wall time of one case's `Scene.solve` "
    "inside the sweep. The 1-worker cluster gives its worker both cores (RAYON_NUM_THREADS=2), the "
    "2-worker one one each; the loops run with the core's default threads. Each loop runs right before "
    "each sweep (same machine load); the fastest of the repeats counts. *From CPU time*: the same ratio "
    "from CPU seconds instead of wall time (for the loop the smaller of its wall and CPU time: its "
    "process's second pool thread spins on the other core without making a small solve faster; for the "
    "sweep the larger of its busiest worker and all its processes' CPU time, driver, scheduler and "
    "nannies included, over the 2 cores): the speed-up on cores of its own, when other jobs share the "
    "machine. Batches: how many the 2-worker sweep sent, largest and smallest.",
    (
        col("case", "case", str),
        col("cases", "n_cases"),
        col("tets", "tets"),
        col("solve [ms]", "solve_seconds", lambda x: "-" if x is None else f"{1e3 * x:.3g}"),
        col("bare loop [cases/s]", "bare_rate"),
        col("case loop [cases/s]", "loop_rate"),
        col("sweep 1 worker [cases/s]", "rate_1"),
        col("sweep 2 workers [cases/s]", "rate_2"),
        col("2 workers / case loop", "speedup_loop", lambda x: fmt(x) + "x" if x else "-"),
        col("2 workers / bare loop", "speedup_bare", lambda x: fmt(x) + "x" if x else "-"),
        col("same, from CPU time", "cpu_speedup_loop", lambda x: fmt(x) + "x" if x else "-"),
        col("overhead per case [ms]", "overhead_seconds", lambda x: "-" if x is None else f"{1e3 * x:.3g}"),
        Column("batches", lambda r: "-" if not r.get("batches") else
               f"{r['batches']} ({r['batch_size']} to {r['smallest_batch']})"),
        col("cluster start [s]", "cluster_start_seconds"),
        Column("load (1 min) start / end", lambda r: "-" if not r.get("load") else
               f"{r['load'][0]:.2f} / {r['load'][1]:.2f}"),
        Column("peak RSS [MiB]", mib),
    ),
)

CANTILEVER = """\
[mesh]
box = { size = [0.4, 0.1, 0.1], cells = [8, 2, 2] }
[material]
youngs_modulus = 66e3
poisson_ratio = 0.45
density = 1080
[[fixed]]
box = { min = [-1e-9, -1, -1], max = [1e-9, 1, 1] }
[loads]
gravity = [0, 0, -9.81]
"""
HAMMERBOT = f"""\
[mesh]
file = "{SOLIDFEM_DATA / 'hammerbot_fine.tet'}"
scale = 0.01
[material]
youngs_modulus = 100e3
poisson_ratio = 0.4
density = 1070
[[fixed]]
box = {{ min = [-0.050001, -1, -1], max = [-0.049999, 1, 1] }}
[loads]
gravity = [0, -9.8, 0]
"""


def _noop(i: int) -> int:
    return i


def _cpu_seconds() -> float:
    """CPU time (user + system) of this process so far, all its threads."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def sweep_throughput(text: str, n: int, lo: float, hi: float, repeats: int = 3) -> Row:
    """One scene, ``n`` Young's moduli in [lo, hi]: sweeps on 1 and 2 workers and the loops in
    this process, each run ``repeats`` times, a loop right before each sweep (so that both see
    the same machine load); the fastest run of each counts."""
    import pyarrow.parquet as pq
    from dask.distributed import Client

    import sorofem as sf
    from sorofem.sweeps._solve import Batch, solve_batch

    load_start = os.getloadavg()[0]
    values = [float(v) for v in np.linspace(lo, hi, n)]
    key = "material.youngs_modulus"
    row: Row = {"n_cases": n, "repeats": repeats}
    times: dict[str, list[float]] = {"bare": [], "loop": [], "1": [], "2": []}
    # CPU seconds of each run (the loop's process; the sweep's workers and driver, scheduler
    # included): what the runs cost whatever else the machine runs meanwhile.
    cpu: dict[str, list[float]] = {"loop": [], "1": [], "2": []}
    with tempfile.TemporaryDirectory(prefix="sorofem-sweep-bench-") as tmp:
        scene = Path(tmp) / "scene.toml"
        scene.write_text(text, encoding="utf-8")
        base = sf.Scene.load(scene)
        row["tets"] = base.mesh.n_tets
        body, poisson, density = base.body, base.material.poisson_ratio, base.material.density
        batch = Batch(str(scene), text, (key,), tuple((i, (v,)) for i, v in enumerate(values)))

        def loops() -> None:
            start = time.perf_counter()
            for e in values:
                body.material = sf.NeoHookean(youngs_modulus=e, poisson_ratio=poisson, density=density)
                sf.solve_static(body, base.gravity, options=base.solve_options)
            times["bare"].append(time.perf_counter() - start)
            start, cpu_start = time.perf_counter(), _cpu_seconds()
            outcomes = solve_batch(batch)
            times["loop"].append(time.perf_counter() - start)
            # A loop lasts at least its CPU time on a core of its own, unless that time counts the
            # spinning of a pool thread that does not make it faster: then its wall time.
            cpu["loop"].append(min(_cpu_seconds() - cpu_start, times["loop"][-1]))
            assert all(o.row["converged"] for o in outcomes)

        for workers in (1, 2):
            started = time.perf_counter()
            with sf.sweeps.local_cluster(workers) as cluster, Client(cluster, set_as_default=False) as client:
                row[f"cluster_start_{workers}"] = time.perf_counter() - started
                # Warm workers: sorofem imported (a one-off per worker, part of the start-up).
                client.run(importlib.import_module, "sorofem.sweeps._solve")
                for k in range(repeats):
                    loops()
                    out = Path(tmp) / f"sweep-{workers}-{k}"
                    before = client.run(_cpu_seconds)
                    start, cpu_start = time.perf_counter(), _cpu_seconds()
                    result = sf.sweep(scene, out, grid={key: values}, client=client, progress=False)
                    times[str(workers)].append(time.perf_counter() - start)
                    driver = _cpu_seconds() - cpu_start
                    after = client.run(_cpu_seconds)
                    busiest = max(after[w] - before[w] for w in after)
                    # On cores of its own the run lasts at least as long as its busiest worker,
                    # and at least its total CPU time spread over the workers' cores.
                    cpu[str(workers)].append(max(busiest, (sum(after.values()) - sum(before.values()) + driver) / workers))
                    assert result.solved == n and result.failed == 0
                table = sf.load_sweep(out, pandas=False)
                row[f"solve_seconds_{workers}"] = statistics.median(table.column("time").to_pylist())
                if workers == 2:
                    # The scheduler's cost of one task (a no-op), for the estimate below.
                    m = 400
                    start = time.perf_counter()
                    client.gather(client.map(_noop, range(m), pure=False))
                    row["task_seconds"] = (time.perf_counter() - start) / m
                    parts = sorted(pq.read_metadata(p).num_rows for p in (out / "results.parquet").glob("part-*"))
                    row["batches"], row["batch_size"], row["smallest_batch"] = len(parts), parts[-1], parts[0]
                    row["write_seconds_per_case"] = _write_cost(out, table, round(n / len(parts)))
    bare, loop, one, two = (min(times[k]) for k in ("bare", "loop", "1", "2"))
    cpu_loop, cpu_two = min(cpu["loop"]), min(cpu["2"])
    load_end = os.getloadavg()[0]
    # Each loop ran right before its sweep: the spread of these paired ratios is the run-to-run noise
    # the fastest-of-the-repeats ratio is meant to see through.
    paired = sorted(a / b for a, b in zip(times["loop"], times["2"]))
    row.update(
        all_seconds=times, cpu_seconds=cpu, cpu_speedup_loop=cpu_loop / cpu_two, bare_seconds=bare, loop_seconds=loop, seconds_1=one, seconds_2=two,
        bare_rate=n / bare, loop_rate=n / loop, rate_1=n / one, rate_2=n / two,
        speedup_loop=loop / two, speedup_bare=bare / two,
        overhead_seconds=(one - loop) / n, solve_seconds=row["solve_seconds_2"],
        worker_seconds_per_case=loop / n, cluster_start_seconds=row["cluster_start_2"],
        converged=True, iterations=None, seconds=two, load=[load_start, load_end],
        paired_speedups=paired,
        note=f"measured {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, fastest of {repeats} runs each "
             f"(2 workers / case loop of each pair: median {statistics.median(paired):.3g}x, "
             f"{paired[0]:.3g}x to {paired[-1]:.3g}x); load average (1 min) {load_start:.2f} at start, {load_end:.2f} at end (2 cores)",
    )
    return row


def _write_cost(out: Path, table: Any, size: int) -> float:
    """Seconds per case the driver spends appending rows (one part file per batch of ``size``
    rows), timed on copies of the sweep's own rows."""
    import pyarrow as pa

    from sorofem.sweeps._store import Store

    def kind(t: Any) -> str:
        if pa.types.is_list(t):
            return "list"
        return {pa.int64(): "int", pa.float64(): "float", pa.bool_(): "bool"}.get(t, "str")

    columns = [(f.name, kind(f.type)) for f in table.schema]
    rows = table.to_pylist()[:size]
    store = Store(out)
    repeats = 20
    start = time.perf_counter()
    for k in range(repeats):
        store.append(900, k, rows, columns)
    return (time.perf_counter() - start) / (repeats * len(rows))


case("sorofem/sweep-cantilever-0.4m-8x2x2-200", "sweep", quick=True)(
    lambda: sweep_throughput(CANTILEVER, 200, 40e3, 100e3, repeats=10))


@case("sorofem/sweep-hammerbot-24", "sweep")
def hammerbot_sweep() -> Row:
    import sorofem as sf

    mesh = sf.Mesh.read(SOLIDFEM_DATA / "hammerbot_fine.tet", scale=0.01)
    assert mesh.nodes_in_box(min=(-0.050001, -1, -1), max=(-0.049999, 1, 1)).size == HAMMERBOT_FIXED_COUNT
    return sweep_throughput(HAMMERBOT, 24, 60e3, 140e3, repeats=2)


@section("Sweeps on a 100-worker cluster (estimate)")
def cluster_estimate(rows: dict[str, Row], array_dir: Path) -> str:
    """A paper estimate of a sweep's throughput on 100 workers from the measured costs."""
    lines = [
        "From the rows above: each worker spends `t_w` per case (the case loop's time per case: "
        "building the case's scene like the first, the solve, the row), and the driver spends "
        "`t_d = t_task / B + t_write` per case, one after another (the scheduler's cost of one task, "
        "measured on no-op tasks, shared by the `B` cases of a batch, and the Parquet write of its row). "
        "With `W` workers the throughput is `min(W / t_w, 1 / t_d)`; the speed-up is that over one process "
        "running the case loop (`1 / t_w`). Assumptions: workers as fast as this machine's cores, one thread "
        "each; the scheduler's per-task cost as measured here (one scheduler, no network latency: rows are "
        "~1 kB, Dask's own figure is of the order of 1 ms per task); results written by the one driver; "
        "cluster start-up and the first model build per worker (one symbolic factorisation) not counted.",
        "",
        "| case | t_w [ms] | t_task [ms] | B | t_write [ms] | t_d [ms] | limit of the driver [cases/s] | "
        "100 workers [cases/s] | speed-up on 100 workers |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name, r in rows.items():
        if not name.startswith("sorofem/sweep-") or r.get("error") or not r.get("task_seconds"):
            continue
        t_w = r["worker_seconds_per_case"]
        batch = r["n_cases"] / r["batches"] if r.get("batches") else r["batch_size"]
        t_d = r["task_seconds"] / batch + r["write_seconds_per_case"]
        rate = min(100 / t_w, 1 / t_d)
        lines.append(
            f"| {name} | {1e3 * t_w:.3g} | {1e3 * r['task_seconds']:.3g} | {batch:.3g} | "
            f"{1e3 * r['write_seconds_per_case']:.3g} | {1e3 * t_d:.3g} | {fmt(1 / t_d)} | {fmt(rate)} | "
            f"{fmt(rate * t_w)}x |"
        )
    lines.append("")
    lines.append("The batch size `B` is the mean of the 2-worker sweep's default batches (cases / batches). "
                 "The default cuts a sweep into rounds of one batch per worker, 2 or 3 rounds, more where the "
                 "50-case cap binds (each batch half a worker's share of the cases left, down to 1/8 of its share "
                 "of the sweep, the last round the rest), so on 100 workers the batches for the same cases are ~50x smaller: a sweep of "
                 "small cases should have at least ~300 x B cases, or a larger `--batch-size`, to keep the driver "
                 "from being the limit.")
    return "\n".join(lines) + "\n"
