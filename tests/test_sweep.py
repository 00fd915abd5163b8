"""`sorofem sweep` / `sf.sweep` on Dask clusters: results equal `sorofem run`, a cluster given by
address, a worker killed mid-sweep, an interrupted driver resumed, failures as rows, bad input.

Every service is started here on 127.0.0.1 and stopped at the end of its test.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import numpy as np
import pytest

pytest.importorskip("distributed", reason='sweeps need the cluster extra: pip install ".[cluster]"')
pytest.importorskip("pyarrow")
pytest.importorskip("zarr")

import sorofem as sf  # noqa: E402
from sorofem.cli import main  # noqa: E402
from sorofem.sweeps import load_fields  # noqa: E402

#: The 0.4 m silicone cantilever on the coarse 8 x 2 x 2 mesh, with a cable along its top edge.
SCENE = """\
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

[[cable]]
start = [0, 0.05, 0.09]
direction = [1, 0, 0]
length = 0.4
divisions = 10
stiffness = 1e5
actuation = 0.9
"""
DASK = Path(sys.executable).parent / "dask"
#: Columns that differ between two runs of the same case (wall time).
TIMING = ("time",)


@pytest.fixture
def scene(tmp_path: Path) -> Path:
    path = tmp_path / "beam.toml"
    path.write_text(SCENE, encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def client() -> Iterator[object]:
    """One local cluster of two single-threaded worker processes for the tests that only need
    somewhere to run."""
    with sf.sweeps.local_cluster(2) as cluster:
        from dask.distributed import Client

        with Client(cluster, set_as_default=False) as c:
            yield c


def _rows(out: Path) -> list[dict]:
    return sf.load_sweep(out, pandas=False).to_pylist()


def _without_timing(rows: list[dict]) -> list[dict]:
    return [{k: v for k, v in r.items() if k not in TIMING} for r in rows]


def test_grid_equals_separate_runs_bit_for_bit(scene, tmp_path, capsys):
    out = tmp_path / "sweep"
    code = main(["sweep", str(scene), "--out", str(out), "--grid", "material.youngs_modulus=50e3,80e3",
                 "--grid", "cable[0].actuation=0.8,0.95", "--save", "displacement", "--workers", "2"])
    printed = capsys.readouterr()
    assert code == 0, printed.err
    assert "4 cases" in printed.out and "2 worker(s)" in printed.out
    rows = _rows(out)
    assert [r["case"] for r in rows] == [0, 1, 2, 3]
    assert [(r["material.youngs_modulus"], r["cable[0].actuation"]) for r in rows] == [
        (50e3, 0.8), (50e3, 0.95), (80e3, 0.8), (80e3, 0.95)]
    fields = load_fields(out)
    assert fields.shape == (4, 81, 3)
    meshio = pytest.importorskip("meshio")
    for r in rows:
        text = SCENE.replace("youngs_modulus = 66e3", f"youngs_modulus = {r['material.youngs_modulus']!r}")
        text = text.replace("actuation = 0.9", f"actuation = {r['cable[0].actuation']!r}")
        single = tmp_path / f"case{r['case']}.toml"
        single.write_text(text, encoding="utf-8")
        assert main(["run", str(single), "--out", str(tmp_path / f"run{r['case']}"), "--quiet"]) == 0
        summary = json.loads((tmp_path / f"run{r['case']}" / "summary.json").read_text())
        assert r["converged"] is True and r["error"] is None
        for name in ("newton_iterations", "residual_norm", "max_displacement"):
            assert r[name] == summary[name], name
        assert r["cable[0].tensions"] == summary["cables"][0]["tensions"]
        assert r["cable[0].max_tension"] == summary["cables"][0]["max_tension"] > 0
        displacement = meshio.read(tmp_path / f"run{r['case']}" / "result.vtu").point_data["displacement"]
        assert np.array_equal(fields[r["case"]], displacement)
        tip = np.array([r["tip.x"], r["tip.y"], r["tip.z"]])
        rest = sf.Mesh.box(size=(0.4, 0.1, 0.1), cells=(8, 2, 2)).points[r["tip.node"]]
        assert rest[0] == 0.4
        np.testing.assert_allclose(tip, rest + displacement[r["tip.node"]], rtol=0, atol=1e-15)
    # A harder pull (smaller alpha) of the cable along the top edge pulls harder and lifts the tip.
    by = {(r["material.youngs_modulus"], r["cable[0].actuation"]): r for r in rows}
    for e in (50e3, 80e3):
        assert by[(e, 0.8)]["tip.z"] > by[(e, 0.95)]["tip.z"]
        assert by[(e, 0.8)]["cable[0].max_tension"] > by[(e, 0.95)]["cable[0].max_tension"]


@contextmanager
def dask_processes(tmp_path: Path, n_workers: int) -> Iterator[tuple[str, list[subprocess.Popen]]]:
    """`dask scheduler` and `n_workers` `dask worker` processes (one thread each, no nanny) on
    127.0.0.1, stopped at the end."""
    file = tmp_path / "scheduler.json"
    log = open(tmp_path / "dask.log", "w")
    env = {**os.environ, "RAYON_NUM_THREADS": "1"}
    procs = [subprocess.Popen([str(DASK), "scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                               "--scheduler-file", str(file)], stdout=log, stderr=log, env=env)]
    workers = []
    try:
        deadline = time.monotonic() + 30
        while not file.is_file() and time.monotonic() < deadline:
            time.sleep(0.1)
        address = json.loads(file.read_text())["address"]
        for _ in range(n_workers):
            workers.append(subprocess.Popen(
                [str(DASK), "worker", address, "--host", "127.0.0.1", "--nthreads", "1", "--no-nanny",
                 "--no-dashboard"], stdout=log, stderr=log, env=env))
        procs += workers
        from dask.distributed import Client

        with Client(address, timeout=30, set_as_default=False) as c:
            c.wait_for_workers(n_workers, timeout=30)
        yield address, workers
    finally:
        for p in reversed(procs):
            if p.poll() is None:
                p.terminate()
        for p in procs:
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        log.close()


def test_sweep_through_a_scheduler_address(scene, tmp_path, capsys):
    out = tmp_path / "sweep"
    with dask_processes(tmp_path, 2) as (address, _):
        code = main(["sweep", str(scene), "--out", str(out), "--scheduler", address,
                     "--sample", "material.youngs_modulus=40e3:90e3", "--samples", "6", "--seed", "3"])
    printed = capsys.readouterr()
    assert code == 0, printed.err
    assert "2 worker(s)" in printed.out
    rows = _rows(out)
    assert [r["case"] for r in rows] == list(range(6)) and all(r["converged"] for r in rows)
    # Latin hypercube: one sample in each sixth of the range.
    strata = sorted(int((r["material.youngs_modulus"] - 40e3) / (50e3 / 6)) for r in rows)
    assert strata == list(range(6))
    manifest = json.loads((out / "sweep.json").read_text())
    assert manifest["runs"][0]["scheduler"] == address


def test_a_worker_killed_mid_sweep(scene, tmp_path):
    out = tmp_path / "sweep"
    # A finer mesh, so that a case lasts long enough to kill a worker while it solves.
    (tmp_path / "beam.toml").write_text(SCENE.replace("cells = [8, 2, 2]", "cells = [16, 4, 4]"))
    n = 16
    with dask_processes(tmp_path, 2) as (address, workers):
        driver = subprocess.Popen(
            [sys.executable, "-m", "sorofem.cli", "sweep", str(scene), "--out", str(out), "--scheduler", address,
             "--grid", "material.youngs_modulus=" + ",".join(str(40e3 + 2e3 * i) for i in range(n)),
             "--batch-size", "1", "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        deadline = time.monotonic() + 60
        while _count_parts(out) < 2 and time.monotonic() < deadline:
            time.sleep(0.02)
        workers[0].kill()
        written_at_kill = _count_parts(out)
        stdout, stderr = driver.communicate(timeout=120)
    assert driver.returncode == 0, stderr
    assert 2 <= written_at_kill < n, "the worker was not killed mid-sweep"
    rows = _rows(out)
    assert len(list((out / "results.parquet").glob("part-*"))) == n
    assert sorted(r["case"] for r in rows) == list(range(n))
    assert all(r["converged"] for r in rows), [r["error"] for r in rows]


def _count_parts(out: Path) -> int:
    return len(list((out / "results.parquet").glob("part-*.parquet")))


def test_interrupted_driver_resumes_without_solving_a_case_twice(scene, tmp_path, client, capsys):
    out = tmp_path / "sweep"
    n = 30
    grid = ["--grid", "cable[0].actuation=" + ",".join(f"{0.7 + 0.01 * i:.2f}" for i in range(n))]
    driver = subprocess.Popen([sys.executable, "-m", "sorofem.cli", "sweep", str(scene), "--out", str(out),
                               *grid, "--workers", "1", "--batch-size", "2", "--quiet"],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while _count_parts(out) < 2 and time.monotonic() < deadline:
        time.sleep(0.01)
    driver.send_signal(signal.SIGINT)
    _, stderr = driver.communicate(timeout=60)
    assert driver.returncode == 130, stderr
    assert "rerun the same command to resume" in stderr
    first = {p.name: p.read_bytes() for p in (out / "results.parquet").glob("part-*.parquet")}
    done = {r["case"] for r in _rows(out)}
    assert 0 < len(done) < n, "the interruption came too late to test a resume"

    assert main(["sweep", str(scene), "--out", str(out), *grid, "--scheduler", client.scheduler.address]) == 0
    printed = capsys.readouterr().out
    assert f"resuming: {len(done)} already in {out}, {n - len(done)} to solve" in printed
    assert f"solved {n - len(done)} case(s)" in printed
    # The first run's part files are untouched; the second run's hold exactly the other cases.
    for name, data in first.items():
        assert (out / "results.parquet" / name).read_bytes() == data
    pq = pytest.importorskip("pyarrow.parquet")
    second = [c for p in (out / "results.parquet").glob("part-*.parquet") if p.name not in first
              for c in pq.read_table(p).column("case").to_pylist()]
    assert sorted(second) == sorted(set(range(n)) - done)
    rows = _rows(out)
    assert [r["case"] for r in rows] == list(range(n))

    reference = tmp_path / "reference"
    sf.sweep(scene, reference, grid={"cable[0].actuation": [float(f"{0.7 + 0.01 * i:.2f}") for i in range(n)]},
             client=client)
    assert _without_timing(rows) == _without_timing(_rows(reference))


def test_a_case_that_does_not_converge_is_a_row(scene, tmp_path, client, capsys):
    out = tmp_path / "sweep"
    address = client.scheduler.address
    args = ["sweep", str(scene), "--out", str(out), "--grid", "solver.max_iterations=1,50", "--scheduler", address]
    assert main(args) == 0
    printed = capsys.readouterr()
    assert "warning: 1 of 2 case(s) did not converge" in printed.err
    failed, ok = _rows(out)
    # As `sorofem run` reports it: the iterations of every cut-back, the residual history.
    assert failed["converged"] is False and failed["error"].startswith("Newton did not converge")
    assert failed["newton_iterations"] > 1 and failed["max_displacement"] is None
    assert ok["converged"] is True and ok["error"] is None and ok["newton_iterations"] > 1
    # Nothing left to solve; --strict still reports the failure with exit 3.
    assert main([*args, "--strict"]) == 3
    printed = capsys.readouterr()
    assert "nothing to solve" in printed.out and "error: 1 of 2 case(s)" in printed.err
    # Another sweep in the same folder is refused, unless --force.
    other = ["sweep", str(scene), "--out", str(out), "--grid", "solver.max_iterations=40", "--scheduler", address]
    assert main(other) == 2
    assert "holds another sweep" in capsys.readouterr().err
    assert main([*other, "--force", "--quiet"]) == 0
    assert [r["solver.max_iterations"] for r in _rows(out)] == [40]


def test_api_result_and_markers(scene, tmp_path, client):
    run = sf.sweep(scene, tmp_path / "a", grid={"loads.gravity": [[0, 0, -9.81], [0, 0, 0]]},
                   markers=[[0.4, 0.05, 0.05], [0.2, 0.05, 0.05]], client=client, progress=False)
    assert (run.n_cases, run.solved, run.skipped, run.failed) == (2, 2, 0, 0)
    rows = run.table(pandas=False).to_pylist()
    assert rows[0]["loads.gravity"] == [0, 0, -9.81]
    sagging, pulled = rows
    # The marker at the tip's centre sags more than the one at mid-span; without gravity only the cable acts.
    assert sagging["marker[0].z"] < sagging["marker[1].z"] < 0.05
    assert pulled["marker[0].z"] > sagging["marker[0].z"]
    again = sf.sweep(scene, tmp_path / "a", grid={"loads.gravity": [[0, 0, -9.81], [0, 0, 0]]},
                     markers=[[0.4, 0.05, 0.05], [0.2, 0.05, 0.05]], client=client)
    assert (again.skipped, again.solved) == (2, 0)


def test_issue_21_batches_shrink_so_that_the_workers_finish_together():
    """Speed (issue 21): big batches first (few tasks: each costs the scheduler, the driver and a
    worker a few ms of CPU), small ones last (no worker idles while another finishes a long
    batch), in rounds of one batch per worker; every case once, one group per batch."""
    from sorofem.sweeps._run import MAX_BATCH, _batches

    # The benchmark's sweep, 200 cases on 2 workers: each batch a quarter of what is left when its round starts (at most
    # MAX_BATCH); the second round takes the last 100 evenly, since a round of quarters (25) would leave fewer than
    # two rounds of the smallest batches (200 / (8 x 2) -> 13).
    assert MAX_BATCH == 50
    assert [len(b) for b in _batches({0: list(range(200))}, set(range(200)), 2)] == [50, 50, 50, 50]
    groups = {0: list(range(60)), 1: list(range(60, 200))}
    todo = set(range(200)) - {3, 100}
    batches = _batches(groups, todo, 2)
    sizes = [len(b) for b in batches]
    assert sorted(i for b in batches for i in b) == sorted(todo)
    assert all(set(b) <= set(groups[0]) or set(b) <= set(groups[1]) for b in batches)
    # A batch cut short by the end of its group still counts in its round.
    assert sizes == [50, 9, 35, 35, 35, 34]
    # Large cases, few of them: a quarter of the sweep a batch, then the rest evenly.
    assert [len(b) for b in _batches({0: list(range(24))}, set(range(24)), 2)] == [6, 6, 6, 6]
    # Many cases on many workers: rounds that shrink from the cap to the last even round.
    sizes = [len(b) for b in _batches({0: list(range(1000))}, set(range(1000)), 8)]
    assert sizes == [50] * 8 + [38] * 8 + [37] * 8
    # A sweep with more cases than the cap allows in its first rounds: MAX_BATCH until the rounds shrink.
    assert [len(b) for b in _batches({0: list(range(398))}, set(range(398)), 2)] == [50] * 6 + [49, 49]
    assert [len(b) for b in _batches(groups, todo, 2, 64)] == [59, 64, 64, 11]


def test_issue_21_the_local_cluster_runs_its_workers_without_profiler(client):
    """Speed (issue 21): the workers of `local_cluster` get its Dask settings (the profiler off,
    slower monitors: CPU the solves need) and one thread of the core's pool each."""
    import dask

    settings = client.run(lambda: {k: dask.config.get(k) for k in sf.sweeps.LOCAL_CLUSTER_CONFIG})
    assert list(settings.values()) == [sf.sweeps.LOCAL_CLUSTER_CONFIG] * 2
    threads = str(max(1, len(os.sched_getaffinity(0)) // 2))
    assert list(client.run(lambda: os.environ.get("RAYON_NUM_THREADS")).values()) == [threads] * 2


#: SCENE's beam with its cable a tendon along the top edge, pulled 10 mm.
TENDON_SCENE = SCENE.replace("stiffness = 1e5\nactuation = 0.9", 'model = "tendon"\npull = 0.01')


def test_a_sweep_over_tendon_pulls_and_tensions(tmp_path):
    """Tendon commands swept on a LocalCluster of this test's own (127.0.0.1, closed at the end):
    one compiled model per worker serves every case, and each row is the case's own solve."""
    assert TENDON_SCENE.count('model = "tendon"') == 1
    pulled, driven = tmp_path / "pulled.toml", tmp_path / "driven.toml"
    pulled.write_text(TENDON_SCENE, encoding="utf-8")
    driven.write_text(TENDON_SCENE.replace("pull = 0.01", "tension = 1.0"), encoding="utf-8")
    pulls, tensions = [0.0, 0.01, 0.02], [0.5, 2.0]
    from dask.distributed import Client

    from sorofem.sweeps import _solve

    with sf.sweeps.local_cluster(1) as cluster, Client(cluster, set_as_default=False) as client:
        assert cluster.scheduler_address.startswith("tcp://127.0.0.1:")
        by_pull = sf.sweep(pulled, tmp_path / "pulls", grid={"cable[0].pull": pulls}, client=client, progress=False)
        by_tension = sf.sweep(driven, tmp_path / "tensions", grid={"cable[0].tension": tensions}, client=client,
                              progress=False)
        kept = client.run(lambda: len(_solve._CACHE))
    assert (by_pull.solved, by_tension.solved) == (3, 2)
    # Pull and tension are per-solve values: the worker kept one scene (and model) per scene
    # file for the five cases, not one per case.
    assert list(kept.values()) == [2]
    rows = by_pull.table(pandas=False).to_pylist() + by_tension.table(pandas=False).to_pylist()
    cases = [(pulled, "pull = 0.01", f"pull = {p!r}") for p in pulls] + [
        (driven, "tension = 1.0", f"tension = {t!r}") for t in tensions]
    for row, (path, old, new) in zip(rows, cases):
        assert row["converged"] is True and row["error"] is None
        result = sf.Scene.from_toml(path.read_text().replace(old, new), path).solve()
        assert row["newton_iterations"] == result.report.iterations
        assert row["cable[0].max_tension"] == result.cable_tension[0]
        assert [row["tip.x"], row["tip.y"], row["tip.z"]] == result.positions[row["tip.node"]].tolist()
    # Pulled by a length: the tension it takes grows with the pull; driven by a tension: it carries it.
    assert rows[0]["cable[0].max_tension"] < rows[1]["cable[0].max_tension"] < rows[2]["cable[0].max_tension"]
    assert [r["cable[0].max_tension"] for r in rows[3:]] == tensions
    assert rows[1]["tip.z"] < rows[2]["tip.z"] and rows[3]["tip.z"] < rows[4]["tip.z"]


BAD = [
    (["--grid", "material.young=1,2"], "unknown key 'young' under 'material'"),
    (["--grid", "material.youngs_modulus=abc"], "material.youngs_modulus: expected a number, got 'abc'"),
    (["--grid", "material.poisson_ratio=0.3,0.6"], "material.poisson_ratio (grid value 1): expected a number >= 0 and < 0.5, got 0.6"),
    (["--grid", "material.youngs_modulus="], "material.youngs_modulus: no values after '='"),
    (["--grid", "cable[2].actuation=0.5"], "the scene has 1 [[cable]] entry (indices 0..0), not 2"),
    (["--grid", "output.vtu=true"], "[output] is not swept"),
    (["--sample", "material.youngs_modulus=1e3:2e3"], "the number of samples is needed"),
    (["--sample", "material.youngs_modulus=2e3:1e3", "--samples", "3"], "expected finite bounds lo < hi"),
    (["--sample", "material.youngs_modulus=1e3:2e3", "--samples", "3", "--seed", "-1"],
     "seed: expected an integer from 0 to 9223372036854775807, got -1"),
    (["--grid", "mesh.file=missing.vtu"], "mesh file not found"),
    (["--grid", "material.shear_modulus=1e4"], "expected exactly one of"),
    ([], "the sweep has no case"),
    (["--grid", "material.youngs_modulus=5e4", "--marker", "2,0,0"], "markers: points: 1 point(s) lie outside"),
]


@pytest.mark.parametrize("extra, message", BAD, ids=[m for _, m in BAD])
def test_bad_input_exits_2_before_any_solve(scene, tmp_path, capsys, extra, message):
    start = time.monotonic()
    assert main(["sweep", str(scene), "--out", str(tmp_path / "out"), *extra]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and message in err, err
    assert not (tmp_path / "out").exists()
    assert time.monotonic() - start < 5


def test_an_empty_table_of_cases_exits_2(scene, tmp_path, capsys):
    table = tmp_path / "cases.csv"
    table.write_text("material.youngs_modulus,loads.gravity\n", encoding="utf-8")
    assert main(["sweep", str(scene), "--out", str(tmp_path / "out"), "--cases", str(table)]) == 2
    assert "the sweep has no case" in capsys.readouterr().err


def test_an_unreachable_scheduler_exits_2_within_10_s(scene, tmp_path, capsys):
    import socket

    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    start = time.monotonic()
    code = main(["sweep", str(scene), "--out", str(tmp_path / "out"), "--grid", "material.youngs_modulus=5e4",
                 "--scheduler", f"tcp://127.0.0.1:{port}"])
    assert code == 2 and time.monotonic() - start < 10
    assert f"could not reach a Dask scheduler at tcp://127.0.0.1:{port}" in capsys.readouterr().err
