"""The "Targets" section of BENCHMARKS.md: each issue's targets against the measured numbers.

A case with a target adds its line here; the rows of every case family are available.
"""

from __future__ import annotations

from pathlib import Path

from cases import peers
from cases.common import MIXED_NU, cantilever_name, per_iteration_ratio
from harness import Row, fmt, in_table, ratio, section

TARGETS_TITLE = "Targets"
PAPER_HAMMERBOT_SECONDS = 7.6  # the paper's hammerbot static solve


@section(TARGETS_TITLE)
def targets(rows: dict[str, Row], array_dir: Path) -> str:
    """Every issue's targets against the measured numbers."""
    lines = ["| target | case | measured | limit | met |", "|---|---|---|---|---|"]

    def add(target: str, case_name: str, value: float | None, limit: float, unit: str = "",
            at_least: bool = False) -> None:
        bound = (">= " if at_least else "<= ") + f"{limit:g}{unit}"
        if value is None:
            lines.append(f"| {target} | {case_name} | not measured | {bound} | - |")
        else:
            ok = "yes" if (value >= limit if at_least else value <= limit) else "**NO**"
            lines.append(f"| {target} | {case_name} | {fmt(value)}{unit} | {bound} | {ok} |")

    def ok_row(name: str) -> Row | None:
        r = rows.get(name)
        return r if r and not r.get("error") and r.get("converged") else None

    # Issue 2: static Neo-Hookean solves.
    r = ok_row("sorofem/hammerbot")
    add("hammerbot static solve time", "sorofem/hammerbot", r and r["seconds"], 0.25, " s")
    for name, limit in [("sorofem/cantilever-0.4m-8x2x2", 12), ("sorofem/cantilever-1m-8x2x2", 25),
                        ("sorofem/cantilever-1m-16x4x4", 25), ("sorofem/cantilever-1m-48x8x8", 25)]:
        if name in rows:
            r = rows[name]
            add("Newton iterations, one load step", name, None if r.get("error") else r.get("iterations"), limit)
    for name, r in rows.items():
        if in_table(name, "static") and r.get("tets", 0) >= 10_000 and not r.get("error"):
            add("time per Newton iteration / one bare numeric factorisation", name, per_iteration_ratio(r), 1.3)
    for name, r in rows.items():
        if in_table(name, "static") and r.get("tets", 0) >= 90_000:
            add("peak memory, ~100k tets", name, r.get("peak_rss_mib") and r["peak_rss_mib"] / 1024, 8.0, " GiB")
    for name in rows:
        if name.startswith("skfem/") and (ratio_to_peer := peers.speedup(rows, name)):
            add("speed-up over scikit-fem (time skfem / sorofem)", name, ratio_to_peer, 50, "x", at_least=True)

    # Mixed formulation.
    mixed_bot, std_bot = f"sorofem/hammerbot-mixed-nu{MIXED_NU:g}", "sorofem/hammerbot"
    if mixed_bot in rows:
        m, s = ok_row(mixed_bot), ok_row(std_bot)
        add(f"hammerbot mixed (nu = {MIXED_NU:g}) solve time / standard hammerbot solve time (nu = 0.4)",
            f"{mixed_bot} vs {std_bot}", m and s and ratio(m["seconds"], s["seconds"]), 2.0, "x")
        add(f"hammerbot mixed solve time, >= 10x faster than the paper's {PAPER_HAMMERBOT_SECONDS:g} s",
            mixed_bot, m and m["seconds"], PAPER_HAMMERBOT_SECONDS / 10, " s")
    mixed_small = cantilever_name("sorofem", 0.4, (8, 2, 2)) + f"-mixed-nu{MIXED_NU:g}"
    std_small = cantilever_name("sorofem", 0.4, (8, 2, 2))
    if mixed_small in rows:
        m, s = ok_row(mixed_small), ok_row(std_small)
        limit = s["iterations"] if s else None
        if limit is None:
            lines.append(f"| Newton iterations, mixed at nu = {MIXED_NU:g} vs standard at nu = 0.45 | {mixed_small} "
                         f"| {fmt(m and m['iterations'])} | standard not measured | - |")
        else:
            add(f"Newton iterations, mixed at nu = {MIXED_NU:g} <= standard at nu = 0.45 ({std_small})",
                mixed_small, m and m["iterations"], limit)
    for name, r in rows.items():
        if in_table(name, "mixed") and r.get("tets", 0) >= 90_000:
            add("peak memory, ~100k tets, mixed", name,
                r.get("peak_rss_mib") and r["peak_rss_mib"] / 1024, 12.0, " GiB")

    # Issue 15: a Yeoh hammerbot costs at most 1.3x the Neo-Hookean one, Newton iterations within 2:
    # side by side in one process (the materials table), and between the hammerbot table's rows.
    for name in (f"sorofem/hammerbot-yeoh-vs-neo-hookean{suffix}" for suffix in ("", f"-mixed-nu{MIXED_NU:g}")):
        if name in rows:
            good = ok_row(name)
            add("Yeoh hammerbot solve time / Neo-Hookean (same process, alternating)", name,
                good and ratio(good["seconds"], good["seconds_neo_hookean"]), 1.3, "x")
            add("Yeoh hammerbot Newton iterations - Neo-Hookean", name,
                good and abs(good["iterations"] - good["iterations_neo_hookean"]), 2)
    for yeoh, neo in [("sorofem/hammerbot-yeoh", std_bot), (f"sorofem/hammerbot-yeoh-mixed-nu{MIXED_NU:g}", mixed_bot)]:
        if yeoh in rows:
            y, n = ok_row(yeoh), ok_row(neo)
            add("Yeoh hammerbot solve time / Neo-Hookean", f"{yeoh} vs {neo}",
                y and n and ratio(y["seconds"], n["seconds"]), 1.3, "x")
            add("Yeoh hammerbot Newton iterations - Neo-Hookean", f"{yeoh} vs {neo}",
                y and n and abs(y["iterations"] - n["iterations"]), 2)

    # Cables.
    r = rows.get("sorofem/hammerbot-2-cables")
    if r is not None:
        good = ok_row("sorofem/hammerbot-2-cables")
        add("static solve time with two cables / without (same process, alternating)", "sorofem/hammerbot-2-cables",
            good and ratio(good["seconds"], good["seconds_without"]), 1.15, "x")
        add("time per Newton iteration with two cables / without", "sorofem/hammerbot-2-cables",
            good and ratio(good["seconds_per_iteration"], good["seconds_per_iteration_without"]), 1.15, "x")
        add("hammerbot with two cables, static solve time", "sorofem/hammerbot-2-cables",
            good and good["seconds"], 0.4, " s")

    # Issue 16: a tendon hammerbot costs at most 1.3x the spring chain at the paper's k.
    name = "sorofem/hammerbot-tendons-vs-springs"
    if name in rows:
        good = ok_row(name)
        add("tendon hammerbot solve time / spring chain at k = 50 kN/m (same process, alternating)", name,
            good and ratio(good["seconds"], good["seconds_springs"]), 1.3, "x")

    # Dynamics.
    r = rows.get("sorofem/hammerbot-dynamics-1s")
    if r is not None:
        good = ok_row("sorofem/hammerbot-dynamics-1s")
        add("1 s of hammerbot dynamics at dt = 10 ms, time", "sorofem/hammerbot-dynamics-1s",
            good and good["seconds"], 10.0, " s")
        failed = bool(r.get("error") or not r.get("converged"))
        lines.append(f"| 1 s of hammerbot dynamics: no Newton failure | sorofem/hammerbot-dynamics-1s | "
                     f"{'failed' if failed else 'none'} ({fmt(r.get('cutbacks'))} cutbacks, "
                     f"{fmt(r.get('iterations'))} Newton it.) | no failure | {'**NO**' if failed else 'yes'} |")
        add("1 s of hammerbot dynamics, default method: time (issue 18)", "sorofem/hammerbot-dynamics-1s",
            good and good["seconds"], 1.0, " s")
        add("1 s of hammerbot dynamics, default method: tip deviation from a tight run (issue 18)",
            "sorofem/hammerbot-dynamics-1s", good and good["max_tip_deviation_percent"], 0.5, " %")
    newton = ok_row("sorofem/hammerbot-dynamics-1s-newton")
    if r is not None and newton:
        add("1 s of hammerbot dynamics: default method time / newton (same run)", "sorofem/hammerbot-dynamics-1s",
            good and ratio(good["seconds"], newton["seconds"]), 1.0, "x")

    traj = ok_row("sorofem/hammerbot-trajectory-gradient")
    if traj:
        add("trajectory gradient (100 steps, 5 parameters) / forward simulation, defaults (issue 18)",
            "sorofem/hammerbot-trajectory-gradient", ratio(traj["seconds"], traj["seconds_forward"]), 2.0, "x")

    # Issue 18: real time in the fast mode at 20k tets, and the largest mesh that runs in real time.
    # The fast mode is modified Newton at tolerance 1e-2; the linearly implicit rows are reported too.
    realtime = {name: r for name, r in rows.items() if in_table(name, "realtime") and ok_row(name)}
    for name, r in realtime.items():
        if 20_000 <= r["tets"] <= 30_000 and r.get("method") == "modified":
            add("1 s of dynamics at 20-30k tets in the fast mode (modified, tolerance 1e-2): real-time factor "
                "(issue 18)", name, r["realtime_factor"], 1.0)
    for method in sorted({r.get("method", "-") for r in realtime.values()}):
        in_time = [r["tets"] for r in realtime.values() if r.get("method") == method and r["realtime_factor"] <= 1.0]
        lines.append(f"| largest mesh simulated in real time, method {method} (issue 18: report it) | "
                     f"sorofem/realtime-* | {max(in_time) if in_time else 'none'} tets | - | - |")

    # Adjoint.
    r = rows.get("sorofem/hammerbot-adjoint")
    if r is not None:
        good = ok_row("sorofem/hammerbot-adjoint")
        add("adjoint (1st call, incl. its factorisation) / forward solve", "sorofem/hammerbot-adjoint",
            good and ratio(good["seconds"], good["seconds_forward"]), 0.25, "x")

    # Contact (issue 17).
    for name, r in rows.items():
        if in_table(name, "contact"):
            good = ok_row(name)
            add("static solve time with a floor / without (same process, alternating)", name,
                good and ratio(good["seconds"], good["seconds_without"]), 2.0, "x")
            timings = (good or {}).get("timings") or {}
            add("contact pass / Newton time", name, ratio(timings.get("contact"), timings.get("total")), 0.25)

    for name, r in rows.items():
        if in_table(name, "contact-finger"):
            good = ok_row(name)
            add("time per Newton iteration with a ball / without (a contact solve at the same iteration count)",
                name, good and ratio(good["seconds_per_iteration"], good["seconds_per_iteration_without"]), 2.0, "x")
            if r.get("tets", 0) >= 10_000:
                timings = (good or {}).get("timings") or {}
                add("contact pass / Newton time, ~10k-tet finger", name,
                    ratio(timings.get("contact"), timings.get("total")), 0.25)
        if in_table(name, "self-contact"):
            timings = (ok_row(name) or {}).get("timings") or {}
            add("contact pass / Newton time, self-contact (the contact pass bound)", name,
                ratio(timings.get("contact"), timings.get("total")), 0.25)

    # Sweeps (issue 21).
    name = "sorofem/sweep-cantilever-0.4m-8x2x2-200"
    if name in rows:
        good = ok_row(name)
        add("sweep throughput, 2 workers / one process looping over the same cases", name,
            good and good["speedup_loop"], 1.7, "x", at_least=True)
        add("the same, from CPU time (the machine shared with other jobs)", name,
            good and good["cpu_speedup_loop"], 1.7, "x", at_least=True)
        add("per-case overhead of the sweep machinery (Dask + Parquet)", name,
            good and 1e3 * good["overhead_seconds"], 20.0, " ms")
    return "\n".join(lines) + "\n"

