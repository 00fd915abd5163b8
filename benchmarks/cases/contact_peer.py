"""The contact pass alone against the IPC Toolkit (``ipctk``, the reference implementation of
IPC): its broad phase, barrier potential, gradient and Hessian on the finger's deformed surface
pressed on the ball, against sorofem's contact pass per Newton iteration in the solve of that
state."""

from __future__ import annotations

import statistics
import time

import numpy as np
from harness import TABLES, Column, Row, Table, case, col, fmt, mib

from .common import TOLERANCE
from .contact_finger import BALL_CENTER, BALL_RADIUS, _finger_body

# 20480 triangles, edges ~0.6 mm: coarser ones lie so far inside the sphere (their sagitta) that ipctk
# finds none of the contacts the solve has within dhat; at 5 it finds the same number.
ICOSPHERE_SUBDIVISIONS = 5
REPEATS = 7


def _ms(x: float | None) -> str:
    return "-" if x is None else f"{1e3 * x:.3g}"


TABLES["contact-peer"] = Table(
    "Contact pass against ipctk (peer)",
    "The finger of the finger-on-a-ball table (35 x 7 x 7 cells) solved with the ball (sorofem). At the "
    "solution, ipctk 1.6 (`NormalCollisions.build` with its default broad phase, then `BarrierPotential` "
    "value, gradient and Hessian, the barrier stiffness and dhat of the solve) on the same deformed body "
    "surface, the ball given to it as an icosphere (subdivided 5 times, 20480 triangles, vertices on the "
    "sphere: ipctk has no analytic sphere, and coarser icospheres lie too far inside it for ipctk to find the "
    "solve's contacts); ipctk's broad phase also pairs the body's surface with itself (no filter); median of "
    "7 runs. sorofem's contact pass per Newton iteration = the solve's "
    "`timings['contact']` / iterations: broad phase, barrier with gradient and Hessian and their scatter "
    "into the free DOFs, plus the gradient-only passes of the line search's trials, against an analytic "
    "sphere. The two do different work on the obstacle side (an analytic distance against 20480 triangles "
    "and their edges) and ipctk's includes self-contact pairs, so the ratio is an order of magnitude, not a "
    "like-for-like kernel speed.",
    (
        col("case", "case", str),
        col("tets", "tets"),
        col("surface vertices", "surface_vertices"),
        col("surface triangles", "surface_faces"),
        col("ball triangles", "ball_faces"),
        col("ipctk collisions", "ipctk_collisions"),
        col("sorofem active contacts", "active_contacts"),
        Column("ipctk build [ms]", lambda r: _ms(r.get("ipctk_build_seconds"))),
        Column("ipctk value + gradient + Hessian [ms]", lambda r: _ms(r.get("ipctk_derivatives_seconds"))),
        Column("ipctk pass [ms]", lambda r: _ms(r.get("ipctk_seconds"))),
        Column("sorofem pass per iteration [ms]", lambda r: _ms(r.get("sorofem_seconds_per_iteration"))),
        Column("ipctk / sorofem", lambda r: fmt(r.get("peer_ratio"))),
        Column("peak RSS [MiB]", mib),
    ),
)


@case("ipctk/contact-pass-finger-35x7x7", "contact-peer")
def ipctk_finger() -> Row:
    import ipctk
    import trimesh

    import sorofem as sf

    body = _finger_body((35, 7, 7), ball=True)
    result = sf.solve_static(body, gravity=(0.0, 0.0, 0.0), tolerance=TOLERANCE, load_steps=1)
    report = result.report
    mesh = body.mesh
    faces = mesh.boundary_faces()
    surface, local = np.unique(faces, return_inverse=True)
    body_vertices = (mesh.points + result.displacement)[surface]
    ball = trimesh.creation.icosphere(subdivisions=ICOSPHERE_SUBDIVISIONS, radius=BALL_RADIUS)
    ball_vertices = np.asarray(ball.vertices) + np.asarray(BALL_CENTER)
    vertices = np.asfortranarray(np.vstack([body_vertices, ball_vertices]))
    triangles = np.vstack([local.reshape(faces.shape), np.asarray(ball.faces) + len(surface)]).astype(np.int32)
    edges = ipctk.edges(triangles)
    collision_mesh = ipctk.CollisionMesh(vertices, edges, triangles)
    potential = ipctk.BarrierPotential(result.contact.dhat, result.contact.stiffness)

    build, derivatives = [], []
    count = 0
    for _ in range(REPEATS):
        collisions = ipctk.NormalCollisions()
        t0 = time.perf_counter()
        collisions.build(collision_mesh, vertices, result.contact.dhat)
        t1 = time.perf_counter()
        potential(collisions, collision_mesh, vertices)
        potential.gradient(collisions, collision_mesh, vertices)
        potential.hessian(collisions, collision_mesh, vertices)
        t2 = time.perf_counter()
        build.append(t1 - t0)
        derivatives.append(t2 - t1)
        count = len(collisions)
    ipctk_seconds = statistics.median(b + d for b, d in zip(build, derivatives))
    ours = report.timings["contact"] / report.iterations
    return {
        "converged": bool(report.converged), "iterations": report.iterations, "tets": mesh.n_tets,
        "surface_vertices": int(len(surface)), "surface_faces": int(len(faces)), "ball_faces": int(len(ball.faces)),
        "ipctk_collisions": int(count), "active_contacts": result.active_contacts,
        "ipctk_build_seconds": statistics.median(build), "ipctk_derivatives_seconds": statistics.median(derivatives),
        "ipctk_seconds": ipctk_seconds, "sorofem_seconds_per_iteration": ours, "peer_ratio": ipctk_seconds / ours,
        "seconds": ipctk_seconds, "api": "ipctk.NormalCollisions.build / BarrierPotential",
    }
