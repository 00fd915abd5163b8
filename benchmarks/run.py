"""Benchmarks behind `make bench`: run every case in a fresh process and write BENCHMARKS.md.

    python benchmarks/run.py --write BENCHMARKS.md            # all cases
    python benchmarks/run.py --write BENCHMARKS.md --quick    # small cases only
    python benchmarks/run.py --list
    python benchmarks/run.py --only 'sorofem/cantilever-0.4m-*'

``harness.py`` runs the cases (each in a child process: ``run.py --child NAME``), times them and
writes the report; ``cases/`` holds one module per case family (static cantilevers, hammerbot,
mixed formulation, cables, dynamics, adjoint, the scikit-fem peer); ``targets.py`` sets the
measured numbers against each issue's targets.

Adding a benchmark is: one case function in its family's module, registered with ``case`` under
a table (add a ``Table`` if it needs new columns), and, if it has a target, one line in
``targets.py``; a new family is one module, imported in ``cases/__init__.py``.

Cases run in registration order, except those registered with ``last=True`` (the scikit-fem
1 m 48x8x8 peer, ~15 minutes), which run after all others. ``--write`` rewrites only the
sections this runner owns (the preamble, its tables, the comparison, the targets and the run
log) and keeps every other ``## `` section of the file (e.g. "## Locking study", written by
examples/02_locking_study.py) as it was, after its own.
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import os
import sys
import tempfile
from pathlib import Path

import cases  # noqa: F401  (registers the tables and cases)
import targets  # noqa: F401  (registers the "Targets" section, after the cases' own sections)
from harness import CASES, Run, child_main, command_line, fmt, foreign_sections, json_default, machine, render, run_child


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--write", metavar="PATH", help="write the Markdown report here")
    parser.add_argument("--quick", action="store_true", help="small cases only")
    parser.add_argument("--only", metavar="GLOB", action="append", help="run the cases matching (repeatable)")
    parser.add_argument("--list", action="store_true", help="list the cases and exit")
    parser.add_argument("--json", metavar="PATH", help="also dump the raw rows as JSON")
    parser.add_argument("--reuse", metavar="PATH",
                        help="rows of the cases not run now from this --json dump of an earlier run "
                             "(the report names them and that run's extension build)")
    parser.add_argument("--child", metavar="CASE", help=argparse.SUPPRESS)
    parser.add_argument("--workdir", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)

    if args.child:
        return child_main(args.child, args.workdir)

    selected = [c for c in CASES.values() if (c.quick or not args.quick)]
    if args.only:
        selected = [c for c in selected if any(fnmatch.fnmatch(c.name, p) for p in args.only)]
    selected.sort(key=lambda c: c.last)  # stable: registration order, the slow ``last`` cases at the end
    if args.list:
        for c in selected:
            print(f"{c.name:48s} table={c.table:8s} {'quick' if c.quick else '':5s} {'last' if c.last else ''}")
        return 0
    if not selected:
        print("no case selected", file=sys.stderr)
        return 2

    command = command_line()
    info = machine()
    with tempfile.TemporaryDirectory(prefix="sorofem-bench-") as tmp:
        run = Run(array_dir=Path(tmp))
        for c in selected:
            print(f"[bench] {c.name} ...", end=" ", flush=True)
            row = run_child(c.name, Path(tmp))
            run.rows[c.name] = row
            if row.get("error"):
                print("ERROR:", row["error"][-400:], flush=True)
            else:
                print(
                    f"{'converged' if row.get('converged') else 'NOT converged'}, "
                    f"{row.get('iterations')} it., {fmt(row.get('seconds'))} s, "
                    f"peak RSS {row['peak_rss_mib']:.0f} MiB (child {row['child_wall_s']:.1f} s)",
                    flush=True,
                )
        reused = _reuse(run, Path(args.reuse)) if args.reuse else []
        if reused:
            earlier = sorted({run.rows[n].get("extension", "?") for n in reused})
            info["rows from an earlier run"] = (f"{len(reused)} of {len(run.rows)} cases from `{args.reuse}` "
                                                f"(extension {', '.join(earlier)}); the run log marks them")
        report = render(run, info, command, args.quick)
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    report = report.replace("\n\n## ", f"\n| load average at end (1, 5, 15 min) | {load} |\n\n## ", 1)
    # Only the rows that time sorofem itself must share one build (the peers use it for meshes only).
    builds = sorted({r["extension"] for n, r in run.rows.items()
                     if n.startswith("sorofem/") and "extension" in r and not r.get("reused")})
    if len(builds) > 1:
        warning = (f"**Warning: the extension was rebuilt during this run ({' -> '.join(builds)}); "
                   "the sorofem rows come from different builds. Run again.**")
        print("[bench]", warning, file=sys.stderr)
        report = report.replace("\n| machine | |", f"\n{warning}\n\n| machine | |", 1)
    if args.write:
        path = Path(args.write)
        if path.exists():
            kept = foreign_sections(path.read_text(encoding="utf-8"))
            if kept:
                report = report.rstrip("\n") + "\n\n" + "\n".join(kept)
                print(f"[bench] kept sections of {path} not written by this runner: "
                      + ", ".join(repr(k.splitlines()[0][3:].strip()) for k in kept))
        tmp_path = path.with_suffix(path.suffix + ".tmp")
        tmp_path.write_text(report)
        tmp_path.replace(path)
        print(f"[bench] wrote {path}")
    else:
        print(report)
    if args.json:
        Path(args.json).write_text(json.dumps(run.rows, indent=1, default=json_default))
    return 1 if any(r.get("error") for r in run.rows.values()) else 0


def _reuse(run: Run, path: Path) -> list[str]:
    """Adds the rows of ``path`` (a ``--json`` dump) for the registered cases this run did not
    run, in registration order after this run's; returns their names."""
    try:
        earlier = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as err:
        raise SystemExit(f"--reuse: cannot read {path}: {err}") from err
    names = [name for name in CASES if name not in run.rows and name in earlier]
    for name in names:
        run.rows[name] = {**earlier[name], "reused": True}
    return names


if __name__ == "__main__":
    sys.exit(main())
