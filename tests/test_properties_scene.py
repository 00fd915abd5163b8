"""Property-based: scene files with hostile values, through the command line. Whatever the
file says, ``sorofem run``/``estimate`` answers with exit 0, 2 (bad input, one ``error:`` line)
or 3 (the solver failed), never 1 (a traceback), and no file it writes holds NaN or Infinity.

Each example mutates one to three keys of a valid scene (every section present) to values of
every kind (:mod:`tests.hostile`); the examples are derandomised in ``make test``.
"""

from __future__ import annotations

import contextlib
import io
import json
import tomllib
from pathlib import Path
from typing import Any

from hypothesis import event, given, settings
from hypothesis import strategies as st

from sorofem.cli import main
from tests.hostile import FLOATS, INTEGERS, STRINGS, VALUES, assert_clean_outputs

BASE = """
[mesh]
box = { size = [0.1, 0.02, 0.02], cells = [3, 1, 1], origin = [0, 0, 0] }
scale = 1.0

[material]
youngs_modulus = 66e3
poisson_ratio = 0.45
density = 1080

[formulation]
kind = "standard"

[[fixed]]
box = { min = [-1e-9, -1, -1], max = [1e-9, 1, 1] }
displacement = [0, 0, 0]

[loads]
gravity = [0, 0, -9.81]
forces = [{ nodes = [7], force = [0, 0, -0.01] }]

[solver]
tolerance = 1e-8
max_iterations = 30
load_steps = 1

[[cable]]
start = [0, 0.01, 0.01]
direction = [1, 0, 0]
length = 0.1
divisions = 3
stiffness = 1e3
actuation = 0.95

[target]
nodes = [3, 7]
positions = [[0.1, 0, -0.001], [0.1, 0.02, -0.001]]

[estimate]
params = ["shear_modulus"]
x0 = [20e3]

[output]
png = false
"""
DYNAMICS = "\n[dynamics]\ndt = 0.01\nsteps = 3\nsave_every = 1\n"


def _paths(value: Any, prefix: tuple = ()) -> list[tuple]:
    """Every key path of a parsed scene: tables, array items, leaves."""
    out = [prefix] if prefix else []
    if isinstance(value, dict):
        for k, v in value.items():
            out += _paths(v, (*prefix, k))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            out += _paths(v, (*prefix, i))
    return out


def _near(original: Any) -> st.SearchStrategy[Any]:
    """Hostile values of the original's kind half of the time (so that more scenes get past the
    type checks and reach the ranges, the mesh and the solver), any kind otherwise."""
    if isinstance(original, bool):
        same: st.SearchStrategy[Any] = st.booleans()
    elif isinstance(original, int):
        same = st.one_of(INTEGERS, st.integers(-2, 12))
    elif isinstance(original, float):
        same = st.one_of(FLOATS, st.floats(0.1, 10.0).map(lambda f: original * f))
    elif isinstance(original, str):
        same = STRINGS
    elif isinstance(original, list) and original:
        same = st.lists(_near(original[0]), min_size=len(original), max_size=len(original))
    else:
        same = VALUES
    return st.one_of(same, VALUES)


def _get(data: Any, path: tuple) -> Any:
    for key in path:
        data = data[key]
    return data


def _set(data: Any, path: tuple, value: Any) -> None:
    for key in path[:-1]:
        data = data[key]
    data[path[-1]] = value


def _toml(value: Any) -> str:
    """A value as TOML (inline tables); None (no TOML null) is left out by the caller."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return {"inf": "inf", "-inf": "-inf", "nan": "nan"}.get(repr(value), repr(value))
    if isinstance(value, str):
        return json.dumps(value)  # a TOML basic string is a JSON string
    if isinstance(value, list):
        return "[" + ", ".join(_toml(v) for v in value if v is not None) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{json.dumps(str(k))} = {_toml(v)}" for k, v in value.items() if v is not None) + " }"
    raise TypeError(value)


def _document(data: dict[str, Any]) -> str:
    return "\n".join(f"{json.dumps(k)} = {_toml(v)}" for k, v in data.items() if v is not None) + "\n"


BASE_DATA = tomllib.loads(BASE)
PATHS = _paths(BASE_DATA)
DYNAMIC_PATHS = _paths(tomllib.loads(BASE + DYNAMICS))


def _check(tmp_path: Path, text: str, command: str) -> None:
    scene = tmp_path / "scene.toml"
    scene.write_text(text, encoding="utf-8")
    out = tmp_path / "out"
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = main([command, str(scene), "--out", str(out), "--quiet"])
    event(f"{command}: exit {code}")
    assert code in (0, 2, 3), (code, err.getvalue())
    assert "Traceback" not in err.getvalue(), err.getvalue()
    if code == 2:
        assert err.getvalue().startswith("error: ") and err.getvalue().count("\n") == 1, err.getvalue()
    assert_clean_outputs(out)


@settings(max_examples=200)
@given(data=st.data())
def test_hostile_scene_values_get_a_clean_answer(tmp_path_factory, data):
    dynamic = data.draw(st.booleans(), label="dynamic")
    parsed = tomllib.loads(BASE + (DYNAMICS if dynamic else ""))
    for path in data.draw(st.lists(st.sampled_from(DYNAMIC_PATHS if dynamic else PATHS), min_size=1, max_size=3),
                          label="paths"):
        try:
            _set(parsed, path, data.draw(_near(_get(parsed, path)), label=str(path)))
        except (KeyError, IndexError, TypeError):
            pass  # an earlier mutation replaced the table this path went into
    _check(tmp_path_factory.mktemp("scene"), _document(parsed), "run")


@settings(max_examples=60)
@given(data=st.data())
def test_hostile_estimate_sections_get_a_clean_answer(tmp_path_factory, data):
    parsed = tomllib.loads(BASE)
    paths = [p for p in PATHS if p[0] in ("estimate", "target")]
    for path in data.draw(st.lists(st.sampled_from(paths), min_size=1, max_size=2), label="paths"):
        try:
            _set(parsed, path, data.draw(_near(_get(parsed, path)), label=str(path)))
        except (KeyError, IndexError, TypeError):
            pass
    _check(tmp_path_factory.mktemp("estimate"), _document(parsed), "estimate")


@settings(max_examples=40)
@given(text=st.text(max_size=300))
def test_any_text_as_a_scene_gets_a_clean_answer(tmp_path_factory, text):
    _check(tmp_path_factory.mktemp("text"), text, "run")
