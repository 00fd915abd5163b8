"""``sorofem fit-material``: fit a hyperelastic model to test-data CSV files.

Usage::

    sorofem fit-material DATA.csv [MORE.csv ...] --model yeoh [--terms N] [--mode MODE]
                         [--bulk-modulus K] [--stress-unit kPa] [--weights relative|absolute]
                         [--out DIR] [--quiet]

Prints the fit (parameters rounded to their standard errors, stability ranges, warnings) and
writes ``DIR/fit.json`` (:meth:`~sorofem.fitting.MaterialFit.to_dict`) and ``DIR/fit.png``
(data against fit). ``DIR`` defaults to the current directory; each file is written under a
temporary name and renamed, and never over one of the input files.

A CSV without a ``# mode:`` line takes ``--mode``; a file's own ``# mode:`` line wins (the
summary lists the mode each file was fitted as).
Exit codes: 0 success; 2 bad input (a message naming the file and line, or the argument);
3 the fit did not converge (the cost history is printed).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path
from typing import Sequence

from ..errors import ConvergenceError, InputError, SolverError
from .curves import MODES
from .fit import fit_material
from .models import MODELS

__all__ = ["_cli"]

EXIT_OK, EXIT_INPUT, EXIT_SOLVER = 0, 2, 3


class _Parser(argparse.ArgumentParser):
    """argparse that raises instead of exiting, so that ``_cli`` returns 2 with one line."""

    def error(self, message: str) -> None:  # type: ignore[override]
        raise InputError(message)


def _parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="sorofem fit-material", description="Fit a hyperelastic model to homogeneous test data.")
    parser.add_argument("data", nargs="+", type=Path, metavar="DATA.csv",
                        help="test curves: columns stretch (or strain) and nominal_stress")
    parser.add_argument("--model", required=True, choices=MODELS)
    parser.add_argument("--terms", type=int, help="yeoh: coefficients c10..c30 fitted; ogden: term pairs (1-3)")
    parser.add_argument("--mode", choices=MODES, help="test mode of files without a '# mode:' line (theirs wins)")
    parser.add_argument("--bulk-modulus", type=float, metavar="K", help="Pa; compressible curves (default incompressible)")
    parser.add_argument("--stress-unit", metavar="UNIT", help="Pa, kPa, MPa, GPa or psi, for files that name none")
    parser.add_argument("--weights", choices=("relative", "absolute"), default="relative")
    parser.add_argument("--out", type=Path, default=Path("."), metavar="DIR", help="output folder (default .)")
    parser.add_argument("--quiet", action="store_true", help="print nothing on success")
    return parser


def _cli(argv: Sequence[str]) -> int:
    """Run ``sorofem fit-material`` with ``argv`` (the arguments after the command name);
    returns the exit code. Errors are one ``error: ...`` line on stderr."""
    try:
        args = _parser().parse_args(list(argv))
    except SystemExit as exc:  # --help
        return exc.code if isinstance(exc.code, int) else EXIT_OK
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_INPUT
    try:
        fit = fit_material(args.model, [str(p) for p in args.data], terms=args.terms, bulk_modulus=args.bulk_modulus,
                           mode=args.mode, stress_unit=args.stress_unit, weights=args.weights)
        outputs = {"fit.json": args.out / "fit.json", "fit.png": args.out / "fit.png"}
        _refuse_inputs(outputs.values(), args.data)
        args.out.mkdir(parents=True, exist_ok=True)
        text = json.dumps(fit.to_dict(), indent=2, allow_nan=False) + "\n"
        _write_atomic(outputs["fit.json"], lambda f: f.write(text.encode()))
        figure = fit.plot()
        _write_atomic(outputs["fit.png"], lambda f: figure.savefig(f, format="png"))
    except ConvergenceError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_SOLVER
    except (InputError, FileNotFoundError, IsADirectoryError, NotADirectoryError, PermissionError) as exc:
        print(f"error: {_one_line(exc)}", file=sys.stderr)
        return EXIT_INPUT
    except SolverError as exc:
        print(f"error: {_one_line(exc)}", file=sys.stderr)
        return EXIT_SOLVER
    if not args.quiet:
        print(fit.summary())
        print(f"wrote {outputs['fit.json']} and {outputs['fit.png']}")
    return EXIT_OK


def _one_line(exc: BaseException) -> str:
    text = str(exc) or type(exc).__name__
    if isinstance(exc, OSError) and exc.filename is not None and exc.strerror:
        text = f"{exc.strerror}: {exc.filename}"
    return " ".join(text.split())


def _refuse_inputs(outputs, inputs: Sequence[Path]) -> None:
    for out in outputs:
        for source in inputs:
            if out.exists() and source.exists() and os.path.samefile(out, source):
                raise InputError(f"refusing to write {out}: it is an input file (choose another --out)")


def _write_atomic(path: Path, write) -> None:
    """Write through a temporary file in the same folder, then rename it over ``path``."""
    handle = tempfile.NamedTemporaryFile(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp", delete=False)
    try:
        with handle:
            write(handle)
        os.replace(handle.name, path)
    except BaseException:
        Path(handle.name).unlink(missing_ok=True)
        raise
