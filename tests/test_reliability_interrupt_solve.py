"""Issue 20, item 12: Ctrl-C (and the command line's SIGTERM) during a long solve of the
compiled core stops it before its next Newton iteration, not when the solve would have ended:
`sf.Interrupted` with the report so far, exit 130/143 without a traceback, nothing written.

Promptness is judged against the same solve run to its end in the same test (its Newton
iterations and its duration), never against a fixed number of seconds."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest

import sorofem as sf
from sorofem.cli import EXIT_SIGINT, EXIT_SIGTERM
from tests.conftest import BOX_SCENE, REPO_ROOT

#: A soft cantilever under five times gravity in 24 load steps: about a hundred Newton
#: iterations of a thousand nodes, seconds in all.
CELLS = (20, 5, 5)
GRAVITY = (0.0, 0.0, -5 * 9.81)
LOAD_STEPS = 24
#: When the signal is sent, as a fraction of the uninterrupted solve's duration after the solve
#: started: early enough that the solve is certainly still running, late enough that it is
#: certainly in the extension (not in the Python lines before it).
SIGNAL_AT = 0.1

EXIT = {signal.SIGINT: EXIT_SIGINT, signal.SIGTERM: EXIT_SIGTERM}


def beam(cells: tuple[int, int, int] = CELLS) -> sf.Body:
    mesh = sf.Mesh.box(size=(0.1, 0.02, 0.02), cells=cells)
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080))
    body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    return body


def solve(body: sf.Body) -> sf.StaticResult:
    return sf.solve_static(body, GRAVITY, load_steps=LOAD_STEPS, tolerance=1e-10)


@pytest.fixture(scope="module")
def uninterrupted() -> dict:
    """The solve run to its end: Newton iterations and seconds (the model built beforehand)."""
    body = beam()
    body.core_model()
    start = time.perf_counter()
    result = solve(body)
    return {"iterations": result.report.iterations, "seconds": time.perf_counter() - start}


CHILD = """
import json, sys, time
import sorofem as sf
from tests.test_reliability_interrupt_solve import beam, solve
body = beam()
body.core_model()
print("solving", flush=True)
start = time.perf_counter()
try:
    result = solve(body)
except sf.Interrupted as err:
    print(json.dumps({"message": str(err), "signal": err.signal, "iterations": err.report.iterations,
                      "report_type": type(err.report).__name__, "seconds": time.perf_counter() - start}))
    sys.exit(130)
print(json.dumps({"message": "converged", "iterations": result.report.iterations}))
"""


def send_during_the_solve(proc: subprocess.Popen, ready, sig: int, uninterrupted: dict, stream) -> tuple[float, str]:
    """Waits until `ready()` says the solve has started, then a fraction of the uninterrupted
    solve's duration, and sends `sig`; returns the first line the process then writes on
    `stream` (its report of the interruption) and the seconds from the signal to it (the
    interpreter's exit after it, slow on a loaded machine, is not counted)."""
    while not ready():
        assert proc.poll() is None, f"the run ended before the signal: {proc.communicate()}"
        time.sleep(0.01)
    time.sleep(SIGNAL_AT * uninterrupted["seconds"])
    assert proc.poll() is None, "the solve ended before the signal"
    proc.send_signal(sig)
    sent = time.perf_counter()
    line = stream.readline()
    return time.perf_counter() - sent, line


def child_env() -> dict:
    """The child imports this module (and conftest's helpers) from the repository."""
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO_ROOT), str(REPO_ROOT / "tests")])}


def test_ctrl_c_stops_a_long_static_solve_at_the_next_newton_iteration(uninterrupted):
    assert uninterrupted["iterations"] >= 50  # a long solve, or the test proves nothing
    proc = subprocess.Popen([sys.executable, "-c", CHILD], cwd=REPO_ROOT, env=child_env(), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    marker = proc.stdout.readline()  # blocks until the solve starts
    assert marker == "solving\n", (marker, proc.communicate())
    stopped_after, line = send_during_the_solve(proc, lambda: True, signal.SIGINT, uninterrupted, proc.stdout)
    out, err = proc.communicate(timeout=60 + 10 * uninterrupted["seconds"])
    assert proc.returncode == EXIT_SIGINT, (out, err)
    assert "Traceback" not in err, err
    stopped = json.loads(line + out)
    assert stopped["signal"] == "SIGINT" and stopped["report_type"] == "SolveReport"
    assert stopped["message"].startswith("solve_static: interrupted after "), stopped["message"]
    assert f"{stopped['iterations']} Newton iterations" in stopped["message"]
    # Stopped well before the end: fewer iterations than the whole solve, and in less than half
    # the time the solve still needed when the signal came.
    assert stopped["iterations"] < uninterrupted["iterations"]
    assert stopped_after < 0.5 * (1 - SIGNAL_AT) * uninterrupted["seconds"], (stopped_after, uninterrupted)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=lambda s: signal.Signals(s).name)
def test_the_command_line_stops_a_long_static_solve_without_waiting(tmp_path, uninterrupted, sig):
    scene = tmp_path / "scene.toml"
    scene.write_text(BOX_SCENE.replace("cells = [4, 1, 1]", f"cells = {list(CELLS)}")
                     .replace("gravity = [0, 0, -9.81]", f"gravity = {list(GRAVITY)}")
                     .replace("load_steps = 1", f"load_steps = {LOAD_STEPS}")
                     .replace("tolerance = 1e-8", "tolerance = 1e-10"))
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "sorofem.cli", "run", str(scene), "--out", str(out), "--quiet"],
                            cwd=REPO_ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    stopped_after, line = send_during_the_solve(proc, (out / "summary.json").exists, sig, uninterrupted, proc.stderr)
    stdout, stderr = proc.communicate(timeout=60 + 10 * uninterrupted["seconds"])
    stderr = line + stderr
    assert proc.returncode == EXIT[sig], stderr
    name = signal.Signals(sig).name
    assert stderr.strip() == f"error: interrupted by {name}" and not stdout
    summary = json.loads((out / "summary.json").read_text())
    assert summary["complete"] is False and summary["status"] == f"interrupted by {name}"
    assert sorted(p.name for p in out.iterdir()) == ["summary.json"]  # nothing written half
    assert stopped_after < 0.5 * (1 - SIGNAL_AT) * uninterrupted["seconds"], (stopped_after, uninterrupted)


@pytest.mark.parametrize("raised", ["extension", "python"])
def test_actuate_interrupted_keeps_the_equilibria_reached(monkeypatch, raised):
    """Ctrl-C in the second solve of a path (as the extension raises it, with a report, or as
    Python does between two lines): `err.result` is the first equilibrium, and the body's
    command is left there; the path goes on from there."""
    body = beam((8, 2, 2))
    cable = sf.Cable.line((0.0, 0.002, 0.002), (1, 0, 0), 0.1, 8, stiffness=1e3)
    body.add_cable(cable)
    real = sf.static.solve_static
    calls = []

    def solve_static(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            if raised == "python":
                raise KeyboardInterrupt
            stop = sf.Interrupted("interrupted after 2 Newton iterations (relative residual 1.000e-03)", signal="SIGTERM")
            stop.report = {"iterations": 2, "residual_history": [1.0, 0.1, 1e-3], "converged": False}
            raise sf.static._interrupted("solve_static", stop, body)
        return real(*args, **kwargs)

    monkeypatch.setattr(sf.static, "solve_static", solve_static)
    path = [0.95, 0.9, 0.85]
    with pytest.raises(sf.Interrupted) as info:
        sf.actuate(body, cable, path)
    err = info.value
    assert [r.actuations[0] for r in err.result] == [0.95]
    assert body.actuations == [0.95]
    assert str(err).endswith("(actuation = 0.9, after 1 equilibrium of the path)"), str(err)
    if raised == "extension":
        assert str(err).startswith("actuate: solve_static: interrupted after 2 Newton iterations")
        assert err.signal == "SIGTERM"
        assert isinstance(err.report, sf.SolveReport) and err.report.iterations == 2
    else:
        assert str(err).startswith("actuate: interrupted (") and err.signal == "SIGINT" and err.report is None
    monkeypatch.setattr(sf.static, "solve_static", real)
    assert [r.actuations[0] for r in sf.actuate(body, cable, path[1:], initial=err.result[-1])] == path[1:]
