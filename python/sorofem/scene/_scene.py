"""The scene: a whole simulation read from a TOML file, built into a body with its loads, cables,
dynamics, target and outputs."""

from __future__ import annotations

import json
import os
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from .._files import check_path
from ..body import Body
from ..cables import Cable
from ..dynamics import Trajectory, simulate
from ..errors import InputError, ParameterError, SceneError
from ..materials import Material
from ..mesh import Mesh
from ..solver import SolveOptions
from ..static import StaticResult, solve_static
from ..targets import Target
from ._build import (
    apply_cables,
    apply_fixed,
    apply_obstacles,
    apply_loads,
    build_control,
    build_dynamics,
    build_estimate,
    build_material,
    build_mesh,
    build_output,
    build_target,
    set_cable_command,
)
from ._keys import SCENE, defaults
from ._motion import build_tracks, check_estimate, check_schedule, control_dynamics, estimate_dynamics
from ._spec import Checker

__all__ = ["Scene", "structure_key", "PER_SOLVE_CABLE_KEYS"]

#: The [[cable]] keys a built model takes at every solve (the others shape the model): a spring
#: chain's actuation and stiffness, a tendon's pull or tension.
PER_SOLVE_CABLE_KEYS = ("actuation", "stiffness", "pull", "tension")


def structure_key(data: Mapping[str, Any]) -> str:
    """The tables a scene's expensive objects are built from, as one JSON string: the mesh, the
    formulation, the supports, the nodal forces, the cables (all but a spring chain's actuation
    and stiffness and a tendon's pull or tension), the material model, the target, the
    obstacles and the contact settings.

    Two scenes whose checked tables give the same key differ only in values a built model takes
    at each solve (material values, cable commands and stiffnesses, gravity, solver and dynamics
    options), so they can share a mesh and a compiled model (:meth:`Scene.from_data`'s ``like``).
    """
    cables = [{k: v for k, v in entry.items() if k not in PER_SOLVE_CABLE_KEYS} for entry in data.get("cable", [])]
    parts = {
        "mesh": data.get("mesh"),
        "formulation": data.get("formulation"),
        "fixed": data.get("fixed"),
        "forces": (data.get("loads") or {}).get("forces"),
        "cable": cables,
        "material_model": (data.get("material") or {}).get("model"),
        "target": data.get("target"),
        "obstacle": data.get("obstacle"),
        "contact": data.get("contact"),
    }
    return json.dumps(parts, sort_keys=True, default=str)


@dataclass
class Scene:
    """A static simulation read from a TOML scene file (schema in the module docstring).

    Attributes
    ----------
    path
        The scene file.
    mesh, material, body
        The model, with the ``[[fixed]]`` conditions and ``[loads].forces`` applied to ``body``.
        With ``[[material.region]]`` entries ``material`` holds per-element arrays.
    formulation
        ``[formulation].kind``.
    formulation_options
        ``[formulation]`` ``volumetric`` and ``pressure_mass`` (keyword arguments of
        :class:`sorofem.Body`), defaults filled in.
    gravity
        ``(3,)`` m/s^2.
    solve_options
        ``[solver]``: the :class:`sorofem.solver.SolveOptions` of every solve of the scene.

    Examples
    --------
    >>> import sorofem as sf
    >>> scene = sf.Scene.load("cantilever.toml")  # doctest: +SKIP
    >>> result = scene.solve()                    # doctest: +SKIP
    """

    path: Path
    mesh: Mesh
    material: Material
    body: Body
    formulation: str
    gravity: np.ndarray
    solve_options: SolveOptions = field(default_factory=SolveOptions)
    formulation_options: dict[str, str] = field(
        default_factory=lambda: {k: v for k, v in defaults("formulation").items() if k != "kind"}
    )
    #: The ``[[cable]]`` entries, added to ``body`` (see :class:`sorofem.Cable`).
    cables: list[Cable] = field(default_factory=list)
    #: ``[dynamics]`` with defaults filled in (``actuation``: a list of
    #: :class:`sorofem.dynamics.Keyframes` per cable, or None), or None for a static scene.
    dynamics: dict[str, Any] | None = None
    #: ``[target]`` as a :class:`sorofem.Target`, or None (also when it is a recorded motion).
    target: Target | None = None
    #: ``[target]`` tracks or tracks_file (with ``[dynamics]``): the marker tracks of
    #: :func:`sorofem.estimate`, ``[(time, Target), ...]``, one per frame with a marker seen,
    #: in time order; else None.
    tracks: list[tuple[float, Target]] | None = None
    #: ``[estimate]``: ``params``, ``x0``, ``bounds``, ``method``, ``starts`` (None when absent), or None.
    estimate: dict[str, Any] | None = None
    #: ``[control]``: ``cables`` (indices), ``bounds``, ``method``, ``keyframe_times``,
    #: ``reach_time`` (None without them), or None.
    control: dict[str, Any] | None = None
    #: Named ``[[material.region]]`` entries: name -> indices of the elements that have the
    #: entry's material (those no later entry overrides); the ``regions=`` of
    #: :func:`sorofem.estimate` for ``"shear_modulus:NAME"`` parameters.
    regions: dict[str, np.ndarray] = field(default_factory=dict)
    #: Per element, the index of the ``[[material.region]]`` entry that set its material, or -1
    #: for ``[material]`` itself; ``(n_tets,)`` int64, or None without regions.
    material_region: np.ndarray | None = None
    #: ``[output]`` with defaults filled in: ``directory`` (a Path, resolved against the scene
    #: file's folder, or None), the switches ``summary``, ``vtu``, ``png``, ``cables``, ``pvd``
    #: (booleans) and ``color_by``.
    output: dict[str, Any] = field(default_factory=lambda: {**defaults("output"), "directory": None})
    #: The files the scene reads: itself, the mesh file and the ``[target]`` surface files
    #: (``sorofem run`` never writes over them).
    input_files: list[Path] = field(default_factory=list)
    #: What the expensive objects of the scene are built from (:func:`structure_key`): scenes
    #: with the same structure can share a mesh and a compiled model (:meth:`from_data`'s ``like``).
    structure: str = field(default="", repr=False)

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> "Scene":
        """Read, validate and build a scene.

        Raises
        ------
        SceneError
            Anything wrong in the file, with ``path``, ``key`` and ``line``.
        FileNotFoundError
            The scene file itself does not exist.
        """
        path = check_path(path, "scene")
        if not path.is_file():
            raise FileNotFoundError(f"scene file not found: {path}")
        try:
            text = path.read_text(encoding="utf-8")
        except UnicodeDecodeError as exc:
            raise SceneError(f"not a UTF-8 text file ({exc})", path=path) from None
        return cls.from_toml(text, path)

    @classmethod
    def from_toml(cls, text: str, path: str | os.PathLike[str]) -> "Scene":
        """Build a scene from TOML text; relative mesh paths are resolved against ``path``'s folder."""
        path = Path(path)
        try:
            raw = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            match = re.search(r"line (\d+)", str(exc))
            raise SceneError(
                f"invalid TOML: {exc}", path=path, line=int(match.group(1)) if match else None
            ) from None
        except RecursionError:
            # tomllib recurses once per nested array or inline table; no scene key nests deeper than 4.
            raise SceneError("invalid TOML: arrays or inline tables nested too deeply for the parser (a scene "
                             "nests them at most 4 levels deep)", path=path) from None
        return cls.from_data(raw, path, text=text)

    @classmethod
    def from_data(
        cls,
        raw: Mapping[str, Any],
        path: str | os.PathLike[str],
        *,
        text: str = "",
        like: "Scene | Sequence[Scene] | None" = None,
    ) -> "Scene":
        """Build a scene from its tables as :func:`tomllib.loads` returns them.

        Parameters
        ----------
        raw
            The tables of a scene file (checked here exactly as :meth:`from_toml` checks them).
        path
            The scene file they stand for: errors name it, relative paths are resolved
            against its folder.
        text
            The file's text, if any, so that errors can give the line.
        like
            Scenes built before (or one): the one with the same :attr:`structure` and folder,
            if any, lends its mesh, supports, forces, cables, target and compiled model (whose
            symbolic factorisation is the expensive part), shared through
            :meth:`sorofem.Body.replace`, instead of their being built again. The scene is the
            one building from scratch gives: a sweep (:func:`sorofem.sweep`) relies on it to
            solve many variants of a scene.
        """
        path = Path(path)
        check = Checker(path, text)
        # Structure, types, ranges and allowed values (everything json_schema() says), with
        # defaults filled in; then what needs the mesh and the other files.
        data = SCENE.check(check, raw, "")
        for name in ("formulation", "loads", "solver", "output", "contact"):
            if name not in data:
                data[name] = SCENE.fields[name].spec.check(check, {}, name)
        structure = structure_key(data)
        candidates = [like] if isinstance(like, Scene) else list(like or ())
        like = next((s for s in candidates if s.structure == structure and s.path.parent == path.parent), None)

        mesh = like.mesh if like is not None else build_mesh(check, data["mesh"], path.parent)
        formulation = data["formulation"]["kind"]
        options = {k: v for k, v in data["formulation"].items() if k != "kind"}
        material, regions, owner = build_material(check, data["material"], mesh, formulation)
        if like is not None:
            like.body.core_model()  # built now, so that this copy and every later one share it
        try:
            body = (like.body.replace(material=material) if like is not None
                    else Body(mesh, material, formulation=formulation, **options))
        except ParameterError as exc:
            raise check.error(f"material.{exc.parameter or 'youngs_modulus'}", str(exc)) from None
        if not data["fixed"] and not data["obstacle"]:
            raise check.error("fixed", "missing: a scene needs a [[fixed]] entry, or [[obstacle]] entries for an "
                              "unsupported body to rest on (an unsupported body in empty space has no equilibrium)")
        # A body lent by ``like`` has its supports, cables and obstacles (they are in the
        # structure); their files are among its input files, which the target's take over.
        obstacle_files: list[Path] = []
        if like is not None:
            gravity, cables = np.array(data["loads"]["gravity"]), like.cables
            for c, entry in enumerate(data["cable"]):
                set_cable_command(check, f"cable[{c}]", entry, body, c)
        else:
            apply_fixed(check, data["fixed"], body)
            gravity = apply_loads(check, data["loads"], body)
            cables = apply_cables(check, data["cable"], body)
            obstacle_files = apply_obstacles(check, data["obstacle"], data["contact"], body, path.parent)
        dynamics = build_dynamics(check, data["dynamics"], body) if "dynamics" in data else None
        target, target_files = None, []
        observed = data.get("target", {})
        motion = "tracks" in observed or "tracks_file" in observed
        if like is not None:
            target = like.target
            target_files = [f for f in like.input_files if f not in (like.path, like.mesh.source)]
        elif "target" in data and not motion:
            target, target_files = build_target(check, data["target"], body, path.parent, data["obstacle"])
        # Tracks are checked against [dynamics], which is not part of the structure: built every time.
        tracks, track_files = (build_tracks(check, observed, data.get("dynamics"), body, path.parent) if motion
                               else (None, []))
        estimate = build_estimate(check, data["estimate"], regions) if "estimate" in data else None
        if estimate is not None:
            check_estimate(check, data["estimate"], data.get("dynamics"))
        control = build_control(check, data["control"], body) if "control" in data else None
        if control is not None:
            check_schedule(check, data["control"], data.get("dynamics"))
            control.update(keyframe_times=data["control"]["keyframe_times"], reach_time=data["control"]["reach_time"])
        output = build_output(check, data["output"], formulation, path.parent)
        return cls(
            path=path,
            mesh=mesh,
            material=material,
            body=body,
            formulation=formulation,
            gravity=gravity,
            solve_options=SolveOptions(**data["solver"]),
            formulation_options=options,
            cables=cables,
            dynamics=dynamics,
            target=target,
            tracks=tracks,
            estimate=estimate,
            control=control,
            regions=regions,
            material_region=owner,
            output=output,
            input_files=list(dict.fromkeys(p for p in (path, mesh.source, *target_files, *track_files, *obstacle_files)
                                           if p is not None)),
            structure=structure,
        )

    @property
    def solver(self) -> dict[str, Any]:
        """The ``[solver]`` table: :attr:`solve_options` as a dict (pass ``options=`` that object
        to :func:`sorofem.solve_static`)."""
        return self.solve_options.to_dict()

    def solve(self, *, body: Body | None = None, initial: StaticResult | None = None) -> StaticResult:
        """Run :func:`sorofem.solve_static` with the scene's loads and solver options (on
        ``body`` instead of ``scene.body`` if given, warm-started from ``initial``)."""
        return solve_static(self.body if body is None else body, self.gravity, initial=initial,
                            options=self.solve_options)

    def simulate(
        self, *, body: Body | None = None, equilibrium: StaticResult | None = None, progress: bool | None = None,
        on_frames: Callable[..., None] | None = None,
    ) -> Trajectory:
        """Run :func:`sorofem.simulate` with the scene's ``[dynamics]`` (from the rest shape,
        or from :meth:`solve`'s equilibrium with ``initial = "static"``).

        Parameters
        ----------
        body
            Integrate this body instead of ``scene.body`` (the viewer passes its own, with the
            formulation and cable actuations set in the page); cables without keyframes hold
            its actuations.
        equilibrium
            With ``initial = "static"``: the equilibrium of ``body`` to start from, if already
            solved (default: solved here). Ignored with ``initial = "rest"``.
        progress, on_frames
            See :func:`sorofem.simulate`.

        Raises
        ------
        InputError
            The scene has no ``[dynamics]`` table.
        """
        if self.dynamics is None:
            raise InputError(f"{self.path}: the scene has no [dynamics] table")
        d = self.dynamics
        body = self.body if body is None else body
        initial = None
        if d["initial"] == "static":
            initial = equilibrium if equilibrium is not None else self.solve(body=body)
        return simulate(
            body, d["dt"], d["steps"], actuation=d["actuation"], gravity=self.gravity,
            damping=(d["mass_damping"], d["stiffness_damping"]), initial=initial, save_every=d["save_every"],
            tolerance=self.solve_options.tolerance, max_iterations=self.solve_options.max_iterations,
            progress=progress, on_frames=on_frames,
        )

    def estimate_dynamics(self) -> dict[str, Any]:
        """The ``dynamics=`` of :func:`sorofem.estimate` that ``sorofem estimate`` passes for a
        scene with ``[dynamics]``, whose target is then :attr:`tracks`: dt, steps, the cable
        schedule, the Rayleigh coefficients (the start of those fitted, the value of the
        others) and, with ``initial = "static"``, the equilibrium :meth:`solve` finds.

        Raises
        ------
        SceneError
            What a fit to motion cannot take, naming the key: no tracks, a field parameter,
            extra starts, ``initial = "static"`` with material parameters.
        InputError
            The scene has no ``[dynamics]`` table or no ``[estimate]`` table.
        """
        if self.dynamics is None or self.estimate is None:
            raise InputError(f"{self.path}: a fit to motion needs [dynamics] and [estimate] tables")
        options = estimate_dynamics(self._checker(), self.dynamics, self.estimate, self.tracks)
        return {**options, "initial": self.solve() if self.dynamics["initial"] == "static" else None}

    def control_dynamics(self) -> dict[str, Any]:
        """The ``dynamics=`` of :func:`sorofem.control` that ``sorofem control`` passes for a
        scene with ``[dynamics]``: dt, steps, ``[control]`` keyframe_times and reach_time, the
        Rayleigh damping and, with ``initial = "static"``, the positions of the equilibrium
        :meth:`solve` finds.

        Raises
        ------
        SceneError
            What a schedule cannot take, naming the key: no keyframe_times or reach_time, a
            method other than l-bfgs-b, a ``[dynamics]`` actuation, tracks as the target.
        InputError
            The scene has no ``[dynamics]`` table or no ``[control]`` table.
        """
        if self.dynamics is None or self.control is None:
            raise InputError(f"{self.path}: a schedule needs [dynamics] and [control] tables")
        options = control_dynamics(self._checker(), self.dynamics, self.control, self.tracks is not None)
        return {**options, "initial": self.solve().positions if self.dynamics["initial"] == "static" else None}

    def _checker(self) -> Checker:
        """Errors naming keys of this scene, with their lines when the file can be read."""
        try:
            text = self.path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError):
            text = ""
        return Checker(self.path, text)

    def to_dict(self) -> dict[str, Any]:
        """Plain summary of the scene's settings."""
        return {
            "scene": str(self.path),
            "mesh": None if self.mesh.source is None else str(self.mesh.source),
            "formulation": self.formulation,
            "formulation_options": self.body.formulation_options,
            "material": self.material.to_dict(),
            "material_regions": None if self.material_region is None else {
                "elements_per_entry": np.bincount(self.material_region + 1).tolist()[1:],
                "named": {name: int(e.size) for name, e in self.regions.items()},
            },
            "gravity": self.gravity.tolist(),
            "fixed_nodes": int(self.body.fixed_nodes.size),
            "solver": self.solve_options.to_dict(),
            "cables": [c.to_dict() for c in self.cables],
            "obstacles": [o.to_dict() for o in self.body.obstacles],
            "contact": self.body.contact_settings,
            "dynamics": None if self.dynamics is None else {
                **self.dynamics,
                "actuation": None if self.dynamics["actuation"] is None else [
                    np.column_stack([k.times, k.values]).tolist() for k in self.dynamics["actuation"]
                ],
            },
            "output": {**self.output, "directory": None if self.output["directory"] is None
                       else str(self.output["directory"])},
        }
