"""Cables: spring chains and tendons routed through a body.

A cable is an ordered chain of points, of one of two **models**:

* ``model="springs"`` (the default, the paper's cable): a chain of unilateral springs bonded to
  the body at every point, driven by a rest-length ratio alpha (below);
* ``model="tendon"``: an inextensible tendon that slides freely through its points (guide
  points; the last one is where it is tied), so one tension ``T >= 0`` acts along all of it,
  driven as a motor drives it: by the pulled length ``d`` (m; the tendon's length is held at
  ``L <= L0 - d``, taut or slack, exactly) or by the tension ``T`` (N). See
  :meth:`sorofem.Body.pull` and docs/theory.md.

Each point of either model is embedded in the tetrahedron that
contains it (it moves with the material, barycentrically), snapped onto the nearest
tetrahedron if it lies within ``snap_tolerance`` outside the mesh, turned into a free node
with its own mass (``outside="free"``), or fixed in the world (the first point, with
``anchor_first=True``: the motor). Consecutive points are joined by **unilateral springs**:
segment ``k`` of rest length ``l_k`` and current length ``L_k`` stores the energy
``stiffness * psi(L_k - alpha l_k)``, where ``alpha`` is the **actuation** (1: rest length,
< 1: pulled in, > 1: paid out) and ``psi`` is zero when the segment is slack and a linear
spring when it is taut, joined smoothly over a transition of width ``w = transition * l_k``::

    tension = 0                              L - alpha l <= 0        (slack)
            = stiffness (L - alpha l)^2 / 2w 0 <= L - alpha l <= w   (transition)
            = stiffness (L - alpha l - w/2)  L - alpha l >= w        (taut)

A cable pushes nothing: it only pulls its points towards each other. The points of a spring
chain are bonded to the material (no sliding), so its tension may vary from segment to
segment; a tendon's is one number (``result.cable_tension``), and its pulled length
``L0 - L`` is ``result.cable_pull``.

Examples
--------
>>> import sorofem as sf
>>> mesh = sf.Mesh.box(size=(0.4, 0.1, 0.1), cells=(8, 2, 2))
>>> body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080))
>>> body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
>>> cable = sf.Cable.line(start=(0, 0.05, 0.01), direction=(1, 0, 0), length=0.4, divisions=10,
...                       stiffness=1e5)
>>> body.add_cable(cable)
0
>>> results = sf.actuate(body, cable, [0.9, 0.8])
>>> [bool(r.cable_tensions[0].max() > 0) for r in results]
[True, True]
"""

from __future__ import annotations

import math
import numbers
import os
from pathlib import Path
from typing import Any, NamedTuple, Protocol, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._files import check_path
from ._formats import meshio_write
from ._validate import MAX_CABLE_DIVISIONS, count, describe, real
from .errors import InputError, ParameterError, ShapeError

__all__ = ["Cable", "CablePlacement", "CABLE_MODELS", "OUTSIDE_MODES", "segment_tensions", "write_cables"]

#: What to do with a cable point farther than ``snap_tolerance`` from the mesh.
OUTSIDE_MODES: tuple[str, ...] = ("error", "free")
#: How a cable acts: a chain of bonded unilateral springs, or a sliding inextensible tendon.
CABLE_MODELS: tuple[str, ...] = ("springs", "tendon")
#: A tendon's commands: pulled length (m) or tension (N).
TENDON_COMMANDS: tuple[str, ...] = ("pull", "tension")

#: Largest change of alpha per continuation step when :func:`sorofem.actuate` builds the path.
DEFAULT_ALPHA_STEP = 0.05
#: How many times :func:`sorofem.actuate` halves a failed continuation step before giving up.
MAX_HALVINGS = 6


def check_actuation(alpha: Any, name: str = "actuation") -> float:
    """Validate an actuation alpha: a finite number > 0 (1 = rest length, < 1 = pulled)."""
    if isinstance(alpha, bool) or not isinstance(alpha, numbers.Real) or not (
        math.isfinite(float(alpha)) and float(alpha) > 0
    ):
        raise ParameterError(
            f"{name}: expected a finite number > 0 (1 = rest length, < 1 = pulled), got {describe(alpha)}",
            name,
        )
    return float(alpha)


def check_pull(pull: Any, name: str = "pull", rest_length: float | None = None) -> float:
    """Validate a tendon's pull: a finite length in m (negative pays the tendon out), shorter
    than its rest length ``rest_length`` when given."""
    if isinstance(pull, bool) or not isinstance(pull, numbers.Real) or not math.isfinite(float(pull)):
        raise ParameterError(f"{name}: expected a finite pulled length in m, got {describe(pull)}", name)
    if rest_length is not None and float(pull) >= rest_length:
        raise ParameterError(
            f"{name}: expected a pull shorter than the tendon's rest length {rest_length:.6g} m, got {float(pull):g} m",
            name,
        )
    return float(pull)


def check_tension(tension: Any, name: str = "tension") -> float:
    """Validate a tendon's tension: a finite force >= 0 N (a tendon cannot push)."""
    if isinstance(tension, bool) or not isinstance(tension, numbers.Real) or not (
        math.isfinite(float(tension)) and float(tension) >= 0
    ):
        raise ParameterError(
            f"{name}: expected a finite tension >= 0 N (a tendon cannot push), got {describe(tension)}", name
        )
    return float(tension)


class Cable:
    """A cable: a chain of unilateral springs, or a sliding tendon, through (or outside) a body.

    Parameters
    ----------
    points
        Rest positions of the cable points, ``(k, 3)`` with ``k >= 2``, m; consecutive
        points must differ. A tendon's last point is where it is tied.
    stiffness
        Spring chains (required): stiffness of each segment spring, N/m, > 0. (Each segment is
        a spring of this stiffness whatever its length: a finer division makes the whole
        cable softer.) Tendons have none.
    actuation
        Spring chains: initial actuation alpha > 0: the segments' rest lengths are multiplied
        by it (1: rest, 0.8: pulled in by 20 %). Change it later with
        :meth:`Body.set_actuation`.
    model
        ``"springs"`` (default) or ``"tendon"`` (see the module docstring and
        :data:`CABLE_MODELS`).
    pull
        Tendons: initial pulled length, m (the tendon's length is held at ``L <= L0 - pull``;
        negative pays it out), shorter than the rest length. Default 0 when ``tension`` is
        not given: the motor holds the tendon at its rest length.
    tension
        Tendons: initial tension, N, >= 0 (force control) instead of a pull. Change either
        later with :meth:`Body.pull`.
    transition
        Width of the slack-to-taut transition as a fraction of each segment's rest length,
        in (0, 1); smaller is closer to an ideal unilateral spring, larger is easier for
        Newton.
    anchor_first
        Fix the first point in the world (the motor) instead of embedding it; the cable then
        exerts an external force on the body (a tendon runs from the motor through its guide
        points).
    snap_tolerance
        Points at most this far outside the mesh (m, >= 0) are attached to the nearest
        tetrahedron.
    outside
        ``"error"`` (default): a point farther outside is an error. ``"free"`` (spring chains
        only): it becomes a free node with its own three unknowns, mass ``free_node_mass``
        and weight.
    free_node_mass
        Mass of each free node, kg, >= 0. A massless free node needs a taut cable on both
        sides to be determined.
    damping
        Dashpot coefficient of each segment, N s/m, >= 0: in :func:`sorofem.simulate` a force
        ``damping * dL/dt`` along each segment opposes the change of its length ``L`` (the
        cable's internal friction); static solves are unaffected. Spring chains only.

    Raises
    ------
    ShapeError
        ``points`` is not a ``(k, 3)`` numeric array.
    ParameterError
        Any other value out of range (the error's ``parameter`` names it).

    Examples
    --------
    >>> import sorofem as sf
    >>> cable = sf.Cable([[0, 0, 0], [0.1, 0, 0], [0.2, 0, 0]], stiffness=1e4)
    >>> cable.n_segments, cable.rest_lengths.tolist()
    (2, [0.1, 0.1])
    >>> tendon = sf.Cable([[0, 0, 0], [0.1, 0, 0], [0.2, 0, 0]], model="tendon", pull=0.01)
    >>> tendon.command
    ('pull', 0.01)
    """

    def __init__(
        self,
        points: ArrayLike,
        stiffness: float | None = None,
        actuation: float = 1.0,
        *,
        model: str = "springs",
        pull: float | None = None,
        tension: float | None = None,
        transition: float = 1e-3,
        anchor_first: bool = False,
        snap_tolerance: float = 0.0,
        outside: str = "error",
        free_node_mass: float = 0.0,
        damping: float = 0.0,
    ) -> None:
        try:
            pts = np.asarray(points, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ShapeError(f"points: expected a (k, 3) array of numbers, got {describe(points)} ({exc})") from None
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise ShapeError(f"points: expected shape (k, 3), got shape {pts.shape}")
        if pts.shape[0] < 2:
            raise ParameterError(f"points: a cable needs at least 2 points, got {pts.shape[0]}", "points")
        if not np.all(np.isfinite(pts)):
            row = int(np.argwhere(~np.isfinite(pts))[0, 0])
            raise ParameterError(f"points: expected finite coordinates, got {pts[row].tolist()} at point {row}", "points")
        lengths = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        if np.any(lengths <= 0):
            k = int(np.argmax(lengths <= 0))
            raise ParameterError(
                f"points: consecutive points must differ, but points {k} and {k + 1} coincide at {pts[k].tolist()}",
                "points",
            )
        if not isinstance(anchor_first, (bool, np.bool_)):
            raise ParameterError(f"anchor_first: expected True or False, got {describe(anchor_first)}", "anchor_first")
        if not isinstance(outside, str) or outside not in OUTSIDE_MODES:
            raise ParameterError(f"outside: expected one of {list(OUTSIDE_MODES)}, got {outside!r}", "outside")
        if not isinstance(model, str) or model not in CABLE_MODELS:
            raise ParameterError(f"model: expected one of {list(CABLE_MODELS)}, got {describe(model)}", "model")
        pts.setflags(write=False)
        lengths.setflags(write=False)
        self._points = pts
        self._rest_lengths = lengths
        self.model = model
        if model == "tendon":
            self._check_tendon_options(stiffness, actuation, transition, outside, free_node_mass, damping)
            if pull is not None and tension is not None:
                raise ParameterError("pull, tension: a tendon takes either a pull or a tension, not both", "pull")
            #: A tendon's initial command: ``("pull", m)`` or ``("tension", N)``.
            self.command = (
                ("tension", check_tension(tension)) if tension is not None
                else ("pull", check_pull(0.0 if pull is None else pull, rest_length=float(lengths.sum())))
            )
            self.stiffness: float | None = None
        else:
            for name, value in (("pull", pull), ("tension", tension)):
                if value is not None:
                    raise ParameterError(
                        f"{name}: only a tendon (model=\"tendon\") takes a {name}; a spring chain is driven by its "
                        "actuation alpha", name,
                    )
            if stiffness is None:
                raise ParameterError("stiffness: a spring chain needs the stiffness of its segments, N/m", "stiffness")
            self.stiffness = real(stiffness, "stiffness", minimum=0.0, strict=True)
            self.command = ("actuation", check_actuation(actuation))
        self.actuation = check_actuation(actuation)
        self.transition = real(transition, "transition", minimum=0.0, strict=True, maximum=1.0)
        self.anchor_first = bool(anchor_first)
        self.snap_tolerance = real(snap_tolerance, "snap_tolerance", minimum=0.0, strict=False)
        self.outside = outside
        self.free_node_mass = real(free_node_mass, "free_node_mass", minimum=0.0, strict=False)
        self.damping = real(damping, "damping", minimum=0.0, strict=False)

    @staticmethod
    def _check_tendon_options(
        stiffness: Any, actuation: Any, transition: Any, outside: Any, free_node_mass: Any, damping: Any
    ) -> None:
        """A tendon has none of a spring chain's options (a clear error rather than an ignored value)."""
        given = {"stiffness": stiffness is not None, "actuation": actuation != 1.0, "transition": transition != 1e-3,
                 "free_node_mass": free_node_mass != 0.0, "damping": damping != 0.0}
        for name, set_ in given.items():
            if set_:
                raise ParameterError(
                    f"{name}: a tendon (model=\"tendon\") has no {name}; it is inextensible and driven by its pull "
                    "(m) or tension (N)", name,
                )
        if outside == "free":
            raise ParameterError(
                "outside: a tendon's guide points must lie in the body (or be the anchor): \"free\" is for spring "
                "chains; a free guide point would have no stiffness along the tendon", "outside",
            )

    @classmethod
    def line(
        cls,
        start: ArrayLike,
        direction: ArrayLike,
        length: float,
        divisions: int,
        stiffness: float | None = None,
        actuation: float = 1.0,
        **options: Any,
    ) -> "Cable":
        """A straight cable of ``divisions`` equal segments (``divisions + 1`` points).

        Parameters
        ----------
        start
            First point, ``(3,)``, m.
        direction
            Direction ``(3,)``, any non-zero length (normalised here).
        length
            Total length, m, > 0.
        divisions
            Number of segments, from 1 to 100,000 (a documented limit).
        stiffness, actuation, **options
            As for :class:`Cable`.

        Examples
        --------
        >>> import sorofem as sf
        >>> cable = sf.Cable.line((0, 0.05, 0.01), (1, 0, 0), length=0.4, divisions=10, stiffness=1e5)
        >>> cable.points.shape, round(float(cable.rest_lengths[0]), 6)
        ((11, 3), 0.04)
        >>> sf.Cable.line((0, 0.05, 0.01), (1, 0, 0), 0.4, 10, model="tendon", tension=2.0).command
        ('tension', 2.0)
        """
        try:
            p0 = np.asarray(start, dtype=np.float64)
            d = np.asarray(direction, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ShapeError(f"start, direction: expected 3 numbers each ({exc})") from None
        if p0.shape != (3,) or not np.all(np.isfinite(p0)):
            raise ShapeError(f"start: expected 3 finite numbers, got {describe(start)}")
        if d.shape != (3,) or not np.all(np.isfinite(d)) or not np.linalg.norm(d) > 0:
            raise ParameterError(f"direction: expected a finite non-zero vector (3,), got {describe(direction)}", "direction")
        length = real(length, "length", minimum=0.0, strict=True)
        divisions = count(divisions, "divisions", 1, MAX_CABLE_DIVISIONS)
        t = np.linspace(0.0, length, divisions + 1)
        points = p0 + t[:, None] * (d / np.linalg.norm(d))
        return cls(points, stiffness, actuation, **options)

    # -- data -----------------------------------------------------------------------

    @property
    def points(self) -> NDArray[np.float64]:
        """Rest positions of the points, ``(k, 3)``, m, read-only."""
        return self._points

    @property
    def rest_lengths(self) -> NDArray[np.float64]:
        """Rest length of each segment, ``(k - 1,)``, m (for alpha = 1)."""
        return self._rest_lengths

    @property
    def n_points(self) -> int:
        return int(self._points.shape[0])

    @property
    def n_segments(self) -> int:
        return int(self._points.shape[0]) - 1

    @property
    def length(self) -> float:
        """Total rest length, m."""
        return float(self._rest_lengths.sum())

    @property
    def is_tendon(self) -> bool:
        return self.model == "tendon"

    def to_core(self, actuation: float | None = None) -> dict[str, Any]:
        """The dict the extension's ``Model(cables=[...])`` takes (a tendon's command as given
        at construction; :meth:`sorofem.Body.core_model` sets the current one)."""
        if self.is_tendon:
            kind, value = self.command
            return {
                "points": np.ascontiguousarray(self._points),
                "model": "tendon",
                kind: value,
                "anchor_first": self.anchor_first,
                "snap_tolerance": self.snap_tolerance,
                "outside": self.outside,
            }
        return {
            "points": np.ascontiguousarray(self._points),
            "stiffness": self.stiffness,
            "actuation": self.actuation if actuation is None else float(actuation),
            "transition": self.transition,
            "anchor_first": self.anchor_first,
            "snap_tolerance": self.snap_tolerance,
            "outside": self.outside,
            "free_node_mass": self.free_node_mass,
            "damping": self.damping,
        }

    def to_dict(self) -> dict[str, Any]:
        """Plain summary (JSON types)."""
        data = self.to_core()
        data["points"] = self._points.tolist()
        data["length"] = self.length
        data["model"] = self.model
        return data

    def __repr__(self) -> str:
        extra = ", anchor_first=True" if self.anchor_first else ""
        extra += f", outside={self.outside!r}" if self.outside != "error" else ""
        if self.is_tendon:
            kind, value = self.command
            return f"Cable({self.n_points} points, length={self.length:.4g} m, model='tendon', {kind}={value:g}{extra})"
        return (
            f"Cable({self.n_points} points, length={self.length:.4g} m, stiffness={self.stiffness:.4g} N/m, "
            f"actuation={self.actuation:g}{extra})"
        )


class CablePlacement(NamedTuple):
    """Where one cable point ended up, from :meth:`Body.cable_placements`.

    Attributes
    ----------
    kind
        ``"embedded"`` (inside tetrahedron ``tet``), ``"snapped"`` (outside the mesh by
        ``distance`` m, attached to the nearest tetrahedron ``tet``), ``"free"`` (free node
        number ``free_index``) or ``"anchor"`` (fixed in the world).
    tet
        Tetrahedron index, or -1.
    free_index
        Free node index (counted over all cables of the body), or -1.
    distance
        Distance from the mesh, m (0 unless snapped).
    """

    kind: str
    tet: int
    free_index: int
    distance: float

    @classmethod
    def from_core(cls, entry: tuple[str, int, float]) -> "CablePlacement":
        kind, index, distance = entry
        if kind == "embedded":
            return cls("snapped" if distance > 0 else "embedded", int(index), -1, float(distance))
        if kind == "free":
            return cls("free", -1, int(index), 0.0)
        return cls(str(kind), -1, -1, 0.0)


def placement_counts(placements: Sequence[CablePlacement]) -> dict[str, Any]:
    """``{"embedded": n, "snapped": n, "free": n, "anchor": n, "max_snap_distance": m}`` of one cable."""
    counts: dict[str, Any] = {kind: 0 for kind in ("embedded", "snapped", "free", "anchor")}
    for p in placements:
        counts[p.kind] += 1
    counts["max_snap_distance"] = max((p.distance for p in placements), default=0.0)
    return counts


class HasCables(Protocol):
    """What :func:`cable_index` needs of a body (a :class:`sorofem.Body`)."""

    @property
    def cables(self) -> tuple[Cable, ...]: ...  # noqa: D102


def cable_index(body: HasCables, cable: "Cable | int") -> int:
    """Index of ``cable`` (a :class:`Cable` added to ``body``, or an index) in ``body.cables``."""
    n = len(body.cables)
    if isinstance(cable, Cable):
        for i, c in enumerate(body.cables):
            if c is cable:
                return i
        raise InputError("cable: this Cable has not been added to the body (use body.add_cable(cable) first)")
    if isinstance(cable, bool) or not isinstance(cable, numbers.Integral):
        raise InputError(f"cable: expected a Cable or an integer index, got {describe(cable)}")
    if not 0 <= int(cable) < n:
        raise InputError(f"cable: index {int(cable)} out of range: the body has {n} cable(s)")
    return int(cable)


def segment_tensions(
    cable: Cable, points: ArrayLike, alpha: float | None = None, rest_lengths: ArrayLike | None = None
) -> NDArray[np.float64]:
    """Tension of each segment, ``(k - 1,)`` N, from the cable's current points ``(k, 3)``:
    the spring law of the module docstring evaluated in NumPy (an independent check of the
    solver's ``result.cable_tensions``). ``alpha`` defaults to ``cable.actuation``;
    ``rest_lengths`` to ``cable.rest_lengths`` (a snapped point's segments are measured from
    the material point it was attached to, see :func:`attached_rest_lengths`).

    Examples
    --------
    >>> import sorofem as sf
    >>> cable = sf.Cable([[0, 0, 0], [1, 0, 0]], stiffness=10.0)
    >>> sf.cables.segment_tensions(cable, [[0, 0, 0], [1.1, 0, 0]]).round(6).tolist()
    [0.995]
    """
    y = np.asarray(points, dtype=np.float64).reshape(cable.n_points, 3)
    alpha = cable.actuation if alpha is None else check_actuation(alpha, "alpha")
    rest = cable.rest_lengths if rest_lengths is None else np.asarray(rest_lengths, dtype=np.float64)
    stretch = np.linalg.norm(np.diff(y, axis=0), axis=1) - alpha * rest
    w = cable.transition * rest
    return cable.stiffness * np.where(
        stretch <= 0, 0.0, np.where(stretch <= w, stretch**2 / (2 * w), stretch - w / 2)
    )


def attached_rest_lengths(body: Any, cable: "Cable | int") -> NDArray[np.float64]:
    """Rest length of each segment as the solver sees it, ``(k - 1,)`` m: measured between the
    material points the cable points are attached to (a snapped point sits on the mesh).
    ``body`` is a :class:`sorofem.Body` (:meth:`sorofem.Body.attached_rest_lengths`)."""
    return body.attached_rest_lengths(cable_index(body, cable))


# ---------------------------------------------------------------------------
# Output


def write_cables(path: str | os.PathLike[str], result: Any, *, run_id: int | None = None) -> None:
    """Write a result's cables (a :class:`sorofem.StaticResult`'s ``cable_points`` and
    ``cable_tensions``) as polylines (``.vtu``/``.vtk``, through meshio) for ParaView.

    Point data: ``cable`` (index). Cell data (one line cell per segment): ``tension`` (N) and
    ``cable``. Written to a temporary name and renamed over ``path``; ``run_id`` marks a
    ``.vtu`` (field data ``sorofem_run_id``).

    Raises
    ------
    InputError
        The result has no cables.
    """
    import meshio

    if not result.cable_points:
        raise InputError("write_cables: the result has no cables")
    points = np.vstack(result.cable_points)
    offsets = np.cumsum([0] + [len(p) for p in result.cable_points])
    lines = np.vstack(
        [np.column_stack([np.arange(a, b - 1), np.arange(a + 1, b)]) for a, b in zip(offsets[:-1], offsets[1:])]
    ).astype(np.int64)
    cable_of_point = np.repeat(np.arange(len(result.cable_points)), np.diff(offsets))
    cable_of_line = np.repeat(np.arange(len(result.cable_points)), np.diff(offsets) - 1)
    tension = np.concatenate(result.cable_tensions)
    meshio_write(
        check_path(path, "path"),
        meshio.Mesh(
            points,
            [("line", lines)],
            point_data={"cable": cable_of_point.astype(np.float64)},
            cell_data={"tension": [tension], "cable": [cable_of_line.astype(np.float64)]},
        ),
        run_id=run_id,
    )
