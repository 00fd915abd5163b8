"""The ``sorofem`` command.

Usage::

    sorofem run SCENE.toml [--out DIR] [--quiet] [--json]
    sorofem estimate SCENE.toml [--out DIR] [--quiet] [--json] [--history FILE] [--resume]
    sorofem control SCENE.toml [--out DIR] [--quiet] [--json]
    sorofem info MESH [--scale S] [--json]
    sorofem convert IN OUT [--scale S] [--quiet]
    sorofem view SCENE.toml | RUN_DIR | FILE.pvd [--trajectory] [--port P] [--host H]
    sorofem schema [--out FILE [--force]]
    sorofem sweep SCENE.toml --out DIR [--grid KEY=V1,V2,...] [--sample KEY=LO:HI --samples N] ...
    sorofem --version

``run`` writes ``DIR/result.vtu``, ``DIR/summary.json``, ``DIR/shape.png`` and
``DIR/convergence.png`` (and ``DIR/deformed.vtu`` with ``[output] deformed = true``). It only
ever writes those names, each through a temporary file renamed over it, and marks them with a
run id (:class:`sorofem.io.RunFolder`: ``summary.json`` says ``"complete": false`` until
everything is written; an earlier run's frames in ``trajectory/`` are removed, its other files
reported as ``stale_outputs``). ``result.vtu`` holds the **rest** mesh with the point data
``displacement`` (the finite-element convention: ParaView's Warp By Vector on it shows the
deformed body); ``deformed.vtu`` the same data on the deformed mesh.
``summary.json`` records, besides the solver report, the volume bookkeeping
``volume_change`` ((V_deformed - V_rest) / V_rest) and ``mean_log_j`` (sum V_e ln J_e / V),
and for ``kind = "mixed"`` the pressure range ``min_pressure``/``max_pressure`` (Pa); the
pressure field itself is the point data ``pressure`` of ``result.vtu``. With ``[[cable]]``
entries, ``run`` also writes ``DIR/cables.vtu`` (the cables as lines, with tension) and
``summary.json`` gets ``cables``: per cable its model and command (alpha, or a tendon's pull or
tension), its tension (a tendon's one number) and pull ``L0 - L``, segment tensions and where each point
was placed. A scene with ``[dynamics]`` is integrated in time instead: ``run`` writes
``DIR/trajectory.pvd`` with the frames in ``DIR/trajectory/``, ``DIR/trajectory.png`` (displacement
and kinetic energy against time) and ``DIR/summary.json`` (steps, Newton iterations, cutbacks,
energies, final cable tensions).

The output folder ``DIR`` is ``--out DIR`` or, without it, the scene's ``[output] directory``
(relative to the scene file); ``--out`` wins when both are given. ``[output]`` also switches
each file off (``summary``, ``vtu``, ``png``, ``cables``, ``pvd``; all on by default) and picks
the field that colours ``shape.png`` (``color_by``). Whatever is switched on, ``run`` refuses to
write over a file the scene reads (the scene, its mesh, its ``[target]`` surfaces).

``estimate`` fits the scene's ``[estimate]`` parameters so that its equilibrium meets
``[target]`` (:func:`sorofem.estimate`); ``control`` finds the actuations of the ``[control]``
cables that bring ``[target]`` closest (:func:`sorofem.control`). Both use the scene's gravity
and ``[solver]`` options (the Newton tolerance no looser than 1e-10) and write ``DIR/summary.json`` (estimate: the parameters, the material
as (mu, lambda) and (E, nu), the residual, forward solves and history; control: actuation,
distance, reachable, forward solves, history), ``DIR/result.vtu`` (the final equilibrium) and
``DIR/fit.png`` (goal against model points, misfit history). ``estimate`` prints each parameter
with its standard error (rounded to it), says which ones ended on a bound (no standard error
there: the covariance is that of the others, with them held), and, when the fit is poorly
conditioned, profiles the misfit along the worst determined parameter (``summary.json``
``profile``, ``DIR/profile.png``).
An estimate that does not converge, or a control target that is not reachable, exits 3
(the outputs are still written). They follow ``[output]`` ``directory``, ``summary`` and ``vtu``.
With ``[dynamics]`` they work in time (:meth:`sorofem.Scene.estimate_dynamics`,
:meth:`~sorofem.Scene.control_dynamics`): ``estimate`` fits the run to the ``[target]`` tracks
(``mass_damping``, ``stiffness_damping`` and scalar material parameters), ``control`` finds the
``[control]`` cables' schedule at ``keyframe_times`` that reaches ``[target]`` at
``reach_time`` and holds it; both write ``DIR/summary.json`` and ``DIR/trajectory.png`` (the
run found; ``estimate`` also ``DIR/fit.png``), no ``result.vtu`` nor history.

``sweep`` solves many variants of a scene, overriding keys by their dotted names, on a Dask
cluster, one row per case in ``DIR/results.parquet`` (:mod:`sorofem.sweeps.cli`; needs
the extra ``cluster``).

``schema`` prints the JSON Schema of scene files (:func:`sorofem.scene.json_schema`), or
writes it to ``--out FILE``; it never overwrites an existing file unless ``--force`` is given.
Editors use it to complete and check scene files (a ``#:schema ./scene.schema.json`` first
line, for VS Code's Even Better TOML or taplo).

Exit codes: 0 success; 2 bad input (scene, mesh or arguments: one ``error: ...`` line on
stderr); 3 the solver failed (``summary.json`` is still written, unless switched off, with
``"converged": false`` and the solver report); 4 an output could not be written (disk full,
file-size limit, permission: the message names the file); 130 and 143 stopped by SIGINT
(Ctrl-C) or SIGTERM (the outputs written are whole, ``summary.json`` says
``"complete": false``); 1 an unexpected error (a bug: please report it with the traceback).
``estimate --history FILE`` (default ``DIR/history.jsonl``) records every iterate as it goes,
and ``--resume`` goes on with an interrupted run.

Examples
--------
>>> from sorofem.cli import main
>>> main(["run", "cantilever.toml", "--out", "results/cantilever"])  # doctest: +SKIP
0
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
import traceback
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator, Sequence

from ._text import plural
from ._version import __version__
from .cables import placement_counts, write_cables
from .convert import run_command as convert_command
from .dynamics import PvdWriter
from .errors import ConvergenceError, InputError, Interrupted, OutputError, SolverError
from .inverse import DEFAULT_TOLERANCE, control, estimate
from .io import RunFolder, atomic_path, write_result, write_text
from .mesh_info import run_command as info_command
from .plot import plot_convergence, plot_fit, plot_profile, plot_rest_and_deformed, plot_trajectory
from .progress import default as progress_default
from .scene import Scene, schema_text
from .solver import SolveReport
from .sweeps import cli as sweep_cli
from .viewer import serve as view_command

__all__ = ["main"]

EXIT_OK, EXIT_UNEXPECTED, EXIT_INPUT, EXIT_SOLVER, EXIT_OUTPUT = 0, 1, 2, 3, 4
#: 128 + the signal's number, as shells report a process a signal ended.
EXIT_SIGINT, EXIT_SIGTERM = 128 + signal.SIGINT, 128 + signal.SIGTERM
OUTPUT_NAMES = ("result.vtu", "summary.json", "shape.png", "convergence.png")
#: Written besides OUTPUT_NAMES when the scene has cables.
CABLE_OUTPUT_NAMES = ("cables.vtu",)
#: Written instead of OUTPUT_NAMES for a scene with [dynamics] (trajectory/ holds the frames).
DYNAMICS_OUTPUT_NAMES = ("trajectory.pvd", "trajectory", "summary.json", "trajectory.png")
#: Every name `run` may write in its folder (sorofem.io.RunFolder: the stale ones are reported).
RUN_OWNED = tuple(dict.fromkeys(OUTPUT_NAMES + CABLE_OUTPUT_NAMES + ("deformed.vtu",) + DYNAMICS_OUTPUT_NAMES))
#: What `estimate` and `control` write (history.jsonl: estimate's, unless --history names another file;
#: trajectory.png: theirs for a scene with [dynamics], which write no result.vtu nor history).
INVERSE_OUTPUT_NAMES = ("summary.json", "result.vtu", "fit.png", "profile.png", "history.jsonl", "trajectory.png")


class _UsageError(Exception):
    pass


class _Parser(argparse.ArgumentParser):
    """argparse that raises instead of printing usage, so every input error is one line."""

    def error(self, message: str) -> None:  # type: ignore[override]
        raise _UsageError(f"{message} (see '{self.prog} --help')")


#: The epilog of ``sorofem --help``.
EPILOG = """\
examples:
  sorofem run examples/scenes/cantilever.toml --out results/cantilever
  sorofem run examples/scenes/dynamics.toml --out results/dynamics       # [dynamics]: a trajectory
  sorofem estimate examples/scenes/estimate.toml --out results/estimate  # fit [estimate] to [target]
  sorofem control examples/scenes/control.toml --out results/control     # cable actuations for [target]
  sorofem estimate examples/scenes/swing_estimate.toml --out results/swing  # [dynamics]: damping from tracks
  sorofem control examples/scenes/schedule.toml --out results/schedule   # [dynamics]: a cable schedule
  sorofem info robot.msh --scale 1e-3                                    # mesh statistics and quality
  sorofem convert robot.msh robot.vtu                                    # see 'sorofem convert --help'
  sorofem schema --out scene.schema.json                                 # for editors

exit codes:
  0    success
  2    bad input: scene, mesh or arguments (one 'error: ...' line on stderr)
  3    the solver failed, an estimate did not converge or a control target is not reachable
       (summary.json is still written)
  4    an output could not be written (disk full, file-size limit, permission)
  1    unexpected error (a bug: please report it with the traceback)
  130  interrupted by Ctrl-C (SIGINT), 143 by SIGTERM: summary.json says "complete": false

documentation: docs/cli.md, docs/scene.md and docs/guarantees.md, or 'sorofem COMMAND --help'"""

#: The epilog of ``sorofem convert --help``: what each output suffix writes.
CONVERT_EPILOG = """\
output formats (by the suffix of OUT):
  .tet                 sorofem's text format (full float precision)
  .msh                 Gmsh 4.1 ASCII
  .node, .ele          TetGen (both STEM.node and STEM.ele are written)
  .stl .obj .ply .off  the boundary surface (outward-oriented triangles)
  .vtu .vtk .mesh ...  any other volume format meshio writes (the tetrahedra)

input formats: .tet, Gmsh .msh (2.2, 4.x), TetGen .node/.ele, and any volume mesh meshio reads
(.vtu, .vtk, .mesh, ...). A surface (.stl, .obj) is not a volume mesh: fill it with tetrahedra by
sf.tetrahedralize or a scene's [mesh] surface = "robot.stl".

example:
  sorofem convert robot_mm.msh robot.vtu --scale 1e-3"""


def _build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="sorofem", description="Simulate, calibrate and control cable-driven silicone soft robots.",
                     epilog=EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"sorofem {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True

    run = sub.add_parser("run", help="solve a scene file and write results")
    run.add_argument("scene", type=Path, help="TOML scene file")
    run.add_argument("--out", type=Path, metavar="DIR",
                     help="output folder (created); overrides the scene's [output] directory")
    run.add_argument("--quiet", action="store_true", help="print nothing on success")
    run.add_argument("--json", action="store_true", help="print summary.json to stdout instead of text")

    for name, text in (("estimate", "fit the scene's [estimate] parameters to its [target]"),
                       ("control", "find the [control] cable actuations that reach the scene's [target]")):
        inv = sub.add_parser(name, help=text)
        inv.add_argument("scene", type=Path, help="TOML scene file with [target] and [" + name + "]")
        inv.add_argument("--out", type=Path, metavar="DIR",
                         help="output folder (created); overrides the scene's [output] directory")
        inv.add_argument("--quiet", action="store_true", help="print nothing on success")
        inv.add_argument("--json", action="store_true", help="print summary.json to stdout instead of text")
        if name == "estimate":
            inv.add_argument("--history", type=Path, metavar="FILE",
                             help="write each iterate to FILE as it goes (default DIR/history.jsonl)")
            inv.add_argument("--resume", action="store_true",
                             help="go on with the interrupted run recorded in the history file")

    info = sub.add_parser("info", help="print statistics of a mesh file")
    info.add_argument("mesh", type=Path, help="mesh file (.tet or any format meshio reads)")
    info.add_argument("--scale", type=float, default=1.0, help="coordinate scale factor (default 1)")
    info.add_argument("--json", action="store_true", help="print as JSON")

    convert = sub.add_parser("convert", help="convert a mesh file to another format (.tet, .msh, .node/.ele, .vtu, "
                             ".stl, ...)", description="Convert a tetrahedral mesh to the format of OUT's suffix.",
                             epilog=CONVERT_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    convert.add_argument("input", type=Path, metavar="IN", help="mesh file (.tet or any format meshio reads)")
    convert.add_argument("output", type=Path, metavar="OUT", help="output file; its suffix picks the format")
    convert.add_argument("--scale", type=float, default=1.0, help="coordinate scale factor (default 1)")
    convert.add_argument("--quiet", action="store_true", help="print nothing on success")

    view = sub.add_parser("view", help="interactive 3-D view in the browser (extra 'viewer': pip install \".[viewer]\")")
    view.add_argument("scene", type=Path,
                      help="TOML scene file, or a .pvd / the --out folder of a dynamic run (played back)")
    view.add_argument("--trajectory", action="store_true", help="simulate the scene's [dynamics] and play it")
    view.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    view.add_argument("--port", type=int, default=8080, help="port (default 8080)")

    schema = sub.add_parser("schema", help="print the JSON Schema of scene files (for editors)")
    schema.add_argument("--out", type=Path, metavar="FILE", help="write it to FILE instead of printing it")
    schema.add_argument("--force", action="store_true", help="overwrite FILE if it exists")

    sweep_cli.add_arguments(sub.add_parser("sweep", help="solve many variants of a scene on a Dask cluster "
                                           "(needs the extra cluster)"))
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit code (see the module docstring)."""
    try:
        with _sigterm_interrupts():
            args = _build_parser().parse_args(argv)
            # --quiet silences the progress line too; otherwise it shows only on a terminal.
            with progress_default(False if getattr(args, "quiet", False) else None):
                return _dispatch(args)
    except OutputError as exc:
        print(f"error: {_one_line(exc)}", file=sys.stderr)
        return EXIT_OUTPUT
    except (_UsageError, InputError, FileNotFoundError, NotADirectoryError, IsADirectoryError,
            PermissionError) as exc:
        print(f"error: {_one_line(exc)}", file=sys.stderr)
        return EXIT_INPUT
    except SolverError as exc:
        print(f"error: solver failed: {_one_line(exc)}", file=sys.stderr)
        return EXIT_SOLVER
    except SystemExit as exc:  # --help and --version exit through argparse
        return exc.code if isinstance(exc.code, int) else EXIT_OK
    except KeyboardInterrupt as exc:
        name = getattr(exc, "signal", "SIGINT")
        print(f"error: interrupted by {name}", file=sys.stderr)
        return EXIT_SIGTERM if name == "SIGTERM" else EXIT_SIGINT
    except Exception:  # noqa: BLE001 - last resort: report a bug with its traceback
        traceback.print_exc()
        print("error: unexpected internal error (a bug; please report it with the traceback above)",
              file=sys.stderr)
        return EXIT_UNEXPECTED


def _dispatch(args: argparse.Namespace) -> int:
    """Runs the parsed command; errors propagate to :func:`main`."""
    if args.command == "run":
        return _run(args)
    if args.command in ("estimate", "control"):
        return _inverse(args)
    if args.command == "convert":
        return convert_command(args.input, args.output, args.scale, quiet=args.quiet)
    if args.command == "view":
        return view_command(args.scene, host=args.host, port=args.port, trajectory=args.trajectory)
    if args.command == "schema":
        return _schema(args)
    if args.command == "sweep":
        return sweep_cli.run_command(args)
    return info_command(args.mesh, args.scale, as_json=args.json)


def _one_line(exc: BaseException) -> str:
    text = str(exc) or type(exc).__name__
    if isinstance(exc, OSError) and exc.filename is not None and exc.strerror:
        text = f"{exc.strerror}: {exc.filename}"
    return " ".join(text.split())


@contextmanager
def _sigterm_interrupts() -> Iterator[None]:
    """Within the block SIGTERM stops the run as Ctrl-C does (an :class:`Interrupted` with
    ``signal="SIGTERM"``), so that it leaves marked, consistent outputs; only in the main
    thread, where Python runs signal handlers."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def stop(signum: int, frame: Any) -> None:
        raise Interrupted("terminated", signal="SIGTERM")

    previous = signal.signal(signal.SIGTERM, stop)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


# ---------------------------------------------------------------------------
# run


def _output_folder(args: argparse.Namespace, scene: Any) -> tuple[Path, str]:
    """The folder to write to and how to name it in messages: ``--out`` wins over the scene's
    ``[output] directory`` (resolved against the scene file's folder)."""
    if args.out is not None:
        out, label = Path(args.out), "--out"
    elif scene.output["directory"] is not None:
        out, label = Path(scene.output["directory"]), f"{scene.path}: [output] directory"
    else:
        raise InputError(
            f"no output folder: pass --out DIR, or set [output] directory = \"...\" in {scene.path} "
            "(relative to the scene file)"
        )
    if out.exists() and not out.is_dir():
        raise InputError(f"{label}: {out} exists and is not a folder")
    return out, label


def _selected_outputs(scene: Any) -> list[str]:
    """The names ``run`` writes for ``scene``: what it produces, less what ``[output]`` turns off."""
    switches = scene.output
    if scene.dynamics is not None:
        wanted = {"trajectory.pvd": "pvd", "trajectory": "pvd", "summary.json": "summary", "trajectory.png": "png"}
        names = DYNAMICS_OUTPUT_NAMES
    else:
        wanted = {"result.vtu": "vtu", "summary.json": "summary", "shape.png": "png", "convergence.png": "png",
                  "cables.vtu": "cables", "deformed.vtu": "deformed"}
        names = OUTPUT_NAMES + (CABLE_OUTPUT_NAMES if scene.cables else ()) + ("deformed.vtu",)
    return [name for name in names if switches[wanted[name]]]


def _refuse_inputs(outputs: dict[str, Path], scene: Any, label: str) -> None:
    """Never write over a file the scene reads (the scene, its mesh, its target surfaces), nor
    put a trajectory frame where one of them is."""
    for source in scene.input_files:
        source = Path(source).resolve()
        for name, target in outputs.items():
            clash = target.resolve() == source
            if name == "trajectory":  # the folder of the frames trajectory/frame_NNNNN.vtu
                clash = clash or (source.parent == target.resolve() and source.name.startswith("frame_"))
            if clash:
                raise InputError(f"{label}: writing {name} would overwrite the input file {source}")


def _report_in(outputs: dict[str, Path]) -> str:
    return f" (report in {outputs['summary.json']})" if "summary.json" in outputs else ""


def _wrote(outputs: dict[str, Path], out: Path, extra: str = "") -> str:
    if not outputs:
        return "wrote nothing: [output] switches every file off"
    return f"wrote {', '.join(outputs)}{extra} to {out}"


def _run(args: argparse.Namespace) -> int:
    scene = Scene.load(args.scene)
    out, label = _output_folder(args, scene)
    outputs = {name: out / name for name in _selected_outputs(scene)}
    _refuse_inputs(outputs, scene, label)
    run = RunFolder(out, outputs, RUN_OWNED, frames="trajectory")

    base = {
        "scene": str(scene.path),
        "n_nodes": scene.mesh.n_nodes,
        "n_tets": scene.mesh.n_tets,
        "formulation": scene.formulation,
        "formulation_options": scene.body.formulation_options,
        "material": scene.material.to_dict(),
        "gravity": scene.gravity.tolist(),
        "solver_options": scene.solve_options.to_dict(),
    }
    try:
        run.start(base)
        _warn_stale(run)
        if scene.dynamics is not None:
            return _run_dynamics(args, scene, run, base)
        return _run_static(args, scene, run, base)
    except (KeyboardInterrupt, OutputError) as exc:
        run.stopped(_stop_status(exc))
        raise


def _run_static(args: argparse.Namespace, scene: Any, run: RunFolder, base: dict[str, Any]) -> int:
    """``run`` for a static scene: result.vtu, cables.vtu, shape.png, convergence.png, summary.json."""
    outputs = run.outputs
    try:
        result = scene.solve()
    except SolverError as exc:
        # Still leave a summary behind: it is what a user (or a script) inspects first.
        raw = getattr(exc, "report", None)
        report = raw if isinstance(raw, SolveReport) else SolveReport.from_dict(raw or {}, scene.formulation)
        summary = {
            **base,
            "converged": False,
            "newton_iterations": report.iterations,
            "residual_norm": report.residual_norm,
            "max_displacement": None,
            "timings": report.timings,
            "error": str(exc),
            "report": report.to_dict(),
        }
        if report.residual_history and "convergence.png" in outputs:
            with atomic_path(outputs["convergence.png"]) as png:
                plot_convergence(report, png, tolerance=scene.solve_options.tolerance)
        text = run.write_summary(summary, complete=True, status="failed")
        if args.json:
            sys.stdout.write(text)
        what = "did not converge" if isinstance(exc, ConvergenceError) else "failed"
        print(f"error: solver {what}: {_one_line(exc)}{_report_in(outputs)}", file=sys.stderr)
        return EXIT_SOLVER

    summary = {**base, **result.to_dict()}
    try:
        if "result.vtu" in outputs:
            write_result(outputs["result.vtu"], result, run_id=run.run_id)
        if "deformed.vtu" in outputs:
            write_result(outputs["deformed.vtu"], result, points="deformed", run_id=run.run_id)
        if "cables.vtu" in outputs:
            write_cables(outputs["cables.vtu"], result, run_id=run.run_id)
        if "shape.png" in outputs:
            color_by = scene.output["color_by"]
            field = "" if color_by == "displacement" else f", coloured by {color_by}"
            with atomic_path(outputs["shape.png"]) as png:
                plot_rest_and_deformed(result, png, color_by=color_by,
                                       title=f"{scene.path.name}: max |u| = {result.max_displacement:.3g} m{field}")
        if "convergence.png" in outputs:
            with atomic_path(outputs["convergence.png"]) as png:
                plot_convergence(result.report, png, tolerance=scene.solve_options.tolerance)
    except (KeyboardInterrupt, OutputError) as exc:
        _unfinished(run, summary, exc)
        raise
    text = run.write_summary(summary, complete=True, status="complete")
    if args.json:
        sys.stdout.write(text)
    elif not args.quiet:
        options = ", ".join(f"{k} {v}" for k, v in scene.body.formulation_options.items())
        print(f"{scene.path.name}: {scene.mesh.n_nodes} nodes, {scene.mesh.n_tets} tets, "
              f"{scene.formulation} ({options})")
        print(result.report.summary())
        print(f"max displacement {result.max_displacement:.6g} m, min J {result.J.min():.4f}, "
              f"max von Mises {result.von_mises.max():.4g} Pa")
        print(f"volume change {result.volume_change:.3e}, mean ln J {result.mean_log_j:.3e}")
        if result.pressure is not None:
            print(f"pressure {result.pressure.min():.4g} .. {result.pressure.max():.4g} Pa")
        for c, tension in enumerate(result.cable_tensions):
            kind, value = result.commands[c]
            if kind == "actuation":
                print(f"cable {c}: alpha {value:g}, tension {tension.min():.4g} .. {tension.max():.4g} N")
            else:
                print(f"cable {c} (tendon, {kind} {value:g} {'m' if kind == 'pull' else 'N'}): tension "
                      f"{result.cable_tension[c]:.6g} N, pull {result.cable_pull[c]:.6g} m")
        print(_wrote(outputs, run.folder))
    return EXIT_OK


def _stop_status(exc: BaseException) -> str:
    if isinstance(exc, OutputError):
        return f"failed: {exc}"
    return f"interrupted by {getattr(exc, 'signal', 'SIGINT')}"


def _unfinished(run: RunFolder, summary: dict[str, Any], exc: BaseException) -> None:
    """Mark the summary of a run stopped while writing its outputs, with what it has."""
    run.summary = summary
    run.stopped(_stop_status(exc))


def _warn_stale(run: RunFolder) -> None:
    if run.stale:
        print(f"warning: {', '.join(run.stale)} in {run.folder} are from an earlier run (this one does not write "
              "them); see stale_outputs in summary.json", file=sys.stderr)


def _run_dynamics(args: argparse.Namespace, scene: Any, run: RunFolder, base: dict[str, Any]) -> int:
    """``run`` for a scene with ``[dynamics]``: trajectory.pvd + frames (written while the
    integration goes), summary.json, trajectory.png."""
    outputs = run.outputs
    base = {**base, "dynamics": scene.to_dict()["dynamics"]}
    if scene.cables:
        base["cables"] = [
            {"rest_length": c.length, "stiffness": c.stiffness, "placements": [p.kind for p in placements],
             "placement_counts": placement_counts(placements)}
            for c, placements in zip(scene.cables, scene.body.cable_placements())
        ]
    writer = PvdWriter(scene.body, run.folder, "trajectory", run_id=run.run_id) if "trajectory.pvd" in outputs else None
    try:
        trajectory = scene.simulate(on_frames=None if writer is None else writer.add)
    except SolverError as exc:
        text = run.write_summary({**base, "converged": False, "error": str(exc)}, complete=True, status="failed")
        if writer is not None:
            writer.close()
        if args.json:
            sys.stdout.write(text)
        print(f"error: solver failed: {_one_line(exc)}{_report_in(outputs)}", file=sys.stderr)
        return EXIT_SOLVER
    except KeyboardInterrupt as exc:
        partial = getattr(exc, "result", None)
        summary = {**base, "converged": None, **({} if partial is None else partial.to_dict())}
        if writer is not None:
            writer.close()
            summary["frames_written"] = writer.n_frames
        _unfinished(run, summary, exc)
        raise
    summary = {**base, "converged": True, **trajectory.to_dict()}
    for entry, tension, points in zip(summary.get("cables", []), trajectory.cable_tensions(-1), trajectory.cable_points[-1]):
        entry["final_tensions"] = tension.tolist()
        entry["final_points"] = points.tolist()
    try:
        if writer is not None:
            writer.close()
        if "trajectory.png" in outputs:
            with atomic_path(outputs["trajectory.png"]) as png:
                plot_trajectory(trajectory, png)
    except (KeyboardInterrupt, OutputError) as exc:
        _unfinished(run, summary, exc)
        raise
    text = run.write_summary(summary, complete=True, status="complete")
    if args.json:
        sys.stdout.write(text)
    elif not args.quiet:
        print(f"{scene.path.name}: {scene.mesh.n_nodes} nodes, {scene.mesh.n_tets} tets, {scene.formulation}, "
              f"{len(scene.cables)} cable(s)")
        print(f"{plural(summary['steps'], 'step')} of {summary['dt']:g} s: "
              f"{plural(summary['newton_iterations'], 'Newton iteration')} "
              f"(max {summary['max_iterations_per_step']} per step), {plural(summary['cutbacks'], 'cutback')}, "
              f"{summary['timings']['simulate']:.3g} s")
        print(f"final kinetic energy {summary['final_kinetic_energy']:.3e} J (max {summary['max_kinetic_energy']:.3e} J), "
              f"max displacement {summary['max_displacement']:.6g} m")
        frames = f" ({trajectory.n_frames} frames)" if "trajectory.pvd" in outputs else ""
        print(_wrote(outputs, run.folder, frames))
    return EXIT_OK


# ---------------------------------------------------------------------------
# estimate, control


def _inverse(args: argparse.Namespace) -> int:
    """``estimate`` / ``control``: summary.json and result.vtu in ``--out``; for a scene with
    ``[dynamics]``, a fit to recorded motion / a schedule (summary.json, trajectory.png)."""
    command = args.command
    scene = Scene.load(args.scene)
    section = getattr(scene, command)
    if scene.target is None and scene.tracks is None:
        raise InputError(f"{scene.path}: '{command}' needs a [target] table")
    if section is None:
        raise InputError(f"{scene.path}: '{command}' needs an [{command}] table")
    in_time = scene.dynamics is not None
    if in_time and command == "estimate" and (args.history is not None or args.resume):
        raise InputError(f"{'--resume' if args.resume else '--history'}: a fit to motion (a scene with [dynamics]) "
                         "keeps no history file to resume; leave it out")
    out, label = _output_folder(args, scene)
    if in_time:
        switches = {"summary.json": scene.output["summary"], "fit.png": scene.output["png"] and command == "estimate",
                    "trajectory.png": scene.output["png"]}
    else:
        switches = {"summary.json": scene.output["summary"], "result.vtu": scene.output["vtu"],
                    "fit.png": scene.output["png"]}
    outputs = {name: out / name for name, on in switches.items() if on}
    history = None
    if command == "estimate" and not in_time:
        history = args.history if args.history is not None else out / "history.jsonl"
        outputs["history.jsonl"] = history
    _refuse_inputs(outputs, scene, label)
    if command == "estimate" and args.resume and not history.is_file():
        raise InputError(f"--resume: no history to resume: {history} does not exist (pass --history FILE)")
    if history is not None:
        history.parent.mkdir(parents=True, exist_ok=True)
    # Checked (and the equilibrium of initial = "static" solved) before anything is written.
    motion = None
    if in_time:
        motion = scene.estimate_dynamics() if command == "estimate" else scene.control_dynamics()
    # Sensitivities are only as accurate as the equilibria: never looser than the inverse default.
    options = scene.solve_options.replace(tolerance=min(scene.solve_options.tolerance, DEFAULT_TOLERANCE))
    base = {
        "scene": str(scene.path),
        "command": command,
        "n_nodes": scene.mesh.n_nodes,
        "n_tets": scene.mesh.n_tets,
        "formulation": scene.formulation,
        "gravity": scene.gravity.tolist(),
        "solver_options": scene.solve_options.to_dict(),
        "options": dict(section),
    }
    if in_time:
        base["dynamics"] = scene.to_dict()["dynamics"]
    run = RunFolder(out, outputs, INVERSE_OUTPUT_NAMES)
    try:
        run.start({**base, "history_file": None if history is None else str(history)})
        _warn_stale(run)
        return _inverse_run(args, scene, section, options, history, run, base, label, motion)
    except (KeyboardInterrupt, OutputError) as exc:
        run.stopped(_stop_status(exc))
        if history is not None and isinstance(exc, KeyboardInterrupt):
            again = "" if args.history is None else f" --history {history}"
            print(f"error: {_stop_status(exc)}: the history so far is in {history}; go on with the same command "
                  f"and --resume{again}", file=sys.stderr)
        raise


def _inverse_run(args: argparse.Namespace, scene: Any, section: dict[str, Any], options: Any, history: Path | None,
                 run: RunFolder, base: dict[str, Any], label: str, motion: dict[str, Any] | None) -> int:
    command, outputs, out = args.command, run.outputs, run.folder
    found = _solve_inverse(command, scene, section, options, history, args, motion)
    if command == "control" and motion is not None:
        plan = found
        summary = {**base, **plan.to_dict(), "history": plan.history, "converged": plan.reachable}
        ok, result, fitted = plan.reachable, None, plan
        words = ", ".join(_COMMAND_WORDS[scene.body.commands[c][0]] for c in section["cables"])
        lines = [
            f"{scene.path.name}: schedule of cable(s) {section['cables']} ({words}) at t = "
            f"{', '.join(f'{t:g}' for t in plan.keyframe_times)} s:",
            *(f"  cable {c}: {', '.join(f'{v:.6g}' for v in plan.actuation[:, j])}"
              for j, c in enumerate(section["cables"])),
            f"at T = {plan.reach_time:g} s: distance {plan.distance:.3e} m (rms), max {plan.max_distance:.3e} m; swing "
            f"after T {plan.swing:.3e} m; {'reachable' if plan.reachable else 'NOT reachable'}, "
            f"{plural(plan.simulations, 'simulation')}",
        ]
        failure = f"target not reachable: {plan.message}"
    elif command == "estimate":
        fit = found
        m = fit.material
        summary = {
            **base,
            **fit.to_dict(),
            "converged": fit.converged,
            # Every parameter of the model, in each of its forms (mu, lambda and E, nu).
            **{name: m.value(name) for form in m.model.forms for name in form.names},
            "residual": fit.residual,
            "history": fit.history,
        }
        ok, result, fitted = fit.converged, fit.result, fit
        lines = [f"{scene.path.name}: {fit.summary()}"]
        if fit.profile is not None and "fit.png" in outputs:
            outputs["profile.png"] = out / "profile.png"
            _refuse_inputs({"profile.png": outputs["profile.png"]}, scene, label)
        failure = f"the fit did not converge: {fit.message}"
    else:
        ctl = found
        unit = "N" if scene.target.kind == "contact_force" else "m"
        summary = {**base, **ctl.to_dict(), "history": ctl.history, "converged": ctl.reachable}
        ok, result, fitted = ctl.reachable, ctl.result, ctl
        lines = [
            f"{scene.path.name}: actuation {', '.join(f'{a:.6g}' for a in ctl.actuation)} "
            f"({', '.join(_COMMAND_WORDS[scene.body.commands[c][0]] for c in section['cables'])}) "
            f"of cable(s) {section['cables']} ({section['method']})",
            f"distance {ctl.distance:.3e} {unit} (rms), max {ctl.max_distance:.3e} {unit}, "
            f"{'reachable' if ctl.reachable else 'NOT reachable'}, {ctl.forward_solves} forward solves",
        ]
        failure = f"target not reachable: {ctl.message}"
    if history is not None:
        summary["history_file"] = str(history)
    try:
        if result is not None and "result.vtu" in outputs:
            write_result(outputs["result.vtu"], result, run_id=run.run_id)
        for name, plot in (("fit.png", plot_fit), ("profile.png", plot_profile), ("trajectory.png", _plot_run)):
            if name in outputs:
                with atomic_path(outputs[name]) as png:
                    plot(fitted, png)
    except (KeyboardInterrupt, OutputError) as exc:
        _unfinished(run, summary, exc)
        raise
    text = run.write_summary(summary, complete=True, status="complete" if ok else "failed")
    if args.json:
        sys.stdout.write(text)
    elif not args.quiet:
        print("\n".join(lines))
        print(_wrote({k: v for k, v in outputs.items() if k != "history.jsonl"}, out))
    if not ok:
        print(f"error: {_one_line(Exception(failure))}{_report_in(outputs)}", file=sys.stderr)
        return EXIT_SOLVER
    return EXIT_OK


#: How the command of each cable kind reads in a summary line.
_COMMAND_WORDS = {"actuation": "alpha", "pull": "pull, m", "tension": "tension, N"}


def _plot_run(found: Any, path: Path) -> None:
    """trajectory.png of a fit to motion or a schedule: the run it found."""
    plot_trajectory(found.trajectory, path)


def _solve_inverse(command: str, scene: Any, section: dict[str, Any], options: Any, history: Path | None,
                   args: argparse.Namespace, motion: dict[str, Any] | None) -> Any:
    if motion is not None and command == "estimate":
        return estimate(
            scene.body, scene.tracks, section["params"], section["x0"], bounds=section["bounds"],
            method=section["method"], regions=scene.regions or None, gravity=scene.gravity,
            tolerance=options.tolerance, max_iterations=options.max_iterations, dynamics=motion,
        )
    if motion is not None:
        return control(
            scene.body, scene.target, cables=section["cables"], bounds=section["bounds"], gravity=scene.gravity,
            options=options, dynamics=motion,
        )
    if command == "estimate":
        return estimate(
            scene.body, scene.target, section["params"], section["x0"], bounds=section["bounds"],
            method=section["method"], starts=section["starts"], regions=scene.regions or None,
            gravity=scene.gravity, options=options, history_path=history, resume=args.resume,
        )
    return control(
        scene.body, scene.target, cables=section["cables"], bounds=section["bounds"], method=section["method"],
        gravity=scene.gravity, options=options,
    )


# ---------------------------------------------------------------------------
# schema


def _schema(args: argparse.Namespace) -> int:
    """``schema``: the scene files' JSON Schema on stdout, or in ``--out FILE`` (never overwritten
    without ``--force``)."""
    text = schema_text()
    out: Path | None = args.out
    if out is None:
        if args.force:
            raise _UsageError("--force: only with --out FILE (see 'sorofem schema --help')")
        sys.stdout.write(text)
        return EXIT_OK
    if out.is_dir():
        raise InputError(f"--out: {out} is a folder; expected a file name such as {out / 'scene.schema.json'}")
    if out.exists() and not args.force:
        raise InputError(f"--out: {out} exists; pass --force to overwrite it")
    out.parent.mkdir(parents=True, exist_ok=True)
    write_text(out, text)
    print(f"wrote {out}")
    return EXIT_OK


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
