"""Issue 20, interrupted runs: SIGINT, SIGTERM and SIGKILL during a static run, a dynamic run
and an estimate (command-line subprocesses, and the Python API) leave consistent outputs
marked as incomplete, and an interrupted estimate resumes to the uninterrupted result."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Callable

import meshio
import numpy as np
import pytest

import sorofem as sf
from sorofem.cli import EXIT_OK, EXIT_SIGINT, EXIT_SIGTERM, main
from sorofem.inverse import _problem
from tests.conftest import BOX_SCENE, REPO_ROOT

G = (0.0, 0.0, -9.81)
EXPECTED_EXIT = {signal.SIGINT: EXIT_SIGINT, signal.SIGTERM: EXIT_SIGTERM, signal.SIGKILL: -signal.SIGKILL}
SIGNALS = [signal.SIGINT, signal.SIGTERM, signal.SIGKILL]


def start(*args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "sorofem.cli", *args, "--quiet"], cwd=REPO_ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def wait_for(condition: Callable[[], bool], proc: subprocess.Popen, timeout: float = 60.0) -> None:
    end = time.monotonic() + timeout
    while not condition():
        assert proc.poll() is None, f"the run ended before the signal: {proc.communicate()}"
        assert time.monotonic() < end, "timed out waiting for the run to get there"
        time.sleep(0.01)


def summary_of(out: Path) -> dict:
    return json.loads((out / "summary.json").read_text())


def no_temporaries(folder: Path) -> bool:
    return not list(folder.rglob(".*.tmp-*"))


def stop(proc: subprocess.Popen, sig: int) -> str:
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == EXPECTED_EXIT[sig], err
    assert "Traceback" not in err
    return err


def records(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines() if line.endswith("}")]


# -- static run --------------------------------------------------------------------------------


@pytest.mark.parametrize("sig", SIGNALS, ids=lambda s: signal.Signals(s).name)
def test_static_run_interrupted_during_the_solve(tmp_path, sig):
    scene = tmp_path / "scene.toml"
    scene.write_text(BOX_SCENE.replace("cells = [4, 1, 1]", "cells = [48, 10, 10]"))
    out = tmp_path / "out"
    proc = start("run", str(scene), "--out", str(out))
    wait_for(lambda: (out / "summary.json").exists(), proc)
    stop(proc, sig)
    summary = summary_of(out)
    assert summary["complete"] is False
    assert summary["status"] == ("running" if sig == signal.SIGKILL else f"interrupted by {signal.Signals(sig).name}")
    assert not (out / "result.vtu").exists()
    if sig != signal.SIGKILL:
        assert no_temporaries(out)


@pytest.mark.parametrize("where", ["result.vtu", "shape.png", "convergence.png"])
def test_static_run_interrupted_while_writing_its_outputs(tmp_path, monkeypatch, capsys, where):
    """Ctrl-C at three points of the writing: the files written are whole, the summary says
    the run is incomplete, no temporary file is left."""
    from sorofem import _files

    scene = tmp_path / "scene.toml"
    scene.write_text(BOX_SCENE)
    out = tmp_path / "out"
    real = _files.os.replace

    def replace(src, dst):
        if str(dst).endswith(where):
            raise KeyboardInterrupt
        return real(src, dst)

    monkeypatch.setattr(_files.os, "replace", replace)
    assert main(["run", str(scene), "--out", str(out), "--quiet"]) == EXIT_SIGINT
    summary = summary_of(out)
    assert summary["complete"] is False and summary["status"] == "interrupted by SIGINT"
    assert not (out / where).exists() and no_temporaries(out)
    if where != "result.vtu":
        assert meshio.read(out / "result.vtu").field_data["sorofem_run_id"][0] == summary["run_id"]


# -- dynamic run -------------------------------------------------------------------------------

DYNAMIC = BOX_SCENE.replace("cells = [4, 1, 1]", "cells = [8, 2, 2]").replace(
    "[solver]", "[dynamics]\ndt = 0.002\nsteps = 30000\nmass_damping = 2.0\n\n[solver]")


@pytest.mark.parametrize("sig", SIGNALS, ids=lambda s: signal.Signals(s).name)
def test_dynamic_run_interrupted_leaves_a_readable_partial_trajectory(tmp_path, sig):
    scene = tmp_path / "scene.toml"
    scene.write_text(DYNAMIC)
    out = tmp_path / "out"
    proc = start("run", str(scene), "--out", str(out))
    wait_for(lambda: (out / "trajectory" / "frame_00010.vtu").exists() and (out / "trajectory.pvd").exists(), proc)
    stop(proc, sig)
    summary = summary_of(out)
    assert summary["complete"] is False
    listed = [line.split('file="')[1].split('"')[0] for line in (out / "trajectory.pvd").read_text().splitlines()
              if "<DataSet" in line]
    assert listed and f'sorofem_run_id="{summary["run_id"]}"' in (out / "trajectory.pvd").read_text()
    for name in listed:  # every frame the index lists is whole and this run's
        frame = meshio.read(out / name)
        assert frame.field_data["sorofem_run_id"][0] == summary["run_id"]
        assert np.all(np.isfinite(frame.points))
    if sig != signal.SIGKILL:
        assert summary["status"] == f"interrupted by {signal.Signals(sig).name}"
        assert summary["frames_written"] == len(listed) == len(list((out / "trajectory").iterdir()))
        assert 0 < summary["steps"] < 30000 and no_temporaries(out)


def test_simulate_interrupted_returns_what_was_done(tmp_path, monkeypatch):
    monkeypatch.setattr(sf.dynamics, "CHUNK_SECONDS", 1e-9)  # one step per chunk
    mesh = sf.Mesh.box(size=(0.1, 0.02, 0.02), cells=(4, 1, 1))
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080))
    body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    writer = sf.dynamics.PvdWriter(body, tmp_path, run_id=7)
    calls = []

    def frames(times, positions, cables):
        writer.add(times, positions, cables)
        calls.append(len(times))
        if len(calls) == 5:
            raise KeyboardInterrupt

    with pytest.raises(sf.Interrupted) as info:
        sf.simulate(body, 0.001, 500, gravity=G, on_frames=frames)
    partial = info.value.result
    assert isinstance(partial, sf.Trajectory) and partial.n_frames == sum(calls) == writer.n_frames == 6
    full = sf.simulate(body, 0.001, partial.iterations.size, gravity=G)
    np.testing.assert_allclose(partial.positions, full.positions, atol=1e-12)  # the same states
    assert writer.close().exists()


# -- estimate ----------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def estimate_scene(tmp_path_factory) -> Path:
    """An estimate of Young's modulus from the tip of a sagging beam, slow enough to interrupt
    (every solve in six load steps)."""
    mesh = sf.Mesh.box(size=(0.1, 0.02, 0.02), cells=(24, 6, 6))
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080))
    body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    goal = sf.solve_static(body, gravity=G, tolerance=1e-11).positions
    tip = mesh.nodes_on_plane((0.1, 0, 0), (1, 0, 0))
    text = BOX_SCENE.replace("cells = [4, 1, 1]", "cells = [24, 6, 6]").replace("load_steps = 1", "load_steps = 6")
    text = text.replace("[solver]", f"""[target]
nodes = {tip.tolist()}
positions = {np.round(goal[tip], 12).tolist()}

[estimate]
params = ["youngs_modulus"]
x0 = [2e3]

[solver]""")
    path = tmp_path_factory.mktemp("estimate") / "scene.toml"
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def uninterrupted(estimate_scene, tmp_path_factory) -> dict:
    out = tmp_path_factory.mktemp("reference")
    assert main(["estimate", str(estimate_scene), "--out", str(out), "--quiet"]) == EXIT_OK
    return summary_of(out)


@pytest.mark.parametrize("sig", SIGNALS, ids=lambda s: signal.Signals(s).name)
def test_estimate_interrupted_resumes_to_the_same_result(tmp_path, estimate_scene, uninterrupted, sig):
    out = tmp_path / "out"
    proc = start("estimate", str(estimate_scene), "--out", str(out))
    history = out / "history.jsonl"
    wait_for(lambda: history.exists() and sum(1 for r in records(history) if r["kind"] == "iteration") >= 2, proc)
    err = stop(proc, sig)
    if sig != signal.SIGKILL:
        assert "--resume" in err
    assert summary_of(out)["complete"] is False
    assert main(["estimate", str(estimate_scene), "--out", str(out), "--quiet", "--resume"]) == EXIT_OK
    resumed = summary_of(out)
    assert resumed["complete"] is True
    assert resumed["params"]["youngs_modulus"] == pytest.approx(uninterrupted["params"]["youngs_modulus"], rel=1e-8)
    assert resumed["params"]["youngs_modulus"] == pytest.approx(66e3, rel=1e-6)
    assert resumed["iterations"] == uninterrupted["iterations"]


def test_estimate_interrupted_in_python_resumes_exactly(tmp_path, monkeypatch):
    """Ctrl-C at evaluation 5 of the Python API (deterministic): the resumed least-squares fit
    takes the uninterrupted steps and ends where it ends."""
    mesh = sf.Mesh.box(size=(0.1, 0.02, 0.02), cells=(4, 1, 1))
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080))
    body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    goal = sf.solve_static(body, gravity=G, tolerance=1e-11).positions
    tip = mesh.nodes_on_plane((0.1, 0, 0), (1, 0, 0))
    target = sf.Target.nodes(tip, goal[tip])
    kwargs = dict(params=["shear_modulus", "lame_lambda"], x0=[8e3, 6e4], gravity=G, starts=[[6e4, 6e5]])
    full = sf.estimate(body, target, history_path=tmp_path / "full.jsonl", **kwargs)
    real = _problem.Problem.evaluate
    count = {"n": 0}

    def evaluate(self, *args, **kw):
        count["n"] += 1
        if count["n"] == 5:
            raise KeyboardInterrupt
        return real(self, *args, **kw)

    monkeypatch.setattr(_problem.Problem, "evaluate", evaluate)
    path = tmp_path / "history.jsonl"
    with pytest.raises(KeyboardInterrupt):
        sf.estimate(body, target, history_path=path, **kwargs)
    monkeypatch.setattr(_problem.Problem, "evaluate", real)
    resumed = sf.estimate(body, target, history_path=path, resume=True, **kwargs)
    for name in kwargs["params"]:
        assert resumed.params[name] == pytest.approx(full.params[name], rel=1e-9)
    assert [s["converged"] for s in resumed.starts] == [s["converged"] for s in full.starts]
    # The same path: iterate for iterate (each re-solved equilibrium agrees to the Newton
    # tolerance, so the last steps before the stopping test may differ by one).
    for k in range(len(full.starts)):
        a = [h for h in resumed.history if h["start"] == k]
        b = [h for h in full.history if h["start"] == k]
        assert abs(len(a) - len(b)) <= 1
        for x, y in zip(a[:-1], b[:-1]):
            assert x["iteration"] == y["iteration"]
            assert x["params"]["shear_modulus"] == pytest.approx(y["params"]["shear_modulus"], rel=1e-6)
