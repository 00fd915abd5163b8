"""Scenes in time for ``sorofem estimate`` and ``sorofem control``: a ``[target]`` given as a
recorded motion (``tracks``, ``tracks_file``), ``[control]`` keyframes (``keyframe_times``,
``reach_time``) and the Rayleigh coefficients in ``[estimate] params``, each checked against
``[dynamics]``; and the ``dynamics=`` arguments of :func:`sorofem.estimate` and
:func:`sorofem.control` that a scene with ``[dynamics]`` stands for.

The times of a scene in time are frames of ``[dynamics]``: ``t = k dt`` with ``k`` from 0 to
``steps`` (to 1e-9 relative, as :func:`sorofem.estimate` matches them).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from ..body import Body
from ..errors import InputError
from ..inverse import MOTION_PARAMETERS
from ..materials import MODELS
from ..targets import Target
from ._build import existing_file, observed_rest
from ._spec import Checker

__all__ = ["TRACK_COLUMNS", "read_tracks", "build_tracks", "check_estimate", "check_schedule", "estimate_dynamics",
           "control_dynamics"]

#: The columns of a ``[target] tracks_file`` table (any order, named by its header line), and
#: of each ``tracks`` row (in this order): time (s), marker (0-based index into nodes or
#: points), position (m).
TRACK_COLUMNS = ("time", "marker", "x", "y", "z")
#: Parameters fitted per element: a fit to motion takes scalars only.
_FIELDS = tuple(dict.fromkeys(n for model in MODELS.values() for n in model.estimable() if n.endswith("_field")))


def _frame(t: float, dt: float) -> int:
    """The frame ``k`` with ``k dt = t`` to 1e-9 relative, or -1."""
    k = round(t / dt)
    return k if abs(k * dt - t) <= 1e-9 * max(1.0, abs(t)) else -1


def read_tracks(check: Checker, file: Path, key: str) -> tuple[np.ndarray, list[str]]:
    """The rows ``(r, 5)`` of a tracks table in :data:`TRACK_COLUMNS` order, and where each
    row is (``"tracks.csv line 7"``) for messages.

    The file is text: values separated by commas or whitespace, ``#`` comments, a header line
    naming the columns first.
    """
    try:
        text = file.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise check.error(key, f"{file}: not a UTF-8 text table") from None
    lines = [(n, line.split("#", 1)[0].replace(",", " ").split()) for n, line in enumerate(text.splitlines(), 1)]
    lines = [(n, words) for n, words in lines if words]
    expected = f"a header line naming the columns {', '.join(TRACK_COLUMNS)} (any order)"
    if not lines:
        raise check.error(key, f"{file} is empty: expected {expected}, then one row per marker and frame")
    header = [word.lower() for word in lines[0][1]]
    missing = [c for c in TRACK_COLUMNS if c not in header]
    unknown = [c for c in header if c not in TRACK_COLUMNS]
    if missing or unknown or len(set(header)) != len(header):
        problem = (f"missing column(s) {', '.join(missing)}" if missing else
                   f"unknown column(s) {', '.join(unknown)}" if unknown else "a column named twice")
        raise check.error(key, f"{file}: {problem}: expected {expected}, got the header {', '.join(header)}")
    order = [header.index(c) for c in TRACK_COLUMNS]
    rows, where = [], []
    for n, words in lines[1:]:
        here = f"{file.name} line {n}"
        if len(words) != len(header):
            raise check.error(key, f"{here}: expected {len(header)} values ({', '.join(header)}), got {len(words)}")
        try:
            values = [float(w) for w in words]
        except ValueError:
            raise check.error(key, f"{here}: expected numbers, got {' '.join(words)}") from None
        if not all(math.isfinite(v) for v in values):
            raise check.error(key, f"{here}: expected finite numbers, got {' '.join(words)}")
        rows.append([values[i] for i in order])
        where.append(here)
    if not rows:
        raise check.error(key, f"{file}: no rows after the header: expected one row per marker and frame")
    return np.array(rows, dtype=np.float64), where


def build_tracks(check: Checker, table: dict[str, Any], dynamics: dict[str, Any] | None, body: Body,
                 base: Path) -> tuple[list[tuple[float, Target]], list[Path]]:
    """``[target]`` nodes or points with ``tracks`` or ``tracks_file`` as the marker tracks of
    :func:`sorofem.estimate` (``[(time, Target), ...]``, one per frame with a marker seen, in
    time order), and the file read."""
    key = "target.tracks_file" if "tracks_file" in table else "target.tracks"
    if dynamics is None:
        raise check.error(key, "a recorded motion needs a [dynamics] table: its dt and steps are the frames the "
                          "times must fall on")
    files: list[Path] = []
    if "tracks_file" in table:
        file = existing_file(check, key, table["tracks_file"], base, "tracks file")
        rows, where = read_tracks(check, file, key)
        files.append(file)
    else:
        rows = np.array(table["tracks"], dtype=np.float64)
        where = [f"item [{i}]" for i in range(len(rows))]
    kind = "nodes" if "nodes" in table else "points"
    rest = observed_rest(check, table, body)
    count = len(rest)
    dt, steps = dynamics["dt"], dynamics["steps"]
    end = dt * steps
    seen: dict[tuple[int, int], str] = {}
    by_frame: dict[int, dict[int, np.ndarray]] = {}
    for (t, marker, *position), here in zip(rows, where):
        if not (marker.is_integer() and 0 <= marker < count):
            raise check.error(key, f"{here}: expected a marker from 0 to {count - 1} (an entry of '{kind}'), got "
                              f"{marker:g}")
        if t < 0 or t > end * (1 + 1e-9):
            raise check.error(key, f"{here}: the time {t:g} s is outside the run of [dynamics], 0 to dt * steps = "
                              f"{end:g} s")
        frame = _frame(t, dt)
        if frame < 0:
            raise check.error(key, f"{here}: the time {t:g} s is not a frame of [dynamics]: expected a multiple of "
                              f"dt = {dt:g} s")
        m = int(marker)
        if (frame, m) in seen:
            raise check.error(key, f"{here}: marker {m} is already given at t = {t:g} s ({seen[frame, m]})")
        seen[frame, m] = here
        by_frame.setdefault(frame, {})[m] = np.array(position)
    tracks = []
    try:
        if kind == "points":  # every marker inside the mesh, whether seen or not
            Target.points(rest, rest).bind(body.mesh)
        for frame in sorted(by_frame):
            markers = sorted(by_frame[frame])
            positions = np.array([by_frame[frame][m] for m in markers])
            observed = rest[markers]
            target = Target.nodes(observed, positions) if kind == "nodes" else Target.points(observed, positions)
            tracks.append((frame * dt, target))
    except InputError as exc:
        raise check.error(f"target.{kind}", str(exc)) from None
    return tracks, files


def check_estimate(check: Checker, table: dict[str, Any], dynamics: dict[str, Any] | None) -> None:
    """``[estimate]`` params that only a fit to motion takes (the Rayleigh coefficients and a
    cable's dashpot) need ``[dynamics]``; their starts are > 0 (they are fitted as logarithms),
    their bounds >= 0."""
    for i, name in enumerate(table["params"]):
        if name not in MOTION_PARAMETERS:
            continue
        if dynamics is None:
            raise check.error("estimate.params", f"{name!r} is fitted to a recorded motion: it needs a [dynamics] table "
                              "and [target] tracks or tracks_file")
        if i < len(table["x0"]) and not (isinstance(table["x0"][i], float) and table["x0"][i] > 0):
            raise check.error("estimate.x0", f"expected a start > 0 for {name!r} (a damping coefficient is fitted as "
                              f"its logarithm), got {table['x0'][i]}")
        bounds = table["bounds"]
        if bounds is not None and i < len(bounds) and bounds[i][0] < 0:
            raise check.error("estimate.bounds", f"expected bounds >= 0 for {name!r} (a damping coefficient), got "
                              f"[{bounds[i][0]:g}, {bounds[i][1]:g}]")


def check_schedule(check: Checker, table: dict[str, Any], dynamics: dict[str, Any] | None) -> None:
    """``[control] keyframe_times`` and ``reach_time``: only with ``[dynamics]``, the keyframes
    increasing within the run, T a frame after the start."""
    given = [name for name in ("keyframe_times", "reach_time") if table[name] is not None]
    if dynamics is None:
        if given:
            raise check.error(f"control.{given[0]}", "a schedule in time needs a [dynamics] table (without it "
                              "sorofem control finds constant commands)")
        return
    dt, steps = dynamics["dt"], dynamics["steps"]
    end = dt * steps
    times = table["keyframe_times"]
    if times is not None:
        for i in range(1, len(times)):
            if times[i] <= times[i - 1]:
                raise check.error("control.keyframe_times", f"expected increasing times, got {times[i]:g} s after "
                                  f"{times[i - 1]:g} s (keyframes {i - 1} and {i})")
        if times[-1] > end * (1 + 1e-12):
            raise check.error("control.keyframe_times", f"expected times within the run, 0 to dt * steps = {end:g} "
                              f"s, got {times[-1]:g} s")
    reach = table["reach_time"]
    if reach is not None:
        if reach > end * (1 + 1e-9):
            raise check.error("control.reach_time", f"expected a time within the run, dt to dt * steps = {end:g} s, "
                              f"got {reach:g} s")
        if _frame(reach, dt) < 1:
            raise check.error("control.reach_time", f"expected a frame of [dynamics], a multiple of dt = {dt:g} s, "
                              f"got {reach:g} s")


def _rayleigh(dynamics: dict[str, Any]) -> tuple[float, float]:
    return dynamics["mass_damping"], dynamics["stiffness_damping"]


def estimate_dynamics(check: Checker, dynamics: dict[str, Any], estimate: dict[str, Any],
                      tracks: Sequence[tuple[float, Target]] | None) -> dict[str, Any]:
    """``dynamics=`` of :func:`sorofem.estimate` for ``sorofem estimate`` of a scene with
    ``[dynamics]``: the run's dt, steps, cable schedule and start of the Rayleigh coefficients
    (those not fitted are held); ``initial`` is None, the caller's to fill in with
    ``initial = "static"``. Refuses what a fit to motion cannot take, naming the key."""
    if tracks is None:
        raise check.error("target", "with [dynamics], sorofem estimate fits a recorded motion: expected [target] "
                          "nodes or points with tracks or tracks_file (leave out [dynamics] to fit the equilibrium)")
    fields = [n for n in estimate["params"] if n.partition(":")[0] in _FIELDS]
    if fields:
        raise check.error("estimate.params", f"{fields[0]!r} is a field (a value per element); a fit to motion "
                          "takes scalar parameters")
    if estimate["starts"]:
        raise check.error("estimate.starts", f"a fit to motion runs from x0 alone, got starts = {estimate['starts']}")
    materials = [n for n in estimate["params"] if n not in MOTION_PARAMETERS]
    if dynamics["initial"] == "static" and materials:
        raise check.error("dynamics.initial", f"a fit of {materials[0]!r} to motion starts from rest (initial = "
                          "\"rest\"): the equilibrium of initial = \"static\" would change with the fitted values")
    return {"dt": dynamics["dt"], "steps": dynamics["steps"], "actuation": dynamics["actuation"],
            "damping": _rayleigh(dynamics), "initial": None}


def control_dynamics(check: Checker, dynamics: dict[str, Any], control: dict[str, Any],
                     has_tracks: bool) -> dict[str, Any]:
    """``dynamics=`` of :func:`sorofem.control` for ``sorofem control`` of a scene with
    ``[dynamics]``: the run, the keyframe times and T of ``[control]`` and the Rayleigh damping;
    ``initial`` is None, the caller's to fill in with ``initial = "static"``. Refuses what a
    schedule cannot take, naming the key."""
    for name in ("keyframe_times", "reach_time"):
        if control[name] is None:
            raise check.error(f"control.{name}", "missing: with [dynamics], sorofem control optimises a schedule: "
                              "expected keyframe_times = [t1, t2, ...] and reach_time = T (s)")
    if control["method"] != "l-bfgs-b":
        raise check.error("control.method", f"a schedule is optimised by 'l-bfgs-b' (with the adjoint gradient), got "
                          f"{control['method']!r}")
    if dynamics["actuation"] is not None:
        raise check.error("dynamics.actuation", "sorofem control finds the schedule of the [control] cables itself: "
                          "leave out actuation (the other cables keep their [[cable]] commands)")
    if has_tracks:
        raise check.error("target", "sorofem control takes a goal (positions or positions_file), not a recorded "
                          "motion (tracks, tracks_file)")
    return {"dt": dynamics["dt"], "steps": dynamics["steps"], "keyframe_times": control["keyframe_times"],
            "reach_time": control["reach_time"], "damping": _rayleigh(dynamics), "initial": None}
