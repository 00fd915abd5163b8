"""The trajectory gradient through contact: the cantilever falling onto a floor, its barrier
stiffness adaptive (balanced at each step's start, which the derivatives follow) or fixed."""

from __future__ import annotations

import statistics
import time

import numpy as np

from harness import TABLES, Column, Row, Table, case, col, fmt, mib, ratio, status

TABLES["trajectory_contact"] = Table(
    "Trajectory gradient through contact (sorofem)",
    "The 0.4 m cantilever (0.1 x 0.1 m, clamped at x = 0, E = 66 kPa, nu = 0.45, rho = 1080 kg/m^3) released "
    "from rest under gravity (0, 0, -9.81) onto a frictionless floor 5 mm below it (sf.Plane), Rayleigh "
    "damping (1.0 1/s, 2e-3 s), 30 steps of 10 ms: it lands within the first steps and rests there. "
    "Objective J = 1/2 |x(T) - X|^2 over every node at the last frame; gradient by `sf.trajectory_gradient` "
    "with respect to Young's modulus and density, against the forward run `sf.simulate` (both with the "
    "defaults: modified Newton to 1e-8). `adaptive`: IPC's barrier stiffness, balanced at each step's start "
    "and followed by the derivatives where it lies inside its bounds (balanced steps); `fixed`: "
    "`set_contact(adaptive_stiffness=False)`, the same reference stiffness (the default from the material) "
    "in every step. Each mode: medians of 3 rounds that alternate the forward run and the gradient in one "
    "process.",
    (
        col("case", "case", str),
        col("tets", "tets"),
        Column("conv.", status),
        col("steps", "steps"),
        col("balanced steps", "balanced_steps"),
        col("forward, adaptive [s]", "seconds_forward"),
        col("gradient, adaptive [s]", "seconds"),
        Column("gradient / forward, adaptive", lambda r: fmt(ratio(r.get("seconds"), r.get("seconds_forward")))),
        col("forward, fixed [s]", "seconds_forward_fixed"),
        col("gradient, fixed [s]", "seconds_fixed"),
        Column("gradient / forward, fixed",
               lambda r: fmt(ratio(r.get("seconds_fixed"), r.get("seconds_forward_fixed")))),
        Column("peak RSS [MiB]", mib),
    ),
)

STEPS, DT, DAMPING, GAP = 30, 0.01, (1.0, 2e-3), 0.005
GRAVITY = (0.0, 0.0, -9.81)
ROUNDS = 3


def _floor_cantilever_gradient(cells: tuple[int, int, int]) -> Row:
    import sorofem as sf

    mesh = sf.Mesh.box(size=(0.4, 0.1, 0.1), cells=cells)
    material = sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080.0)
    fixed = mesh.nodes_on_plane((0, 0, 0), (1, 0, 0))

    def body(adaptive: bool) -> sf.Body:
        b = sf.Body(mesh, material)
        b.fix(fixed)
        b.add_obstacle(sf.Plane((0.0, 0.0, -GAP), (0, 0, 1)))
        b.set_contact(adaptive_stiffness=adaptive)
        return b

    def objective(x: np.ndarray) -> tuple[float, np.ndarray]:
        d = np.zeros_like(x)
        d[-1] = x[-1] - x[0]
        return 0.5 * float(np.sum(d[-1] ** 2)), d

    kwargs = dict(gravity=GRAVITY, damping=DAMPING)
    row: Row = {"tets": mesh.n_tets, "steps": STEPS}
    for adaptive, suffix in ((True, ""), (False, "_fixed")):
        forward_times, gradient_times = [], []
        for _ in range(ROUNDS):
            t0 = time.perf_counter()
            forward = sf.simulate(body(adaptive), DT, STEPS, **kwargs)
            t1 = time.perf_counter()
            g = sf.trajectory_gradient(body(adaptive), objective, ["youngs_modulus", "density"], dt=DT, steps=STEPS,
                                       **kwargs)
            t2 = time.perf_counter()
            forward_times.append(t1 - t0)
            gradient_times.append(t2 - t1)
        row["seconds_forward" + suffix] = statistics.median(forward_times)
        row["seconds" + suffix] = statistics.median(gradient_times)
        row["forward_times" + suffix], row["gradient_times" + suffix] = forward_times, gradient_times
        if adaptive:
            row["balanced_steps"] = g.balanced_stiffness_steps
            row["converged"] = bool(np.isfinite(forward.positions).all())
            row["min_distance"] = float(np.nanmin(forward.min_distances))
    return row


@case("sorofem/trajectory-gradient-cantilever-on-floor-16x4x4", "trajectory_contact")
def sorofem_trajectory_gradient_on_floor_small() -> Row:
    return _floor_cantilever_gradient((16, 4, 4))


@case("sorofem/trajectory-gradient-cantilever-on-floor-32x8x8", "trajectory_contact")
def sorofem_trajectory_gradient_on_floor_large() -> Row:
    return _floor_cantilever_gradient((32, 8, 8))
