"""``sorofem sweep``: solve many variants of a scene (:func:`sorofem.sweep`).

Usage::

    sorofem sweep SCENE.toml --out DIR [--grid KEY=V1,V2,...]... [--sample KEY=LO:HI]...
                  [--samples N] [--seed S] [--cases FILE.csv|FILE.parquet]
                  [--save displacement] [--marker X,Y,Z]... [--workers N | --scheduler ADDRESS]
                  [--batch-size N] [--strict] [--force] [--quiet] [--json]

Writes ``DIR/results.parquet`` (one row per case), ``DIR/cases.parquet``, ``DIR/sweep.json`` and,
with ``--save displacement``, ``DIR/fields.zarr``. Rerunning the same command resumes: only the
cases without a row are solved. Exit codes: 0 done (cases that did not converge are rows with
``converged = false``, counted in the last line); 2 bad input (a key, a value, no case, an
``--out`` holding another sweep, an unreachable scheduler); 3 with ``--strict`` when a case
failed; 130 interrupted (rerun to resume).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from ..errors import InputError
from ._cases import parse_key, parse_values
from ._run import sweep
from ._solve import FIELDS
from ._store import Store

__all__ = ["add_arguments", "run_command"]

EXIT_OK, EXIT_INPUT, EXIT_SOLVER, EXIT_INTERRUPTED = 0, 2, 3, 130


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``sorofem sweep`` (the command line's parser calls this)."""
    parser.add_argument("scene", type=Path, help="TOML scene file")
    parser.add_argument("--out", type=Path, metavar="DIR", required=True,
                        help="the sweep's folder (created; rerun the same command on it to resume)")
    parser.add_argument("--grid", action="append", default=[], metavar="KEY=V1,V2,...",
                        help="sweep a dotted scene key over values (several --grid: the Cartesian product)")
    parser.add_argument("--sample", action="append", default=[], metavar="KEY=LO:HI",
                        help="draw a number key in [LO, HI] (Latin hypercube, with --samples)")
    parser.add_argument("--samples", type=int, metavar="N", help="number of --sample draws")
    parser.add_argument("--seed", type=int, default=0, help="seed of the samples (default 0)")
    parser.add_argument("--cases", type=Path, metavar="FILE", help="a .csv or .parquet table of cases, one column per key")
    parser.add_argument("--save", action="append", default=[], choices=FIELDS,
                        help="also keep this full field of every case in DIR/fields.zarr")
    parser.add_argument("--marker", action="append", default=[], metavar="X,Y,Z",
                        help="follow this rest point (m, inside the mesh) (default: the scene's [target] points)")
    parser.add_argument("--workers", type=int, metavar="N", help="local worker processes (default: one per core)")
    parser.add_argument("--scheduler", metavar="ADDRESS", help="run on the Dask cluster of this scheduler (tcp://HOST:PORT)")
    parser.add_argument("--batch-size", type=int, metavar="N", help="cases sent to a worker at once")
    parser.add_argument("--strict", action="store_true", help="exit 3 when a case did not converge")
    parser.add_argument("--force", action="store_true", help="replace another sweep held in --out")
    parser.add_argument("--quiet", action="store_true", help="print nothing on success")
    parser.add_argument("--json", action="store_true", help="print the run's counts as JSON")


def _pairs(items: list[str], option: str) -> dict[str, str]:
    out: dict[str, str] = {}
    for item in items:
        name, sep, rest = item.partition("=")
        if not sep or not name.strip():
            raise InputError(f"{option} {item!r}: expected KEY=VALUES, e.g. {option} material.youngs_modulus=50e3,66e3")
        if name.strip() in out:
            raise InputError(f"{option}: {name.strip()} given twice")
        out[name.strip()] = rest
    return out


def _marker(text: str) -> list[float]:
    try:
        point = [float(v) for v in text.split(",")]
    except ValueError:
        point = []
    if len(point) != 3:
        raise InputError(f"--marker {text!r}: expected X,Y,Z (three numbers, m)")
    return point


def run_command(args: argparse.Namespace) -> int:
    """Run ``sorofem sweep`` from parsed arguments; returns the exit code (errors propagate
    to the command line, which maps them to exit 2)."""
    grid = {}
    for name, text in _pairs(args.grid, "--grid").items():
        grid[name] = parse_values(parse_key(name, "--grid"), text, "--grid")
    sample = {}
    for name, text in _pairs(args.sample, "--sample").items():
        lo, sep, hi = text.partition(":")
        try:
            sample[name] = (float(lo), float(hi))
        except ValueError:
            sep = ""
        if not sep:
            raise InputError(f"--sample {name}={text}: expected LO:HI, e.g. --sample {name}=0.6:1.0")
    if args.cases is not None and (grid or sample):
        raise InputError("--cases: give a table of cases or --grid/--sample, not both")
    markers = [_marker(m) for m in args.marker] or None
    log = (lambda line: None) if args.quiet or args.json else (lambda line: print(line, flush=True))
    try:
        result = sweep(
            args.scene, args.out, grid=grid or None, sample=sample or None, samples=args.samples, seed=args.seed,
            cases=args.cases, save=args.save, markers=markers, workers=args.workers, scheduler=args.scheduler,
            batch_size=args.batch_size, force=args.force, progress=False if args.quiet else None, log=log,
        )
    except KeyboardInterrupt:
        done = _done(args.out)
        print(f"error: interrupted{done}; rerun the same command to resume", file=sys.stderr)
        return EXIT_INTERRUPTED
    if args.json:
        sys.stdout.write(json.dumps(result.to_dict(), indent=2) + "\n")
    elif not args.quiet:
        rate = f" ({result.solved / result.time:.3g} cases/s)" if result.solved and result.time > 0 else ""
        print(f"solved {result.solved} case(s) in {result.time:.3g} s{rate}; {result.n_cases} of {result.n_cases} "
              f"cases in {result.out / 'results.parquet'}")
    if result.failed:
        print(f"{'error' if args.strict else 'warning'}: {result.failed} of {result.n_cases} case(s) did not "
              "converge (rows with converged = false; see their error column)", file=sys.stderr)
        if args.strict:
            return EXIT_SOLVER
    return EXIT_OK


def _done(out: Path) -> str:
    try:
        store = Store(out)
        manifest = store.manifest() or {}
        return f" with {len(store.done())} of {manifest.get('n_cases', '?')} cases written to {out}"
    except Exception:  # noqa: BLE001 - only a message; the interruption is what matters
        return ""
