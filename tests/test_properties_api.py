"""Property-based: the public API with hostile arguments. Every call either works, and then
its result holds finite numbers only, or raises one of sorofem's errors (an
:class:`~sorofem.InputError` naming the argument, a :class:`~sorofem.SolverError`), never a
library's exception (TypeError, ZeroDivisionError, OverflowError, MemoryError, a panic).

One argument at a time is made hostile (:mod:`tests.hostile`), the others stay valid, so every
argument's check is reached.
"""

from __future__ import annotations

import math
import os
import tempfile
from pathlib import Path
from typing import Any, Callable

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

import sorofem as sf
from sorofem.io import json_text
from tests.hostile import FLOATS, INTEGERS, STRINGS, VALUES, VECTORS, sorofem_errors

G = (0.0, 0.0, -9.81)
HOSTILE = st.one_of(VALUES, VECTORS, INTEGERS, FLOATS, STRINGS)


def body(cables: bool = False) -> sf.Body:
    mesh = sf.Mesh.box(size=(0.1, 0.02, 0.02), cells=(2, 1, 1))
    b = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080))
    b.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    if cables:
        b.add_cable(sf.Cable.line((0, 0.01, 0.01), (1, 0, 0), 0.1, 2, stiffness=1e3, actuation=0.95))
    return b


TARGET = sf.Target.nodes([2, 5], [[0.1, 0, -0.001], [0.1, 0.02, -0.001]])


def _in_scratch(call: Callable[[], Any]) -> Any:
    """``call()`` with a scratch folder as the working directory (relative names land there)."""
    scratch = Path(tempfile.gettempdir()) / "sorofem-property"
    scratch.mkdir(exist_ok=True)
    cwd = os.getcwd()
    os.chdir(scratch)
    try:
        return call()
    finally:
        os.chdir(cwd)


def finite(value: Any) -> bool:
    """Every number reachable in ``value`` (results, their arrays and dicts) is finite."""
    if isinstance(value, (float, np.floating)):
        return math.isfinite(value)
    if isinstance(value, np.ndarray):
        return value.dtype.kind not in "fc" or bool(np.all(np.isfinite(value)))
    if isinstance(value, dict):
        return all(finite(v) for v in value.values())
    if isinstance(value, (list, tuple)):
        return all(finite(v) for v in value)
    return True


def check_result(result: Any) -> None:
    if result is None:
        return
    if isinstance(result, sf.StaticResult):
        assert finite([result.positions, result.J, result.von_mises, result.to_dict()])
    elif isinstance(result, sf.Trajectory):
        assert finite([result.positions, result.kinetic_energy, result.velocities, result.to_dict()])
    elif isinstance(result, sf.Mesh):
        assert finite(result.points) and np.all(result.volumes > 0)
    elif hasattr(result, "to_dict"):
        json_text(result.to_dict())  # no NaN can reach a summary


#: Each public function with valid arguments; the property replaces one of them.
CALLS: dict[str, tuple[Callable[..., Any], dict[str, Any]]] = {
    "Mesh.box": (sf.Mesh.box, {"size": (0.1, 0.02, 0.02), "cells": (2, 1, 1), "origin": (0, 0, 0)}),
    "Mesh": (sf.Mesh, {"points": [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], "tets": [[0, 1, 2, 3]],
                       "orientation": "reorient"}),
    "Mesh.scaled": (lambda factor: sf.Mesh.box().scaled(factor), {"factor": 2.0}),
    "Mesh.nodes_on_plane": (lambda point, normal, tol: sf.Mesh.box().nodes_on_plane(point, normal, tol),
                            {"point": (0, 0, 0), "normal": (1, 0, 0), "tol": 1e-9}),
    "Mesh.nodes_in_box": (lambda lo, hi: sf.Mesh.box().nodes_in_box(lo, hi), {"lo": (0, 0, 0), "hi": (1, 1, 1)}),
    "NeoHookean": (lambda **kw: sf.NeoHookean(**kw), {"youngs_modulus": 66e3, "poisson_ratio": 0.45, "density": 1080}),
    "Cable.line": (lambda start, direction, length, divisions, stiffness, actuation:
                   sf.Cable.line(start, direction, length, divisions, stiffness=stiffness, actuation=actuation),
                   {"start": (0, 0.01, 0.01), "direction": (1, 0, 0), "length": 0.1, "divisions": 2,
                    "stiffness": 1e3, "actuation": 0.9}),
    "Body.fix": (lambda nodes, displacement: body().fix(nodes, displacement), {"nodes": [5], "displacement": (0, 0, 0)}),
    "Body.add_force": (lambda nodes, force: body().add_force(nodes, force), {"nodes": [5], "force": (0, 0, -1)}),
    "solve_static": (lambda gravity, tolerance, max_iterations, load_steps:
                     sf.solve_static(body(), gravity, tolerance=tolerance, max_iterations=max_iterations,
                                     load_steps=load_steps),
                     {"gravity": G, "tolerance": 1e-8, "max_iterations": 30, "load_steps": 1}),
    "simulate": (lambda dt, steps, gravity, damping, save_every, actuation:
                 sf.simulate(body(cables=True), dt, steps, actuation=actuation, gravity=gravity, damping=damping,
                             save_every=save_every),
                 {"dt": 0.01, "steps": 3, "gravity": G, "damping": (0.0, 0.0), "save_every": 1, "actuation": None}),
    "actuate": (lambda alphas, max_step: sf.actuate(body(cables=True), 0, alphas, G, max_step=max_step),
                {"alphas": 0.9, "max_step": 0.1}),
    "estimate": (lambda params, x0, bounds, method, starts, max_evaluations, regularization:
                 sf.estimate(body(), TARGET, params, x0, bounds=bounds, method=method, starts=starts,
                             max_evaluations=max_evaluations, regularization=regularization, gravity=G),
                 {"params": ["shear_modulus"], "x0": [20e3], "bounds": None, "method": "least-squares", "starts": None,
                  "max_evaluations": 20, "regularization": 0.0}),
    "control": (lambda cables, bounds, x0, tolerance, max_evaluations:
                sf.control(body(cables=True), TARGET, cables, bounds, x0, tolerance=tolerance,
                           max_evaluations=max_evaluations, gravity=G),
                {"cables": [0], "bounds": [(0.5, 1.0)], "x0": None, "tolerance": 1e-3, "max_evaluations": 10}),
    "control(dynamics=)": (lambda dt, steps, keyframe_times, reach_time, damping, x0:
                           sf.control(body(cables=True), TARGET, [0], [(0.5, 1.0)], x0, gravity=G, max_evaluations=3,
                                      dynamics={"dt": dt, "steps": steps, "keyframe_times": keyframe_times,
                                                "reach_time": reach_time, "damping": damping}),
                           {"dt": 0.01, "steps": 3, "keyframe_times": [0.01, 0.02], "reach_time": 0.02,
                            "damping": (1.0, 0.0), "x0": None}),
    "gradient": (lambda params, gravity: sf.gradient(body(), TARGET, params, gravity), {"params": ["shear_modulus"],
                                                                                         "gravity": G}),
    "Target.nodes": (lambda nodes, positions: sf.Target.nodes(nodes, positions).bind(body().mesh),
                     {"nodes": [2], "positions": [[0.1, 0, 0]]}),
    "Target.points": (lambda points, positions: sf.Target.points(points, positions).bind(body().mesh),
                      {"points": [[0.05, 0.01, 0.01]], "positions": [[0.05, 0.01, 0.0]]}),
    "SolveOptions": (lambda **kw: sf.SolveOptions(**kw), {"tolerance": 1e-8, "max_iterations": 50, "load_steps": 1}),
    "Mesh.transformed": (lambda axes: sf.Mesh.box().transformed(axes), {"axes": ["x", "-z", "y"]}),
    "Keyframes": (lambda points: sf.dynamics.Keyframes(points), {"points": [[0.0, 1.0], [0.5, 0.8]]}),
    "Target.surface": (lambda scale, rest_scale: sf.Target.surface(
        sf.io.Surface(np.array([[0.0, 0, 0], [0.1, 0, 0], [0, 0.02, 0]]), np.array([[0, 1, 2]])), scale,
        rest_scale=rest_scale).bind(body().mesh), {"scale": 1.0, "rest_scale": None}),
    "io.write_mesh": (lambda path: _in_scratch(lambda: sf.io.write_mesh(path, sf.Mesh.box())), {"path": "box.tet"}),
    "Cable": (lambda points, stiffness, actuation, transition: sf.Cable(points, stiffness=stiffness,
                                                                       actuation=actuation, transition=transition),
              {"points": [[0, 0.01, 0.01], [0.1, 0.01, 0.01]], "stiffness": 1e3, "actuation": 0.9,
               "transition": 0.05}),
}


@settings(max_examples=500)
@given(name=st.sampled_from(sorted(CALLS)), data=st.data())
def test_public_functions_answer_hostile_arguments_cleanly(name, data):
    function, valid = CALLS[name]
    argument = data.draw(st.sampled_from(sorted(valid)), label="argument")
    kwargs = {**valid, argument: data.draw(HOSTILE, label=argument)}
    check_result(sorofem_errors(lambda: function(**kwargs)))


@settings(max_examples=30)
@given(value=st.one_of(FLOATS, st.integers(-3, 3)), when=st.integers(0, 2))
def test_user_callables_that_fail_or_return_garbage_are_named(value, when):
    def schedule(t: float) -> Any:
        if when == 0:
            return value
        if when == 1:
            return 1.0 / (value - value)  # ZeroDivisionError or NaN
        return [value, "x"]

    b = body(cables=True)
    check_result(sorofem_errors(lambda: sf.simulate(b, 0.01, 2, actuation=schedule)))
    check_result(sorofem_errors(lambda: sf.gradient(body(), lambda x: (value, schedule(0.0)), ["shear_modulus"], G)))
