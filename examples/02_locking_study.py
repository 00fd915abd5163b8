"""Volumetric locking of linear tetrahedra, and the mixed formulation that avoids it.

A silicone cantilever (0.4 x 0.1 x 0.1 m, E = 66 kPa, rho = 1080 kg/m^3) is clamped at
x = 0 and sags under gravity. Its tip deflection (minus the mean z-displacement of the
x = L face nodes) is computed on a sequence of geometrically similar meshes (cubic cells
of edge 0.05/k m: 8k x 2k x 2k cells) for nu in {0.45, 0.49, 0.499, 0.4999}, with the
standard displacement formulation and the mixed displacement-pressure one.

Mesh topology matters as much as resolution. The study uses the *uniform* Kuhn split
(every hex cut into six tets around the same main diagonal, :func:`kuhn_box`), on which
P1 locks as the textbooks say. ``sf.Mesh.box`` mirrors the split from hex to hex (the
paper's ``box2.tet`` pattern); on that symmetric mesh the standard elements keep far more
incompressible bending modes and lock only mildly in this problem, at the price of many
more Newton iterations: the "mirrored split" table compares both on the cheap meshes.

Reference: the deflection of the continuum model at each nu is estimated by Richardson
extrapolation of the **mixed** sequence on its three finest meshes, with the order of
convergence observed from those three meshes (the meshes are similar, so the error is
C h^p to leading order). It is checked three ways: the mixed sequence is monotone and the
observed order is near 2 (P1 displacement, nonlinear beam bending); the extrapolation
lies within a few per mille of the finest mixed result; and at nu = 0.45, where P1
standard elements lock only mildly, the standard sequence converges towards the same
value from below.

Physics checked (``result["checks"]``, all must hold; the script exits 1 otherwise):
the mixed deflection on the second mesh (16x4x4) is within 10 % of the reference for
every nu, and at nu >= 0.499 the standard one there is less than a third of it (locking).

Usage::

    python examples/02_locking_study.py [--out DIR] [--full] [--write-table BENCHMARKS.md]

Quick mode (the default, a few seconds) uses the meshes 8x2x2 and 16x4x4 and
extrapolates with the order assumed to be 2. ``--full`` adds 24x6x6, 32x8x8, 48x12x12
and 64x16x16 (mixed only, plus standard at nu = 0.45: about 19k nodes, a minute or two
per solve) and the 1 m cantilever of the paper. ``--write-table`` replaces (or appends)
the section "## Locking study" of the given markdown file and leaves the others alone.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import re
import sys
import time
from pathlib import Path
from typing import Any, Sequence

import numpy as np

import sorofem as sf

WIDTH = 0.1  # m, square cross-section
E = 66e3  # Pa
DENSITY = 1080.0  # kg/m^3
GRAVITY = (0.0, 0.0, -9.81)  # m/s^2
POISSON_RATIOS = (0.45, 0.49, 0.499, 0.4999)
FORMULATIONS = ("standard", "mixed")
#: Refinement levels k: cells (8k, 2k, 2k) of edge 0.05/k m on the 0.4 m beam.
QUICK_LEVELS = (1, 2)
FULL_LEVELS = (1, 2, 3, 4, 6, 8)
#: Levels solved with the mixed formulation only (and standard at nu = 0.45), for time.
MIXED_ONLY_LEVELS = (8,)
#: The 1 m cantilever of the paper: cells (20k, 2k, 2k), same cell sizes.
PAPER_LENGTH = 1.0
PAPER_LEVELS = (1, 2, 3)
#: It hangs nearly vertically: gravity is applied in this many increments.
PAPER_LOAD_STEPS = 10
SECTION = "## Locking study"


def kuhn_box(size: Sequence[float], cells: Sequence[int]) -> sf.Mesh:
    """A box of hexahedra, each split into the six tets around its main diagonal (0,0,0)-(1,1,1),
    the same in every hex. Node (i, j, k) has index i + (nx+1) (j + (ny+1) k)."""
    nx, ny, nz = cells
    axes = [np.linspace(0.0, s, n + 1) for s, n in zip(size, cells)]
    z, y, x = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    points = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
    tets = []
    for k, j, i in itertools.product(range(nz), range(ny), range(nx)):
        for perm in itertools.permutations(range(3)):
            corner = [i, j, k]
            tet = [i + (nx + 1) * (j + (ny + 1) * k)]
            for axis in perm:
                corner[axis] += 1
                tet.append(corner[0] + (nx + 1) * (corner[1] + (ny + 1) * corner[2]))
            tets.append(tet)
    return sf.Mesh(points, np.array(tets, dtype=np.int64))  # odd permutations get reoriented


def cantilever(
    length: float, level: int, nu: float, formulation: str, load_steps: int = 1, split: str = "uniform"
) -> dict[str, Any]:
    """Solve one cantilever; returns its tip deflection (m, positive downwards) and costs.

    ``split``: ``"uniform"`` (:func:`kuhn_box`) or ``"mirrored"`` (``sf.Mesh.box``)."""
    cells = (round(length / WIDTH * 2 * level), 2 * level, 2 * level)
    size = (length, WIDTH, WIDTH)
    mesh = kuhn_box(size, cells) if split == "uniform" else sf.Mesh.box(size=size, cells=cells)
    material = sf.NeoHookean(youngs_modulus=E, poisson_ratio=nu, density=DENSITY)
    body = sf.Body(mesh, material, formulation=formulation)
    clamped = mesh.nodes_on_plane(point=(0, 0, 0), normal=(1, 0, 0))
    body.fix(clamped)
    tip = mesh.nodes_on_plane(point=(length, 0, 0), normal=(1, 0, 0))
    start = time.perf_counter()
    try:
        result = sf.solve_static(body, gravity=GRAVITY, load_steps=load_steps)
    except sf.ConvergenceError as err:
        result = None
        iterations = err.report.iterations
    seconds = time.perf_counter() - start
    unknowns = 3 * (mesh.n_nodes - clamped.size) + (mesh.n_nodes if formulation == "mixed" else 0)
    return {
        "length": length,
        "cells": "x".join(map(str, cells)),
        "split": split,
        "h": WIDTH / (2 * level),
        "nu": nu,
        "formulation": formulation,
        "n_nodes": mesh.n_nodes,
        "unknowns": unknowns,
        "converged": result is not None,
        "deflection": math.nan if result is None else -float(result.displacement[tip, 2].mean()),
        "iterations": iterations if result is None else result.report.iterations,
        "seconds": seconds,
        "volume_change": math.nan if result is None else result.volume_change,
    }


def richardson(h: Sequence[float], d: Sequence[float], order: float | None = None) -> tuple[float, float]:
    """Extrapolate ``d(h) = d0 + C h^p`` to h = 0 from the last two (``order`` given) or the
    last three values (order observed). Returns ``(d0, p)``."""
    h, d = np.asarray(h, dtype=float), np.asarray(d, dtype=float)
    if order is None:
        (h1, h2, h3), (d1, d2, d3) = h[-3:], d[-3:]
        ratio = (d1 - d2) / (d2 - d3)
        if not ratio > 0:
            return math.nan, math.nan  # not in the asymptotic range
        # (h1^p - h2^p) / (h2^p - h3^p) increases with p: bisection.
        lo, hi = 0.1, 8.0
        for _ in range(200):
            p = 0.5 * (lo + hi)
            if (h1**p - h2**p) / (h2**p - h3**p) < ratio:
                lo = p
            else:
                hi = p
        order = 0.5 * (lo + hi)
    (h2, h3), (d2, d3) = h[-2:], d[-2:]
    c = (d2 - d3) / (h2**order - h3**order)
    return float(d3 - c * h3**order), float(order)


def run(out_dir: str | Path, quick: bool = True) -> dict[str, Any]:
    """Run the study; writes ``locking.png``, ``locking.md`` and ``locking.json`` to ``out_dir``.

    Returns a dict with ``rows`` (one per solve), ``reference`` (per nu: extrapolated
    deflection, observed order, finest mixed value), ``table`` (markdown), ``checks``
    (name -> bool), ``paper`` (the 1 m cantilever rows, full mode only) and ``figure``.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    levels = QUICK_LEVELS if quick else FULL_LEVELS
    rows = []
    for level in levels:
        for nu in POISSON_RATIOS:
            for formulation in FORMULATIONS:
                if level in MIXED_ONLY_LEVELS and formulation == "standard" and nu != POISSON_RATIOS[0]:
                    continue
                rows.append(cantilever(0.4, level, nu, formulation))

    reference: dict[float, dict[str, float]] = {}
    for nu in POISSON_RATIOS:
        mixed = [r for r in rows if r["nu"] == nu and r["formulation"] == "mixed"]
        h = [r["h"] for r in mixed]
        d = [r["deflection"] for r in mixed]
        d0, p = richardson(h, d, order=2.0 if len(mixed) < 3 else None)
        reference[nu] = {"deflection": d0, "order": p, "finest_mixed": d[-1], "finest_cells": mixed[-1]["cells"]}
        if len(mixed) >= 3:
            reference[nu]["order2_estimate"] = richardson(h, d, order=2.0)[0]

    mirrored = [
        cantilever(0.4, level, nu, formulation, split="mirrored")
        for level in QUICK_LEVELS
        for nu in POISSON_RATIOS[2:]
        for formulation in FORMULATIONS
    ]

    paper = []
    if not quick:
        for level in PAPER_LEVELS:
            for nu in POISSON_RATIOS:
                for formulation in FORMULATIONS:
                    paper.append(cantilever(PAPER_LENGTH, level, nu, formulation, PAPER_LOAD_STEPS))

    second = levels[1]
    checks = {}
    for nu in POISSON_RATIOS:
        ref = reference[nu]["deflection"]
        at = {r["formulation"]: r["deflection"] for r in rows if r["nu"] == nu and r["h"] == WIDTH / (2 * second)}
        checks[f"mixed within 10% of reference at nu={nu}, level {second}"] = abs(at["mixed"] / ref - 1) < 0.10
        if nu >= 0.499:
            checks[f"standard locks (< 1/3 of reference) at nu={nu}, level {second}"] = at["standard"] < ref / 3

    table = markdown_table(rows, reference, paper, quick, mirrored)
    figure = out / "locking.png"
    plot(rows, reference, figure)
    (out / "locking.md").write_text(table, encoding="utf-8")
    data = {"rows": rows, "reference": reference, "paper": paper, "mirrored": mirrored, "checks": checks, "quick": quick}
    (out / "locking.json").write_text(json.dumps(data, indent=2, default=str) + "\n", encoding="utf-8")
    return {**data, "table": table, "figure": figure}


def markdown_table(
    rows: list[dict[str, Any]],
    reference: dict[float, dict[str, float]],
    paper: list[dict[str, Any]],
    quick: bool,
    mirrored: list[dict[str, Any]] = (),
) -> str:
    """The study as a markdown section (starting with :data:`SECTION`)."""
    lines = [
        SECTION,
        "",
        "Generated by `python examples/02_locking_study.py"
        + ("" if quick else " --full")
        + " --write-table BENCHMARKS.md`.",
        "Silicone cantilever 0.4 x 0.1 x 0.1 m clamped at x = 0, E = 66 kPa, rho = 1080 kg/m^3, "
        "gravity 9.81 m/s^2 along -z, Neo-Hookean with c(J) = ln J; one load step, relative "
        "residual 1e-8. Tip deflection = minus the mean z-displacement of the x = L face nodes, "
        "in mm (linear beam theory would give 616 mm: the beam bends far into the nonlinear range). "
        "Meshes are similar (cubic cells, each split into 6 tets around the same diagonal: the "
        "uniform Kuhn split); \"unknowns\" are free displacements "
        "(+ nodal pressures for mixed); \"it\" = Newton iterations.",
        "",
        "Reference = Richardson extrapolation of the mixed deflections on the three finest meshes "
        "with the observed order p (two meshes and p = 2 in quick mode).",
        "",
        "| nu | reference [mm] | observed p | finest mixed [mm] | p = 2 estimate [mm] |",
        "|---|---|---|---|---|",
    ]
    for nu, ref in reference.items():
        order2 = ref.get("order2_estimate")
        lines.append(
            f"| {nu} | {1e3 * ref['deflection']:.2f} | {ref['order']:.2f} | "
            f"{1e3 * ref['finest_mixed']:.2f} ({ref['finest_cells']}) | "
            f"{'-' if order2 is None else f'{1e3 * order2:.2f}'} |"
        )
    lines += [
        "",
        "Tip deflection [mm] (ratio to the reference), Newton iterations and wall time [s] on a "
        "2-core machine:",
        "",
        "| cells | unknowns std / mixed | nu | standard | mixed | it std / mixed | time std / mixed [s] |",
        "|---|---|---|---|---|---|---|",
    ]
    lines += _rows_table(rows, {nu: ref["deflection"] for nu, ref in reference.items()})
    if mirrored:
        lines += [
            "",
            "Mirrored split (`sf.Mesh.box`: the Kuhn split mirrored from hex to hex, the paper's "
            "box2.tet pattern), same cantilever, ratios to the same reference. On this symmetric mesh "
            "standard P1 keeps enough incompressible bending modes to lock only mildly, but needs "
            "many more Newton iterations:",
            "",
            "| cells | unknowns std / mixed | nu | standard | mixed | it std / mixed | time std / mixed [s] |",
            "|---|---|---|---|---|---|---|",
        ]
        lines += _rows_table(mirrored, {nu: ref["deflection"] for nu, ref in reference.items()})
    if paper:
        lines += [
            "",
            "The 1 m cantilever of the paper (1 x 0.1 x 0.1 m, same material and cell sizes). It hangs "
            "nearly vertically, so its deflection saturates near the length of the beam (plus its "
            "stretch under its own weight) and locking shows much less; gravity in "
            f"{PAPER_LOAD_STEPS} load steps; ratios are to the mixed result on the finest mesh of the same nu:",
            "",
            "| cells | unknowns std / mixed | nu | standard | mixed | it std / mixed | time std / mixed [s] |",
            "|---|---|---|---|---|---|---|",
        ]
        finest = {r["nu"]: r["deflection"] for r in paper if r["formulation"] == "mixed"}
        lines += _rows_table(paper, finest)
    return "\n".join(lines) + "\n"


def _rows_table(rows: list[dict[str, Any]], ref: dict[float, float]) -> list[str]:
    lines = []
    for cells in dict.fromkeys(r["cells"] for r in rows):
        for nu in POISSON_RATIOS:
            pair = {r["formulation"]: r for r in rows if r["cells"] == cells and r["nu"] == nu}
            if "mixed" not in pair:
                continue
            std, mix = pair.get("standard"), pair["mixed"]

            def cell(r: dict[str, Any] | None, key: str, fmt: str) -> str:
                return "-" if r is None else format(r[key], fmt)

            def deflection(r: dict[str, Any] | None) -> str:
                if r is None:
                    return "-"
                if not r["converged"]:
                    return "no convergence"
                return f"{1e3 * r['deflection']:.1f} ({r['deflection'] / ref[nu]:.2f})"

            lines.append(
                f"| {cells} | {cell(std, 'unknowns', 'd')} / {mix['unknowns']} | {nu} | {deflection(std)} | "
                f"{deflection(mix)} | {cell(std, 'iterations', 'd')} / {mix['iterations']} | "
                f"{cell(std, 'seconds', '.2f')} / {mix['seconds']:.2f} |"
            )
    return lines


def plot(rows: list[dict[str, Any]], reference: dict[float, dict[str, float]], path: Path) -> None:
    """Deflection against unknowns (log x), one panel per nu, reference dashed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    fig, axes = plt.subplots(1, len(POISSON_RATIOS), figsize=(4 * len(POISSON_RATIOS), 3.6), sharey=True)
    for ax, nu in zip(axes, POISSON_RATIOS):
        for formulation, style in (("standard", "o-"), ("mixed", "s-")):
            sel = [r for r in rows if r["nu"] == nu and r["formulation"] == formulation]
            ax.semilogx(
                [r["unknowns"] for r in sel], [1e3 * r["deflection"] for r in sel], style, label=formulation
            )
        ax.axhline(1e3 * reference[nu]["deflection"], color="k", ls="--", lw=1, label="reference")
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_title(f"nu = {nu}")
        ax.set_xlabel("unknowns")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("tip deflection [mm]")
    axes[0].set_ylim(bottom=0)
    axes[0].legend(loc="lower right")
    fig.suptitle("0.4 m silicone cantilever under gravity: P1 locking vs mixed P1-P1")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def write_table(path: str | Path, table: str) -> None:
    """Replace the section :data:`SECTION` of a markdown file (up to the next ``## ``
    heading) with ``table``, or append it; the other sections are kept as they are."""
    path = Path(path)
    text = path.read_text(encoding="utf-8") if path.exists() else "# Benchmarks\n"
    pattern = re.compile(rf"^{re.escape(SECTION)}[ \t]*\n.*?(?=^## |\Z)", re.MULTILINE | re.DOTALL)
    if pattern.search(text):
        text = pattern.sub(lambda _: table.rstrip("\n") + "\n\n", text, count=1).rstrip("\n") + "\n"
    else:
        text = text.rstrip("\n") + "\n\n" + table
    path.write_text(text, encoding="utf-8")


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("results/locking"), help="output folder")
    parser.add_argument("--full", action="store_true", help="all meshes and the 1 m cantilever (minutes)")
    parser.add_argument("--write-table", type=Path, metavar="MD", help="write the '## Locking study' section")
    args = parser.parse_args(argv)
    result = run(args.out, quick=not args.full)
    print(result["table"])
    if args.write_table:
        write_table(args.write_table, result["table"])
        print(f"wrote the section '{SECTION}' of {args.write_table}")
    failed = [name for name, ok in result["checks"].items() if not ok]
    for name in failed:
        print(f"CHECK FAILED: {name}", file=sys.stderr)
    print(f"figure: {result['figure']}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
