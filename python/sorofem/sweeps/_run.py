"""Running a sweep on a Dask cluster: :func:`sweep`.

The cases are grouped by what they share (mesh, supports, cables: one compiled model) and sent
to the workers in batches; each finished batch is appended to the results at once, so an
interruption loses only the batches in flight and a rerun of the same sweep solves only the
cases that have no row yet.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import math
import os
import queue
import signal
import threading
import time
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping, Sequence

import numpy as np
from numpy.typing import ArrayLike

from .._validate import dask_client
from .._version import __version__
from ..errors import InputError, SceneError
from ..progress import Progress
from ..scene import SCENE, Checker, Scene
from ..targets import embed_points
from ._cases import Cases, read_scene
from ._solve import FIELDS, Batch, solve_batch, tip_node
from ._store import Store, load_sweep, missing_extra, result_columns

__all__ = ["sweep", "SweepResult", "CONNECT_TIMEOUT", "local_cluster", "LOCAL_CLUSTER_CONFIG"]

#: Seconds to wait for a scheduler given by address before giving up.
CONNECT_TIMEOUT = 5.0
#: The batches shrink as the sweep goes on (factoring: rounds of one batch per worker, each
#: batch 1 / (SHARE x workers) of the cases left when its round starts), so that the first are
#: large (few tasks: each costs the scheduler, the driver and the worker a few ms of CPU) and
#: the last small (the workers finish together, none waits on a long last batch) ...
SHARE = 2
#: ... none smaller than the cases / (MAX_BATCHES_PER_WORKER x workers), a round that would
#: leave fewer cases than two rounds of those taking them all, evenly: Dask hands a
#: single-thread worker its next task while it still runs one, so the last two rounds are
#: handed out about together and the finer split of the last one would only add tasks ...
MAX_BATCHES_PER_WORKER = 8
#: ... and none larger than this (how much an interruption can lose per worker).
MAX_BATCH = 50
#: Dask settings of :func:`local_cluster`: each worker's statistical profiler samples the running
#: solve every 10 ms, every Dask server (scheduler, nannies, workers) checks its event loop
#: every 20 ms, and each worker and its nanny read the worker's memory every 100 ms (half of
#: an idle cluster's CPU time), CPU taken from the solves on the same cores. Only the
#: dashboard's profile and system pages lose detail, and a worker outgrowing its memory limit
#: is paused or restarted up to a second later.
LOCAL_CLUSTER_CONFIG = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.interval": "5s",
    "distributed.worker.memory.monitor-interval": "1s",
}
#: Seconds between two looks for a Ctrl-C while no batch finishes (a finished batch wakes the
#: driver at once).
POLL = 0.1


@dataclass
class SweepResult:
    """What :func:`sweep` did. The results themselves are in ``out`` (:meth:`table`)."""

    #: The sweep's folder.
    out: Path
    #: Cases in the sweep.
    n_cases: int
    #: Cases that already had a row when this run started (a resumed sweep).
    skipped: int
    #: Cases solved by this run.
    solved: int
    #: Rows of the whole table with ``converged`` false.
    failed: int
    #: Wall time of this run, s.
    time: float
    #: Worker threads of the cluster.
    workers: int

    def table(self, *, pandas: bool | None = None) -> Any:
        """The results (:func:`sorofem.load_sweep`)."""
        return load_sweep(self.out, pandas=pandas)

    def to_dict(self) -> dict[str, Any]:
        return {"out": str(self.out), "n_cases": self.n_cases, "skipped": self.skipped, "solved": self.solved,
                "failed": self.failed, "time": self.time, "workers": self.workers}


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def local_cluster(workers: int | None = None) -> Any:
    """A Dask ``LocalCluster`` for sweeps: ``workers`` processes (default: one per core) of one
    thread each, and the Rust core's thread pool in each worker sized so that workers x
    threads = cores (``RAYON_NUM_THREADS``): cases run side by side rather than each solve
    spreading over every core. Dask's own monitors are slowed down (:data:`LOCAL_CLUSTER_CONFIG`)."""
    try:
        import dask
        from dask.distributed import LocalCluster
    except ImportError as exc:
        raise missing_extra("a sweep", exc) from None
    cores = _cores()
    n = cores if workers is None else workers
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise InputError(f"workers: expected an integer >= 1, got {workers!r}")
    threads = max(1, cores // int(n))
    # The workers' nannies take the configuration as it is now into the worker processes they start.
    with dask.config.set(LOCAL_CLUSTER_CONFIG):
        return LocalCluster(
            # No fixed port: the scheduler's HTTP routes (and dashboard, if bokeh is there) take a free one.
            n_workers=int(n), threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=":0",
            silence_logs=logging.ERROR, env={"RAYON_NUM_THREADS": str(threads)},
        )


@contextlib.contextmanager
def _client(client: Any, scheduler: str | None, workers: int | None) -> Iterator[Any]:
    """The client to run on: the one given (left open), one connected to ``scheduler``, or
    one of a new :func:`local_cluster` (both closed at the end)."""
    if client is not None:
        if scheduler is not None or workers is not None:
            raise InputError("client: give a client, a scheduler address or a number of workers, not several")
        yield dask_client(client)
        return
    try:
        from dask.distributed import Client
    except ImportError as exc:
        raise missing_extra("a sweep", exc) from None
    if scheduler is not None:
        if workers is not None:
            raise InputError("workers: the workers of a cluster given by --scheduler are its own; drop --workers")
        try:
            own = Client(scheduler, timeout=CONNECT_TIMEOUT, set_as_default=False)
        except (OSError, TimeoutError, ValueError) as exc:
            raise InputError(
                f"scheduler: could not reach a Dask scheduler at {scheduler} within {CONNECT_TIMEOUT:g} s "
                f"({' '.join(str(exc).split())})"
            ) from None
        with own:
            yield own
        return
    with local_cluster(workers) as cluster, Client(cluster, set_as_default=False) as own:
        yield own


def _fingerprint(path: Path, text: str, cases: Cases, save: Sequence[str], markers: np.ndarray) -> str:
    record = {"scene": str(path.resolve()), "text": text, "cases": cases.digest(), "save": sorted(save),
              "markers": markers.tolist()}
    return hashlib.sha256(json.dumps(record, sort_keys=True).encode()).hexdigest()


def _check_cases(path: Path, text: str, base: dict[str, Any], cases: Cases) -> tuple[Scene, dict[int, list[int]]]:
    """Everything that can be checked before any solve. Returns the scene of case 0 (built in
    full: its mesh, cables, target) and the cases of each group (cases that share a model)."""
    groups: dict[tuple[Any, ...], list[int]] = {}
    for i in range(cases.n):
        groups.setdefault(cases.group(i), []).append(i)
    for key, column in zip(cases.keys, cases.values):
        if key.text == "mesh.file":
            for value in dict.fromkeys(column):
                file = Path(value) if Path(value).is_absolute() else path.parent / value
                if not file.is_file():
                    raise InputError(f"mesh.file: mesh file not found: {file} (a value of the sweep)")
    first = None
    for members in groups.values():
        data = base
        for key, value in zip(cases.keys, cases.row(members[0])):
            data = key.apply(data, value, f"case {members[0]}")
        try:
            if first is None:
                first = Scene.from_data(data, path, text=text)
            else:
                SCENE.check(Checker(path, text), data, "")
        except SceneError as exc:
            shown = ", ".join(f"{k.text}={json.dumps(v)}" for k, v in zip(cases.keys, cases.row(members[0])))
            raise InputError(f"case {members[0]} ({shown}): {exc}") from None
    assert first is not None
    return first, {g: members for g, members in enumerate(groups.values())}


def _markers(markers: ArrayLike | None, probe: Scene, base: dict[str, Any]) -> np.ndarray:
    """The rest points to follow: ``markers``, else the scene's [target] nodes or points."""
    if markers is None:
        target = base.get("target", {})
        if probe.target is not None and ("nodes" in target or "points" in target):
            return np.asarray(probe.target.rest_points, dtype=np.float64).reshape(-1, 3)
        return np.zeros((0, 3))
    points = np.asarray(markers, dtype=np.float64)
    if points.ndim == 1 and points.size == 3:
        points = points.reshape(1, 3)
    if points.ndim != 2 or points.shape[1] != 3 or not np.all(np.isfinite(points)):
        raise InputError(f"markers: expected finite rest points of shape (k, 3), got shape {points.shape}")
    try:
        embed_points(probe.mesh, points)
    except InputError as exc:
        raise InputError(f"markers: {exc}") from None
    return points


def _batches(groups: dict[int, list[int]], todo: set[int], workers: int, size: int | None = None) -> list[list[int]]:
    """The cases to solve, cut into batches of one group each, in the order they are sent: of
    ``size`` cases, or without it shrinking round by round from ``MAX_BATCH`` (see :data:`SHARE`)."""
    left = len(todo)
    smallest = max(1, math.ceil(left / (MAX_BATCHES_PER_WORKER * workers)))
    out: list[list[int]] = []
    n = size or 0
    in_round = 0
    for members in groups.values():
        pending = [i for i in members if i in todo]
        k = 0
        while k < len(pending):
            if size is None and in_round == 0:
                n = min(MAX_BATCH, max(smallest, math.ceil(left / (SHARE * workers))))
                if left - workers * n < 2 * workers * smallest:
                    n = min(MAX_BATCH, math.ceil(left / workers))
                in_round = workers
            out.append(pending[k:k + n])
            k += n
            left -= len(out[-1])
            in_round -= 1
    return out


def sweep(
    scene: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    grid: Mapping[str, Sequence[Any]] | None = None,
    sample: Mapping[str, Sequence[float]] | None = None,
    samples: int | None = None,
    seed: int = 0,
    cases: str | os.PathLike[str] | Mapping[str, Sequence[Any]] | None = None,
    save: Sequence[str] = (),
    markers: ArrayLike | None = None,
    workers: int | None = None,
    client: Any = None,
    scheduler: str | None = None,
    batch_size: int | None = None,
    force: bool = False,
    progress: bool | None = None,
    log: Callable[[str], None] | None = None,
) -> SweepResult:
    """Solve many variants of a scene on a Dask cluster, each as ``sorofem run`` would, and
    collect one row per case in ``out/results.parquet``.

    Each case overrides scene keys by their dotted names (``material.youngs_modulus``,
    ``cable[0].actuation``, ``loads.gravity``, ``mesh.file``, ...), checked against the scene
    spec before anything is solved. Cases that share a mesh, supports and cables are solved by
    one compiled model per worker. Rows are written as batches finish; a rerun of the same
    sweep on the same ``out`` solves only the cases without a row (resume after a crash or
    Ctrl-C). A case that does not converge is a row with ``converged`` false and its
    ``error``. See ``docs/sweep.md``.

    Parameters
    ----------
    scene
        The scene file.
    out
        The sweep's folder (created): ``sweep.json``, ``cases.parquet``, ``results.parquet/``
        and, with ``save``, ``fields.zarr``.
    grid
        ``key: values``: the Cartesian product of the values is swept.
    sample, samples, seed
        ``key: (lo, hi)``: ``samples`` Latin-hypercube samples within the bounds
        (``scipy.stats.qmc``, seeded by ``seed``); with ``grid``, every grid point gets every
        sample.
    cases
        Instead of grid and sample: a table of cases, a CSV or Parquet file (one column per
        key) or a mapping key -> column.
    save
        Full fields to keep per case in ``fields.zarr``, one name or several:
        ``"displacement"`` (the final one for a dynamic scene), ``(n_cases, n_nodes, 3)`` m.
    markers
        Rest points ``(k, 3)`` (m, inside the mesh) whose deformed positions are collected
        as ``marker[i].x`` .. ``marker[i].z``; default: the scene's ``[target]`` nodes or
        points, if any. The tip (the node farthest from the supports) is always collected.
    workers
        Worker processes of the local cluster (default: one per core; the Rust core then
        uses cores / workers threads in each).
    client
        A ``dask.distributed.Client`` to run on instead (left open).
    scheduler
        The address of a running Dask scheduler (``tcp://HOST:PORT``) to connect to instead.
    batch_size
        Cases sent to a worker at once. Default: batches that shrink as the sweep goes on,
        in rounds of one per worker, each half a worker's share of the cases left when its
        round starts (at most 50, at least 1/8 of a worker's share of the sweep), so that the
        workers finish together.
    force
        Replace the sweep ``out`` holds if it is another one (by default that is refused).
    progress
        A progress line (cases done, failed, rate, time left); see :mod:`sorofem.progress`.
    log
        Called with a line of text when the sweep starts (cases, workers, how many are
        already done); the command line prints it.

    Returns
    -------
    SweepResult

    Raises
    ------
    InputError
        A bad key or value, no case, ``out`` holding another sweep, an unreachable scheduler,
        the ``cluster`` extra not installed.

    Examples
    --------
    >>> import sorofem as sf
    >>> run = sf.sweep("cantilever.toml", "results/sweep", workers=2,
    ...                grid={"material.youngs_modulus": [50e3, 66e3, 80e3]})   # doctest: +SKIP
    >>> sf.load_sweep("results/sweep")[["material.youngs_modulus", "tip.z"]]   # doctest: +SKIP
    """
    start = time.perf_counter()
    path, text, base = read_scene(scene)
    table = Cases.build(path, grid=grid, sample=sample, samples=samples, seed=seed, table=cases)
    save = tuple(dict.fromkeys((save,) if isinstance(save, str) else save))
    for name in save:
        if name not in FIELDS:
            raise InputError(f"save: unknown field {name!r} (expected one of {', '.join(FIELDS)})")
    if save and any(k.parts[0][0] == "mesh" for k in table.keys):
        raise InputError("save: full fields need one mesh for every case, and this sweep varies "
                         f"{', '.join(k.text for k in table.keys if k.parts[0][0] == 'mesh')}")
    if batch_size is not None and (isinstance(batch_size, bool) or not isinstance(batch_size, (int, np.integer))
                                   or batch_size < 1):
        raise InputError(f"batch_size: expected an integer >= 1, got {batch_size!r}")
    probe, groups = _check_cases(path, text, base, table)
    points = _markers(markers, probe, base)
    dynamic = probe.dynamics is not None
    key_columns = [(k.text, k.column_type()) for k in table.keys]
    columns = result_columns(key_columns, dynamic=dynamic, n_cables=len(probe.cables), n_markers=len(points))

    store = Store(out)
    if store.root.exists() and not store.root.is_dir():
        raise InputError(f"out: {store.root} exists and is not a folder")
    fingerprint = _fingerprint(path, text, table, save, points)
    manifest = store.manifest()
    same = manifest is not None and manifest.get("fingerprint") == fingerprint
    if not same and store.holds_sweep_files() and not force:
        known = manifest is not None and manifest.get("fingerprint")
        what = (f"another sweep (scene {manifest.get('scene')}, {manifest.get('n_cases')} cases, keys "
                f"{', '.join(manifest.get('keys', []))})" if known else "the files of an unfinished or damaged sweep")
        raise InputError(f"out: {store.root} holds {what}; choose another folder, or pass force=True (--force) "
                         "to replace it")
    done = store.done() if same else set()
    todo = set(range(table.n)) - done
    result = SweepResult(Path(out), table.n, len(done), 0, store.failed() if same else 0, 0.0, 0)
    say = log or (lambda line: None)
    keys = ", ".join(k.text for k in table.keys)
    if not todo:
        say(f"{path.name}: all {table.n} cases ({keys}) are already in {store.root}: nothing to solve")
        result.time = time.perf_counter() - start
        return result

    # The cluster first: a scheduler that cannot be reached leaves no folder behind.
    with _client(client, scheduler, workers) as dask:
        n_threads = sum(dask.nthreads().values())
        if n_threads == 0:
            say(f"no worker is connected to the scheduler {dask.scheduler.address} yet: the cases wait for one")
        n_threads = max(n_threads, 1)
        batches = _batches(groups, todo, n_threads, batch_size)
        sizes = sorted({len(b) for b in batches})
        result.workers = n_threads
        if not same:
            manifest = {
                "sorofem_version": __version__,
                "fingerprint": fingerprint,
                "scene": str(path.resolve()),
                "scene_text": text,
                "keys": [k.text for k in table.keys],
                "origin": table.origin,
                "n_cases": table.n,
                "kind": "dynamic" if dynamic else "static",
                "n_nodes": probe.mesh.n_nodes,
                "tip_node": tip_node(probe),
                "markers": points.tolist(),
                "save": list(save),
                "columns": [name for name, _ in columns],
                "runs": [],
            }
        assert manifest is not None
        run = len(manifest["runs"])
        manifest["runs"].append({"started": datetime.now(timezone.utc).isoformat(timespec="seconds"),
                                 "cases_before": len(done), "workers": n_threads, "batches": len(batches),
                                 "batch_size": sizes[-1], "scheduler": dask.scheduler.address if dask.scheduler else None})

        # Called by _execute once the batches are sent: the workers start solving meanwhile.
        def write_folder() -> None:
            if same:
                store.clean_temporaries()
                store.write_manifest(manifest)
            else:
                store.clear()
                store.create(manifest, key_columns, table.columns(), columns)
                if save:
                    store.create_fields(save, table.n, probe.mesh.n_nodes)
            resumed = f"; resuming: {len(done)} already in {store.root}, {len(todo)} to solve" if done else ""
            cut = f"of {sizes[0]}" if len(sizes) == 1 else f"of {sizes[-1]} down to {sizes[0]}"
            say(f"{path.name}: {table.n} cases ({keys}) in {len(groups)} group(s) sharing a model, "
                f"{n_threads} worker(s), {len(batches)} batches {cut} cases{resumed}")

        _execute(dask, store, table, path, text, batches, points, save, len(probe.cables), columns, run, result,
                 progress, write_folder)
    result.time = time.perf_counter() - start
    return result


@contextlib.contextmanager
def _interruptible() -> Iterator[threading.Event]:
    """Ctrl-C (SIGINT) sets the event instead of raising at a random place (Dask's own threads
    and finalisers swallow a KeyboardInterrupt raised there); a second one raises at once."""
    stop = threading.Event()
    if threading.current_thread() is not threading.main_thread():
        yield stop
        return

    def handler(signum: int, frame: Any) -> None:
        if stop.is_set():
            raise KeyboardInterrupt
        stop.set()

    previous = signal.signal(signal.SIGINT, handler)
    try:
        yield stop
    finally:
        signal.signal(signal.SIGINT, previous)


def _execute(dask: Any, store: Store, table: Cases, path: Path, text: str, batches: list[list[int]],
             points: np.ndarray, save: tuple[str, ...], n_cables: int, columns: list[tuple[str, str]], run: int,
             result: SweepResult, progress: bool | None, write_folder: Callable[[], None]) -> None:
    """Submit the batches, then ``write_folder`` (the record and the case table: the workers
    solve meanwhile, nothing is written before it), then write each batch as it finishes and
    keep the counts of ``result``."""
    keys = tuple(k.text for k in table.keys)
    marker_points = tuple(tuple(float(v) for v in p) for p in points)
    total = sum(len(m) for m in batches)
    bar = Progress(total=total, desc="sweep", unit="cases", enabled=progress)
    # Filled by Dask's callback thread as batches finish (failed or not); the driver sleeps on it.
    finished: queue.SimpleQueue[Any] = queue.SimpleQueue()
    futures: dict[Any, tuple[int, list[int]]] = {}
    started = time.perf_counter()
    try:
        with _interruptible() as stop:
            # An absolute path: a worker of another process (or machine) has its own working folder.
            scene_path = str(path.resolve())
            # One map, one message to the scheduler; the batches start in this order.
            submitted = dask.map(solve_batch, [
                Batch(scene_path, text, keys, tuple((i, table.row(i)) for i in members), marker_points, save, n_cables)
                for members in batches], pure=False)
            for b, (future, members) in enumerate(zip(submitted, batches)):
                futures[future] = (b, members)
                future.add_done_callback(finished.put)
            write_folder()
            while futures:
                if stop.is_set():
                    raise KeyboardInterrupt
                try:
                    future = finished.get(timeout=POLL)
                except queue.Empty:
                    continue
                if future in futures:
                    _write(store, future, *futures.pop(future), keys, table, columns, run, result)
                rate = result.solved / max(time.perf_counter() - started, 1e-9)
                bar.set(result.solved, postfix=f"{result.failed} failed, {rate:.3g} cases/s")
    finally:
        bar.close()
        if futures:
            dask.cancel(list(futures))


def _write(store: Store, future: Any, b: int, members: list[int], keys: tuple[str, ...], table: Cases,
           columns: list[tuple[str, str]], run: int, result: SweepResult) -> None:
    """Append the rows (and fields) of a finished batch."""
    try:
        outcomes = future.result()
    except Exception as exc:  # noqa: BLE001 - e.g. KilledWorker: the batch's cases are failed rows
        message = " ".join(f"{type(exc).__name__}: {exc}".split())
        rows = [{"case": i, "converged": False, "error": f"the batch could not run: {message}"} for i in members]
        fields: list[dict[str, np.ndarray]] = [{} for _ in members]
    else:
        rows = [o.row for o in outcomes]
        fields = [o.fields for o in outcomes]
    for row in rows:
        row.update(zip(keys, table.row(row["case"])))
    store.write_fields([r["case"] for r in rows], fields)
    store.append(run, b, rows, columns)
    result.solved += len(rows)
    result.failed += sum(1 for r in rows if not r.get("converged"))
