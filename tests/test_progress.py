"""Progress bars (sorofem.progress, drawn by rich): redrawn in place on a terminal, one final
line in a log when asked for, silent otherwise; and their use by the static solve and the
inverse problems (sf.estimate, sf.control). simulate's is in test_dynamics.py."""

from __future__ import annotations

import io
import re
import sys
import time

import numpy as np
import pytest

import sorofem as sf
from sorofem import progress
from sorofem.progress import Progress, is_enabled

ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")


class FakeTTY(io.StringIO):
    """A text stream that says it is a terminal."""

    def isatty(self) -> bool:
        return True


class BrokenStream(FakeTTY):
    def write(self, text: str) -> int:
        raise BrokenPipeError("the reader went away")


def states(text: str) -> list[str]:
    """The successive states drawn (terminal control sequences removed), non-empty ones only."""
    return [s.strip() for s in re.split(r"[\r\n]", ANSI.sub("", text)) if s.strip()]


def test_terminal_gets_a_redrawn_bar_with_count_percentage_and_times(monkeypatch) -> None:
    monkeypatch.setenv("COLUMNS", "200")
    stream = FakeTTY()
    with Progress(total=4, desc="simulate", unit="steps", stream=stream, delay=0) as bar:
        for k in range(4):
            bar.update(1, postfix=f"t={k + 1} s, 0 cutbacks")
            time.sleep(0.3)  # rich redraws 10 times a second
    drawn = states(stream.getvalue())
    assert len(drawn) >= 2
    last = drawn[-1]
    assert last.startswith("simulate") and "100%" in last and "4/4 steps" in last
    assert last.endswith("t=4 s, 0 cutbacks")  # the whole postfix, with its unit
    assert re.search(r"\d:\d\d:\d\d", last)  # elapsed (and remaining) time
    assert stream.getvalue().count("\r") >= 2  # redrawn in place
    assert ANSI.sub("", stream.getvalue()).endswith("\n")  # the final state stays on screen


def test_non_terminal_gets_nothing_when_automatic() -> None:
    stream = io.StringIO()
    with Progress(total=3, desc="simulate", stream=stream, delay=0) as bar:
        assert not bar.active
        for _ in range(3):
            bar.update()
    assert stream.getvalue() == ""
    assert bar.done == 3  # the count is kept even when nothing is drawn


def test_asked_for_in_a_log_it_writes_its_final_state_once() -> None:
    """progress=True where the stream is no terminal (a pipe, a CI log): one plain line, no
    control sequences, wide enough that a long postfix is kept whole."""
    log = io.StringIO()
    postfix = "t=0.5 s, 3.0 it/step, 0 cutbacks, " + "and a long tail " * 4 + "END"
    with Progress(total=1000, desc="simulate", unit="steps", stream=log, enabled=True) as bar:
        for _ in range(10):
            bar.update(50, postfix=postfix)
    text = log.getvalue()
    assert text.count("\n") == 1 and "\r" not in text and "\x1b" not in text
    assert "50%" in text and "500/1000 steps" in text and text.rstrip().endswith("END")


def test_disabled_forced_and_the_automatic_choice() -> None:
    tty = FakeTTY()
    with Progress(total=2, stream=tty, enabled=False) as bar:
        bar.update(2)
    assert tty.getvalue() == ""
    with Progress(total=2, stream=io.StringIO(), enabled=True) as bar:  # asked for: drawn anywhere
        assert bar.active and bar.delay == 0
    assert is_enabled(None, FakeTTY()) and not is_enabled(None, io.StringIO())
    assert is_enabled(True, io.StringIO()) and not is_enabled(False, FakeTTY())


def test_automatic_bar_waits_for_a_long_run() -> None:
    stream = FakeTTY()
    with Progress(total=10, stream=stream) as bar:  # automatic: DELAY before it appears
        assert bar.active and bar.delay == progress.DELAY
        bar.update(10)
    assert stream.getvalue() == ""  # a quick run leaves no trace
    stream = FakeTTY()
    with Progress(total=10, stream=stream, delay=0.2) as bar:
        time.sleep(0.5)
        bar.update(10)
    assert "10/10" in states(stream.getvalue())[-1]


def test_unknown_total_counts_and_shows_elapsed_time() -> None:
    stream = FakeTTY()
    with Progress(desc="estimate (least-squares)", unit="solves", stream=stream, delay=0) as bar:
        bar.update(1, postfix="it 0, loss 1.2e-03 m^2")
        bar.update(5)
    last = states(stream.getvalue())[-1]
    assert re.fullmatch(r"estimate \(least-squares\) 6 solves 0:00:0\d it 0, loss 1\.2e-03 m\^2", last), last
    assert "%" not in last and "?" not in last


def test_a_narrow_terminal_wraps_the_postfix_instead_of_cutting_it(monkeypatch) -> None:
    monkeypatch.setenv("COLUMNS", "60")
    stream = FakeTTY()
    with Progress(total=1000, desc="simulate", unit="steps", stream=stream, delay=0) as bar:
        bar.set(500, postfix="t=0.5 s, 3.0 it/step, 0 cutbacks")
    final = ANSI.sub("", stream.getvalue()).split("\r")[-1]
    assert max(len(line) for line in final.splitlines()) <= 60
    assert " ".join(final.split()).endswith("t=0.5 s, 3.0 it/step, 0 cutbacks")


def test_zero_total_and_overshoot_do_not_break() -> None:
    stream = FakeTTY()
    with Progress(total=0, stream=stream, delay=0) as bar:
        bar.update(3)
    with Progress(total=2, stream=stream, delay=0) as bar:
        bar.update(5)
    assert "5/2" in states(stream.getvalue())[-1]


def test_broken_stream_never_raises() -> None:
    with Progress(total=3, stream=BrokenStream(), delay=0) as bar:
        bar.update(1)
        time.sleep(0.2)  # rich's refresh thread writes too
        bar.update(2)
        bar.print("a message")
    Progress(stream=BrokenStream(), enabled=False).print("a message")


def test_print_writes_above_the_bar() -> None:
    stream = FakeTTY()
    with Progress(total=2, stream=stream, delay=0) as bar:
        bar.update(1)
        bar.print("[it 1] loss 1e-3")
    drawn = states(stream.getvalue())
    assert "[it 1] loss 1e-3" in drawn
    assert drawn.index("[it 1] loss 1e-3") < len(drawn) - 1 and "2" in drawn[-1]  # the bar is drawn below it
    plain = io.StringIO()
    Progress(stream=plain).print("verbose line")  # inactive: a plain line
    assert plain.getvalue() == "verbose line\n"


def test_default_context_changes_the_automatic_choice() -> None:
    with progress.default(False):
        assert not Progress(stream=FakeTTY()).active
        bar = Progress(stream=FakeTTY(), enabled=True)  # an explicit argument wins
        assert bar.active
        bar.close()
    with progress.default(True):
        bar = Progress(stream=io.StringIO())
        assert bar.active and bar.delay == 0
        bar.close()
    bar = Progress(stream=FakeTTY())
    assert bar.active  # back to automatic
    bar.close()


def test_the_description_can_change_while_running() -> None:
    stream = FakeTTY()
    with Progress(stream=stream, delay=0, desc="estimate") as bar:
        bar.desc = "estimate start 2/2"
        bar.update(1)
    assert states(stream.getvalue())[-1].startswith("estimate start 2/2 1")


# -- the solvers and inverse problems ----------------------------------------------------


def _cantilever(cable: bool = False) -> sf.Body:
    mesh = sf.Mesh.box(size=(0.4, 0.1, 0.1), cells=(4, 2, 2))
    body = sf.Body(mesh, sf.NeoHookean(shear_modulus=22.76e3, lame_lambda=0.2048e6, density=1080))
    body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    if cable:
        body.add_cable(sf.Cable.line((0.0, 0.02, 0.02), (1, 0, 0), 0.4, 8, stiffness=2e3))
    return body


G = (0.0, 0.0, -9.81)


def test_estimate_reports_solves_and_the_objective(capsys) -> None:
    body = _cantilever()
    goal = sf.solve_static(body, G).positions
    target = sf.Target.nodes(np.arange(body.mesh.n_nodes), goal)
    quiet = sf.estimate(body, target, ["shear_modulus", "lame_lambda"], x0=[20e3, 0.3e6], gravity=G, progress=False,
                        profile=False)
    assert capsys.readouterr().err == ""
    fit = sf.estimate(body, target, ["shear_modulus", "lame_lambda"], x0=[20e3, 0.3e6], gravity=G, progress=True,
                      profile=False)
    lines = states(capsys.readouterr().err)
    assert len(lines) == 1  # stderr is no terminal: the final state, once
    last = lines[0]
    assert last.startswith(f"estimate (least-squares) {fit.forward_solves - len(fit.results)} solves")
    assert f"it {fit.iterations}, loss " in last and re.search(r"rms \S+ m$", last)
    assert fit.params == pytest.approx(quiet.params, rel=1e-12)  # the bar changes nothing
    assert fit.forward_solves == quiet.forward_solves


def test_estimate_verbose_lines_go_above_the_bar(capsys) -> None:
    body = _cantilever()
    goal = sf.solve_static(body, G).positions
    target = sf.Target.nodes(np.arange(body.mesh.n_nodes), goal)
    sf.estimate(body, target, ["shear_modulus"], x0=[20e3], gravity=G, verbose=True, progress=True,
                method="l-bfgs-b", starts=[[25e3]])
    lines = states(capsys.readouterr().err)
    verbose = [k for k, line in enumerate(lines) if line.startswith("[start")]
    assert len(verbose) >= 2 and verbose[-1] < len(lines) - 1
    assert lines[-1].startswith("estimate (l-bfgs-b) start 2/2 ")


def test_control_progress(capsys) -> None:
    body = _cantilever(cable=True)
    body.set_actuation(0, 0.6)
    goal = sf.solve_static(body, G).positions
    body.set_actuation(0, 1.0)
    tip = body.mesh.nodes_on_plane((0.4, 0, 0), (1, 0, 0))
    ctl = sf.control(body, sf.Target.nodes(tip, goal[tip]), gravity=G, progress=True)
    assert states(capsys.readouterr().err)[-1].startswith("control (l-bfgs-b) ")
    assert ctl.actuation == pytest.approx([0.6], rel=1e-4)
    sf.control(body, sf.Target.nodes(tip, goal[tip]), gravity=G)  # automatic: pytest's stderr is no terminal
    assert capsys.readouterr().err == ""


def test_stderr_is_looked_up_when_the_bar_is_created(monkeypatch) -> None:
    fake = FakeTTY()
    monkeypatch.setattr(sys, "stderr", fake)
    monkeypatch.setattr(progress, "DELAY", 0.0)
    with Progress(total=1) as bar:
        bar.update()
    assert "100%" in fake.getvalue()


def test_static_solve_shows_iterations_with_plurals_right(monkeypatch) -> None:
    monkeypatch.setenv("COLUMNS", "200")  # a wide terminal: one line
    stream = FakeTTY()
    monkeypatch.setattr(sys, "stderr", stream)
    body = _cantilever()
    result = sf.solve_static(body, gravity=(0, 0, -9.81), progress=True)
    last = states(stream.getvalue())[-1]
    assert last.startswith("static solve") and last.endswith(
        f"{result.report.iterations} Newton iterations, 1 load step, 0 cutbacks")
    stream = FakeTTY()
    monkeypatch.setattr(sys, "stderr", stream)
    sf.solve_static(body, gravity=(0, 0, -9.81))  # automatic: a quick solve prints nothing
    assert stream.getvalue() == ""
