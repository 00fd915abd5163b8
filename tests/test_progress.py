"""The progress line (sorofem.progress): drawn in place on a terminal, silent elsewhere; and its
use by the inverse problems (sf.estimate, sf.control). simulate's is in test_dynamics.py."""

from __future__ import annotations

import io
import sys
import time

import numpy as np
import pytest

import sorofem as sf
from sorofem import progress
from sorofem.progress import Progress, format_duration, is_enabled


class FakeTTY(io.StringIO):
    """A text stream that says it is a terminal."""

    def isatty(self) -> bool:
        return True


class BrokenStream(FakeTTY):
    def write(self, text: str) -> int:
        raise BrokenPipeError("the reader went away")


def _draws(text: str) -> list[str]:
    """The successive states of the line (what follows each carriage return)."""
    return [part.rstrip("\n").rstrip() for part in text.split("\r")[1:]]


def test_tty_gets_carriage_return_updates_and_a_final_newline() -> None:
    stream = FakeTTY()
    with Progress(total=4, desc="simulate", unit="steps", stream=stream, delay=0, refresh=None) as bar:
        for k in range(4):
            bar.update(1, postfix=f"t={k + 1} s")
            time.sleep(progress.MIN_INTERVAL * 1.2)  # every update is due
    text = stream.getvalue()
    assert text.startswith("\r") and text.endswith("\n") and text.count("\n") == 1
    draws = _draws(text)
    assert len(draws) >= 4
    assert "1/4 steps" in draws[0] and "25%" in draws[0]
    assert draws[-1].startswith("simulate 100%|") and "4/4 steps" in draws[-1] and "t=4 s" in draws[-1]
    assert "<0:00]" in draws[-1]  # elapsed < ETA, and nothing left at the end


def test_non_tty_stream_gets_nothing() -> None:
    stream = io.StringIO()
    with Progress(total=3, desc="simulate", stream=stream, delay=0) as bar:
        assert not bar.active
        for _ in range(3):
            bar.update()
    assert stream.getvalue() == ""
    assert bar.done == 3  # the count is kept even when nothing is drawn


def test_disabled_and_forced() -> None:
    tty, plain = FakeTTY(), io.StringIO()
    with Progress(total=2, stream=tty, enabled=False) as bar:
        bar.update(2)
    assert tty.getvalue() == ""
    with Progress(total=2, stream=plain, enabled=True, refresh=None) as bar:  # asked for: drawn anywhere
        assert bar.delay == 0
        bar.update(2)
    assert plain.getvalue().startswith("\r") and plain.getvalue().endswith("\n")
    assert is_enabled(None, FakeTTY()) and not is_enabled(None, io.StringIO())
    assert is_enabled(True, io.StringIO()) and not is_enabled(False, FakeTTY())


def test_automatic_line_waits_for_a_long_run() -> None:
    stream = FakeTTY()
    with Progress(total=10, stream=stream, refresh=None) as bar:  # automatic: DELAY before the first draw
        assert bar.active and bar.delay == progress.DELAY
        bar.update(10)
    assert stream.getvalue() == ""  # a quick run leaves no trace


def test_unknown_total_counts_and_shows_elapsed_time() -> None:
    stream = FakeTTY()
    with Progress(desc="estimate (least-squares)", unit="solves", stream=stream, delay=0, refresh=None) as bar:
        bar.update(1, postfix="it 0, loss 1.2e-03")
        bar.update(5)
    last = _draws(stream.getvalue())[-1]
    assert last.startswith("estimate (least-squares) 6 solves [0:00]") and last.endswith("loss 1.2e-03")
    assert "%" not in last and "<" not in last
    assert stream.getvalue().endswith("\n")


def test_zero_total_and_overshoot_do_not_break() -> None:
    stream = FakeTTY()
    with Progress(total=0, stream=stream, delay=0, refresh=None) as bar:
        bar.update(3)
    with Progress(total=2, stream=stream, delay=0, refresh=None) as bar:
        bar.update(5)
        assert "100%" in bar.line()


def test_line_fits_the_width_and_shrinks_the_bar() -> None:
    bar = Progress(total=1000, desc="simulate", unit="steps", enabled=False)
    bar.set(500, postfix="t=0.5 s, 3.0 it/step, 0 cutbacks")
    for width in (40, 80, 120, 200):
        line = bar.line(width)
        assert len(line) <= width - 1
    assert bar.line(200).count("#") == 15 and bar.line(200).count("-") == 15  # 30 wide, half done
    assert "|##---|" in bar.line(80)  # at 80 columns the bar is 5 wide


def test_a_previous_longer_line_is_blanked() -> None:
    stream = FakeTTY()
    with Progress(desc="x", stream=stream, delay=0, refresh=None) as bar:
        bar.set(1, postfix="a long text " * 3)
        time.sleep(progress.MIN_INTERVAL * 1.2)
        bar.set(2, postfix="short")
    first, second = stream.getvalue().split("\r")[1:3]
    assert len(second) >= len(first)  # padded with spaces over the old text


def test_broken_stream_never_raises() -> None:
    with Progress(total=3, stream=BrokenStream(), delay=0, refresh=None) as bar:
        bar.update(1)
        assert not bar.active
        bar.update(2)
        bar.print("a message")


def test_background_refresh_moves_the_clock_during_a_long_call() -> None:
    stream = FakeTTY()
    bar = Progress(total=5, stream=stream, delay=0, refresh=0.05)
    time.sleep(0.4)  # no update: one long call
    bar.close()
    assert len(_draws(stream.getvalue())) >= 3
    assert bar._ticker is not None and not bar._ticker.is_alive()
    assert stream.getvalue().endswith("\n")


def test_print_writes_above_the_line() -> None:
    stream = FakeTTY()
    with Progress(total=2, stream=stream, delay=0, refresh=None) as bar:
        bar.update(1)
        bar.print("[it 1] loss 1e-3")
    text = stream.getvalue()
    assert "\r[it1]loss1e-3\n\r" in text.replace(" ", "")  # cleared, printed, redrawn
    assert text.endswith("\n")
    plain = io.StringIO()
    Progress(stream=plain).print("verbose line")  # inactive: a plain line
    assert plain.getvalue() == "verbose line\n"


def test_default_context_changes_the_automatic_choice() -> None:
    with progress.default(False):
        assert not Progress(stream=FakeTTY()).active
        assert Progress(stream=FakeTTY(), enabled=True, refresh=None).active  # an explicit argument wins
    with progress.default(True):
        bar = Progress(stream=io.StringIO(), refresh=None)
        assert bar.active and bar.delay == 0
    assert Progress(stream=FakeTTY(), refresh=None).active  # back to automatic


def test_format_duration() -> None:
    assert format_duration(0) == "0:00"
    assert format_duration(75.4) == "1:15"
    assert format_duration(3725) == "1:02:05"
    assert format_duration(float("nan")) == "?" and format_duration(-1) == "?"


# -- the inverse problems --------------------------------------------------------------


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
    quiet = sf.estimate(body, target, ["shear_modulus", "lame_lambda"], x0=[20e3, 0.3e6], gravity=G, progress=False)
    assert capsys.readouterr().err == ""
    fit = sf.estimate(body, target, ["shear_modulus", "lame_lambda"], x0=[20e3, 0.3e6], gravity=G, progress=True)
    err = capsys.readouterr().err
    assert err.startswith("\r") and err.endswith("\n")
    last = _draws(err)[-1]
    assert last.startswith("estimate (least-squares) ") and " solves [" in last and "loss " in last
    assert f"it {fit.iterations}" in last
    assert fit.params == pytest.approx(quiet.params, rel=1e-12)  # the line changes nothing
    assert fit.forward_solves == quiet.forward_solves


def test_estimate_verbose_lines_go_above_the_progress_line(capsys) -> None:
    body = _cantilever()
    goal = sf.solve_static(body, G).positions
    target = sf.Target.nodes(np.arange(body.mesh.n_nodes), goal)
    sf.estimate(body, target, ["shear_modulus"], x0=[20e3], gravity=G, verbose=True, progress=True,
                method="l-bfgs-b", starts=[[25e3]])
    err = capsys.readouterr().err
    verbose = [line for line in err.split("\n") if "[start" in line]
    assert len(verbose) >= 2 and all(line.split("\r")[-1].startswith("[start") for line in verbose)
    assert "start 2/2" in err


def test_control_progress(capsys) -> None:
    body = _cantilever(cable=True)
    body.set_actuation(0, 0.6)
    goal = sf.solve_static(body, G).positions
    body.set_actuation(0, 1.0)
    tip = body.mesh.nodes_on_plane((0.4, 0, 0), (1, 0, 0))
    ctl = sf.control(body, sf.Target.nodes(tip, goal[tip]), gravity=G, progress=True)
    err = capsys.readouterr().err
    assert _draws(err)[-1].startswith("control (l-bfgs-b) ") and err.endswith("\n")
    assert ctl.actuation == pytest.approx([0.6], rel=1e-4)
    sf.control(body, sf.Target.nodes(tip, goal[tip]), gravity=G)  # automatic: pytest's stderr is no terminal
    assert capsys.readouterr().err == ""


def test_stderr_is_looked_up_when_the_line_is_created(monkeypatch) -> None:
    fake = FakeTTY()
    monkeypatch.setattr(sys, "stderr", fake)
    monkeypatch.setattr(progress, "DELAY", 0.0)
    with Progress(total=1, refresh=None) as bar:
        bar.update()
    assert fake.getvalue().endswith("\n") and "100%" in fake.getvalue()


def test_static_solve_line_shows_elapsed_time_and_iterations(monkeypatch) -> None:
    stream = FakeTTY()
    monkeypatch.setattr(sys, "stderr", stream)
    body = _cantilever()
    result = sf.solve_static(body, gravity=(0, 0, -9.81), progress=True)
    text = stream.getvalue()
    assert "static solve" in text and f"{result.report.iterations} Newton iterations" in text
    assert text.endswith("\n")
    stream = FakeTTY()
    monkeypatch.setattr(sys, "stderr", stream)
    sf.solve_static(body, gravity=(0, 0, -9.81))  # automatic: a quick solve prints nothing
    assert stream.getvalue() == ""
