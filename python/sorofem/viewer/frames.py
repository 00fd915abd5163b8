"""The saved frames of a motion, from a :class:`~sorofem.Trajectory` or a ``.pvd`` time series."""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..dynamics import Trajectory
from ..errors import InputError
from ..mesh import Mesh

__all__ = ["Frames", "load_frames"]


@dataclass
class Frames:
    """The saved frames of a motion, as :func:`build_trajectory_view` plays them.

    Attributes
    ----------
    times
        ``(f,)`` time of each frame, s.
    positions
        ``(f, n_nodes, 3)`` node positions, m.
    mesh
        The rest mesh (its boundary is the surface shown).
    cable_points
        Per frame, one ``(k, 3)`` array per cable, m (empty lists without cables).
    fixed_nodes
        Indices of the supported nodes (empty when read from a ``.pvd``, which does not record
        them).
    kinetic_energy
        ``(f,)`` J, or None (not in a ``.pvd``).
    actuation
        ``(f, n_cables)`` alpha in force at each frame, or None (not in a ``.pvd``).
    trajectory
        The :class:`~sorofem.Trajectory` they come from, if any.
    source
        A label: the ``.pvd`` path or ``"trajectory"``.
    """

    times: NDArray[np.float64]
    positions: NDArray[np.float64]
    mesh: Mesh
    cable_points: list[list[NDArray[np.float64]]]
    fixed_nodes: NDArray[np.int64]
    kinetic_energy: NDArray[np.float64] | None = None
    actuation: NDArray[np.float64] | None = None
    trajectory: Trajectory | None = None
    source: str = "trajectory"

    @property
    def n_frames(self) -> int:
        return int(self.times.size)

    @property
    def n_cables(self) -> int:
        return len(self.cable_points[0]) if self.cable_points else 0

    @classmethod
    def from_trajectory(cls, trajectory: Trajectory, source: str = "trajectory") -> "Frames":
        """The frames of a :class:`~sorofem.Trajectory` (no copy of the positions)."""
        n_cables = len(trajectory.body.cables)
        actuation = None
        if n_cables:
            steps = np.rint(trajectory.times / trajectory.dt).astype(np.int64) - 1
            initial = np.asarray(trajectory.initial_actuation, dtype=np.float64).reshape(1, n_cables)
            table = np.vstack([initial, trajectory.actuation.reshape(-1, n_cables)])
            actuation = table[np.clip(steps + 1, 0, len(table) - 1)]
        return cls(
            times=trajectory.times, positions=trajectory.positions, mesh=trajectory.mesh,
            cable_points=trajectory.cable_points if n_cables else [[] for _ in range(trajectory.n_frames)],
            fixed_nodes=trajectory.body.fixed_nodes, kinetic_energy=trajectory.kinetic_energy,
            actuation=actuation, trajectory=trajectory, source=source,
        )

    @classmethod
    def read_pvd(cls, path: str | os.PathLike[str]) -> "Frames":
        """Read a ``.pvd`` time series written by :meth:`sorofem.Trajectory.write_pvd` (or
        ``sorofem run`` with ``[dynamics]``): one ``.vtu`` per frame with the tetrahedra and,
        after the nodes, the cable points joined by line cells.

        The rest shape is the first frame's points minus its ``displacement`` point data (the
        first frame itself when there is none).

        Raises
        ------
        InputError
            The file or a frame is missing or unreadable, has no tetrahedra, or the frames do
            not have the same points.
        """
        import meshio

        path = Path(path)
        try:
            root = ET.parse(path).getroot()
        except (OSError, ET.ParseError) as exc:
            raise InputError(f"{path}: cannot read the .pvd collection ({exc})") from None
        datasets = root.findall("./Collection/DataSet")
        if not datasets:
            raise InputError(f"{path}: no <DataSet> entries in the .pvd collection")
        times, positions, cable_points = [], [], []
        tets = chains = None
        rest = None
        n = n_points = 0
        for i, entry in enumerate(datasets):
            file = entry.get("file")
            if not file:
                raise InputError(f"{path}: <DataSet> {i} has no file attribute")
            frame_path = path.parent / file
            try:
                frame = meshio.read(frame_path)
            except Exception as exc:  # noqa: BLE001 - meshio raises many kinds
                raise InputError(f"{path}: frame {i} ({frame_path}) cannot be read: {exc}") from None
            try:
                times.append(float(entry.get("timestep", i)))
            except ValueError:
                raise InputError(f"{path}: <DataSet> {i} has timestep={entry.get('timestep')!r}, not a number") from None
            points = np.asarray(frame.points, dtype=np.float64)
            if tets is None:
                tet_blocks = [b.data for b in frame.cells if b.type == "tetra"]
                if not tet_blocks:
                    raise InputError(f"{path}: frame 0 ({frame_path}) has no tetrahedra")
                tets = np.vstack(tet_blocks).astype(np.int64)
                lines = [b.data for b in frame.cells if b.type == "line"]
                lines_arr = np.vstack(lines).astype(np.int64) if lines else np.zeros((0, 2), dtype=np.int64)
                n = int(lines_arr.min()) if lines_arr.size else len(points)
                chains = _chains(lines_arr)
                n_points = len(points)
                displacement = frame.point_data.get("displacement")
                rest = points[:n] - (0.0 if displacement is None else np.asarray(displacement, dtype=np.float64)[:n])
            elif len(points) != n_points:
                raise InputError(f"{path}: frame {i} has {len(points)} points, frame 0 has {n_points}")
            positions.append(points[:n])
            cable_points.append([points[chain] for chain in chains])
        assert tets is not None and rest is not None
        return cls(
            times=np.array(times), positions=np.stack(positions), mesh=Mesh(rest, tets),
            cable_points=cable_points, fixed_nodes=np.zeros(0, dtype=np.int64), source=str(path),
        )


def _chains(lines: NDArray[np.int64]) -> list[NDArray[np.int64]]:
    """Point indices of each polyline in a list of line cells (consecutive cells sharing an end
    form one polyline, as write_pvd writes the cables)."""
    chains: list[list[int]] = []
    for a, b in lines.tolist():
        if chains and chains[-1][-1] == a:
            chains[-1].append(b)
        else:
            chains.append([a, b])
    return [np.array(c, dtype=np.int64) for c in chains]


def load_frames(source: Trajectory | Frames | str | os.PathLike[str]) -> Frames:
    """The frames to play from a :class:`~sorofem.Trajectory`, a ``.pvd`` file, or a folder
    holding ``trajectory.pvd`` (the ``--out`` folder of ``sorofem run``) or exactly one
    ``.pvd``.

    Raises
    ------
    InputError
        Nothing to play at ``source``.
    """
    if isinstance(source, Frames):
        return source
    if isinstance(source, Trajectory):
        return Frames.from_trajectory(source)
    if not isinstance(source, (str, os.PathLike)):
        raise InputError(f"expected a sorofem.Trajectory, a .pvd file or a folder, got {type(source).__name__}")
    path = Path(source)
    if path.is_dir():
        candidates = [path / "trajectory.pvd"] if (path / "trajectory.pvd").is_file() else sorted(path.glob("*.pvd"))
        if len(candidates) != 1:
            found = ", ".join(c.name for c in candidates) or "none"
            raise InputError(f"{path}: expected trajectory.pvd or exactly one .pvd file in the folder, found {found}")
        path = candidates[0]
    elif not path.is_file():
        raise InputError(f"{path}: no such file or folder")
    if path.suffix.lower() != ".pvd":
        raise InputError(f"{path}: expected a .pvd time series (written by Trajectory.write_pvd or sorofem run)")
    return Frames.read_pvd(path)
