"""Writing a trajectory's frames as a ParaView collection while it is integrated:
:class:`PvdWriter` (``sorofem.dynamics.PvdWriter``)."""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Sequence
from xml.sax.saxutils import quoteattr

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._files import write_text
from ._formats import meshio_write
from .body import Body

__all__ = ["PvdWriter"]


class PvdWriter:
    """Writes the frames of a simulation as they come: ``directory/name/frame_NNNNN.vtu`` and the
    index ``directory/name.pvd`` that lists them (ParaView reads it as a time series).

    Each frame is written to a temporary name and renamed; the index is rewritten (the same
    way) after every :meth:`add` that follows the previous one by ``every`` seconds, and by
    :meth:`close`, so at any moment it lists complete frames only. Pass :meth:`add` as
    ``on_frames=`` of :func:`simulate` to write frames while the integration runs.

    ``run_id`` (an integer) marks the files of one run: it is each frame's field data
    ``sorofem_run_id`` and an attribute of the index; frames of another run left in the folder
    beyond this run's last frame are never listed.

    Examples
    --------
    >>> writer = sf.dynamics.PvdWriter(body, "results/pull")             # doctest: +SKIP
    >>> traj = sf.simulate(body, 0.01, 100, on_frames=writer.add)      # doctest: +SKIP
    >>> writer.close()                                                 # doctest: +SKIP
    """

    def __init__(self, body: Body, directory: str | os.PathLike[str], name: str = "trajectory", *,
                 run_id: int | None = None, every: float = 2.0) -> None:
        self.body = body
        self.directory = Path(directory)
        self.name = name
        self.run_id = run_id
        self.every = every
        self.frames_dir = self.directory / name
        self.frames_dir.mkdir(parents=True, exist_ok=True)
        self.entries: list[str] = []
        self._indexed_at = time.perf_counter()
        self._model = body.core_model()
        rest_cables = [c.points for c in body.cables]
        self._rest_cables = np.vstack(rest_cables) if rest_cables else None
        self._lines = None
        self._rest_lengths = np.concatenate(
            [body.attached_rest_lengths(c) for c in range(len(body.cables))]) if rest_cables else None
        if rest_cables:
            offsets = np.cumsum([body.mesh.n_nodes] + [len(p) for p in rest_cables])
            self._lines = np.vstack(
                [np.column_stack([np.arange(a, b - 1), np.arange(a + 1, b)]) for a, b in zip(offsets[:-1], offsets[1:])]
            ).astype(np.int64)

    @property
    def pvd(self) -> Path:
        return self.directory / f"{self.name}.pvd"

    @property
    def n_frames(self) -> int:
        """Frames written so far."""
        return len(self.entries)

    def add(self, times: ArrayLike, positions: ArrayLike, cable_points: Sequence[Sequence[ArrayLike]] = (),
            contact_forces: ArrayLike | None = None) -> None:
        """Write frames: their ``times`` ``(k,)``, node ``positions`` ``(k, n_nodes, 3)``, with
        cables per frame one ``(p, 3)`` array per cable, and with obstacles the contact force on
        each node ``(k, n_nodes, 3)`` (N; point data ``contact_force``)."""
        import meshio

        mesh = self.body.mesh
        times = np.asarray(times, dtype=np.float64).reshape(-1)
        positions = np.asarray(positions, dtype=np.float64).reshape(times.size, mesh.n_nodes, 3)
        for k in range(times.size):
            f = len(self.entries)
            x = positions[k]
            j = np.asarray(self._model.element_fields(x)["J"], dtype=np.float64)
            points, disp = x, x - mesh.points
            point_data = {"displacement": disp}
            if contact_forces is not None:
                point_data["contact_force"] = np.asarray(contact_forces, dtype=np.float64)[k].reshape(mesh.n_nodes, 3)
            cells: list[tuple[str, NDArray[np.int64]]] = [("tetra", mesh.tets)]
            cell_j = [j]
            if self._lines is not None and k < len(cable_points):
                cable_x = np.vstack([np.asarray(c, dtype=np.float64) for c in cable_points[k]])
                points = np.vstack([x, cable_x])
                disp = np.vstack([disp, cable_x - self._rest_cables])
                point_data = {key: np.vstack([values, np.zeros((len(cable_x), 3))]) for key, values in point_data.items()}
                point_data["displacement"] = disp
                cells.append(("line", self._lines))
                # A segment's "volume ratio" is its stretch, deformed over rest length.
                lengths = np.linalg.norm(points[self._lines[:, 1]] - points[self._lines[:, 0]], axis=1)
                cell_j.append(lengths / self._rest_lengths)
            file = self.frames_dir / f"frame_{f:05d}.vtu"
            meshio_write(file, meshio.Mesh(points, cells, point_data=point_data, cell_data={"J": cell_j}),
                         run_id=self.run_id)
            self.entries.append(
                f'    <DataSet timestep="{float(times[k])!r}" group="" part="0" '
                f"file={quoteattr(f'{self.name}/{file.name}')}/>"
            )
        if time.perf_counter() - self._indexed_at >= self.every:
            self._write_index()

    def _write_index(self) -> None:
        run = "" if self.run_id is None else f' sorofem_run_id="{self.run_id}"'
        write_text(
            self.pvd,
            f'<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1"{run}>\n  <Collection>\n'
            + "\n".join(self.entries)
            + "\n  </Collection>\n</VTKFile>\n",
        )
        self._indexed_at = time.perf_counter()

    def close(self) -> Path:
        """Write the index of every frame written; returns its path."""
        self._write_index()
        return self.pvd
