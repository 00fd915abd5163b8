"""Statistics and quality of a tetrahedral mesh file (``sorofem info MESH [--scale S] [--json]``).

Examples
--------
>>> import sorofem as sf
>>> from sorofem.mesh_info import run_command
>>> sf.Mesh.box(size=(0.4, 0.1, 0.1), cells=(4, 1, 1)).write("/tmp/beam.tet")
>>> run_command("/tmp/beam.tet", as_json=True)  # doctest: +SKIP
"""

from __future__ import annotations

import os
import sys

import numpy as np

from .io import json_text, read_mesh

__all__ = ["BAD_QUALITY", "tet_quality", "run_command"]

#: Radius ratio below which a tet counts as bad in `sorofem info` (1 = regular tet).
BAD_QUALITY = 0.1


def tet_quality(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """Radius ratio ``3 r_in / r_circ`` of each tetrahedron: 1 for a regular tet, 0 when degenerate."""
    p = points[tets]
    a, b, c, d = p[:, 0], p[:, 1], p[:, 2], p[:, 3]
    volume = np.abs(np.einsum("ij,ij->i", b - a, np.cross(c - a, d - a))) / 6.0
    area = sum(
        0.5 * np.linalg.norm(np.cross(q - o, r - o), axis=1) for o, q, r in ((a, b, c), (a, b, d), (a, c, d), (b, c, d))
    )
    # Circumradius from products of opposite edge lengths (Cayley-Menger in closed form).
    x = np.linalg.norm(a - b, axis=1) * np.linalg.norm(c - d, axis=1)
    y = np.linalg.norm(a - c, axis=1) * np.linalg.norm(b - d, axis=1)
    z = np.linalg.norm(a - d, axis=1) * np.linalg.norm(b - c, axis=1)
    product = np.clip((x + y + z) * (x + y - z) * (x - y + z) * (-x + y + z), 0.0, None)
    with np.errstate(divide="ignore", invalid="ignore"):
        r_in = 3.0 * volume / area
        r_circ = np.sqrt(product) / (24.0 * volume)
        quality = np.where(volume > 0, 3.0 * r_in / r_circ, 0.0)
    return np.nan_to_num(quality, nan=0.0)


def run_command(path: str | os.PathLike[str], scale: float = 1.0, as_json: bool = False) -> int:
    """``sorofem info MESH [--scale S] [--json]``: print the statistics of a mesh file; returns
    the exit code (0)."""
    mesh = read_mesh(path, scale=scale)
    lo, hi = mesh.bounds
    vol = mesh.volumes
    quality = tet_quality(mesh.points, mesh.tets)
    data = {
        "file": str(path),
        "n_nodes": mesh.n_nodes,
        "n_tets": mesh.n_tets,
        "n_boundary_faces": int(mesh.boundary_faces().shape[0]),
        "volume": float(vol.sum()),
        "bounds_min": lo.tolist(),
        "bounds_max": hi.tolist(),
        "min_tet_volume": float(vol.min()),
        "max_tet_volume": float(vol.max()),
        "quality_measure": "radius ratio 3 r_in / r_circ (1 = regular)",
        "min_quality": float(quality.min()),
        "mean_quality": float(quality.mean()),
        "bad_tets": int(np.count_nonzero(quality < BAD_QUALITY)),
        "bad_quality_threshold": BAD_QUALITY,
        "reoriented_tets": int(mesh.reoriented.size),
        "cell_tags": None if mesh.cell_tags is None else {
            int(t): int(n) for t, n in zip(*np.unique(mesh.cell_tags, return_counts=True))
        },
    }
    if as_json:
        sys.stdout.write(json_text(data))
        return 0
    fmt = lambda v: "[" + ", ".join(f"{x:.6g}" for x in v) + "]"  # noqa: E731
    print(f"{path}")
    print(f"  nodes            {mesh.n_nodes}")
    print(f"  tets             {mesh.n_tets}  ({data['reoriented_tets']} reoriented)")
    print(f"  boundary faces   {data['n_boundary_faces']}")
    print(f"  volume           {data['volume']:.6g} m^3")
    print(f"  bounding box     {fmt(lo)} .. {fmt(hi)} (size {fmt(hi - lo)}) m")
    print(f"  tet volume       min {data['min_tet_volume']:.4g}, max {data['max_tet_volume']:.4g} m^3")
    print(f"  quality          radius ratio min {data['min_quality']:.3f}, mean {data['mean_quality']:.3f} (1 = regular)")
    print(f"  bad tets         {data['bad_tets']} with radius ratio < {BAD_QUALITY}")
    if data["cell_tags"] is not None:
        tags = ", ".join(f"{t}: {n}" for t, n in data["cell_tags"].items())
        print(f"  cell tags        {tags} (tag: tets; Gmsh physical group / TetGen region)")
    return 0
