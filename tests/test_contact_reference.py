"""The contact kernels against the reference implementation of IPC, ipctk (the IPC Toolkit's
Python bindings; a test-only dependency: this module is skipped when it is not installed).

Random configurations of four points, a quarter of them with nearly parallel edges (where the
edge-edge mollifier acts): squared point-triangle and edge-edge distances with their gradients
and Hessians (each from its closest features), the mollifier and the barrier with its two
derivatives, to 1e-10 relative to the largest entry.
"""

from __future__ import annotations

import numpy as np
import pytest

from sorofem._extension import core

ipctk = pytest.importorskip("ipctk")

DHAT = 0.7


def _configurations(count: int = 400) -> list[np.ndarray]:
    rng = np.random.default_rng(1)
    out = []
    for k in range(count):
        x = rng.uniform(-1, 1, (4, 3))
        if k % 4 == 1:  # nearly parallel edges
            x[2] = x[0] + rng.uniform(-0.3, 0.3, 3)
            x[3] = x[2] + 0.9 * (x[1] - x[0]) + rng.uniform(-1e-3, 1e-3, 3)
        out.append(x)
    return out


def _relative(ours: np.ndarray, reference: np.ndarray) -> float:
    ours, reference = np.atleast_1d(ours).ravel(), np.atleast_1d(reference).ravel()
    return float(np.abs(ours - reference).max() / max(np.abs(reference).max(), 1e-300))


def test_distances_mollifier_and_barrier_match_ipctk():
    worst: dict[str, float] = {}
    mollified = 0
    for x in _configurations():
        ours = core()._contact_reference(x, DHAT)
        p = [x[i] for i in range(4)]
        pt, ee, m = ours["point_triangle"], ours["edge_edge"], ours["mollifier"]
        eps = ipctk.edge_edge_mollifier_threshold(*p)
        mollified += ipctk.edge_edge_mollifier(*p, eps) < 1.0
        d = ipctk.point_triangle_distance(*p)
        pairs = {
            "point-triangle distance": (pt["value"], d),
            "point-triangle gradient": (pt["gradient"], ipctk.point_triangle_distance_gradient(*p)),
            "point-triangle Hessian": (pt["hessian"], ipctk.point_triangle_distance_hessian(*p)),
            "edge-edge distance": (ee["value"], ipctk.edge_edge_distance(*p)),
            "edge-edge gradient": (ee["gradient"], ipctk.edge_edge_distance_gradient(*p)),
            "edge-edge Hessian": (ee["hessian"], ipctk.edge_edge_distance_hessian(*p)),
            "mollifier threshold": (ours["mollifier_threshold"], eps),
            "mollifier": (m["value"], ipctk.edge_edge_mollifier(*p, eps)),
            "mollifier gradient": (m["gradient"], ipctk.edge_edge_mollifier_gradient(*p, eps)),
            "mollifier Hessian": (m["hessian"], ipctk.edge_edge_mollifier_hessian(*p, eps)),
        }
        if d < DHAT**2:
            b, db, d2b = ours["barrier"]
            pairs |= {
                "barrier": (b, ipctk.barrier(d, DHAT**2)),
                "barrier first derivative": (db, ipctk.barrier_first_derivative(d, DHAT**2)),
                "barrier second derivative": (d2b, ipctk.barrier_second_derivative(d, DHAT**2)),
            }
        for name, (a, b) in pairs.items():
            worst[name] = max(worst.get(name, 0.0), _relative(np.asarray(a), np.asarray(b)))
    assert mollified >= 50, "too few configurations exercise the mollifier"
    assert {"barrier", "barrier second derivative"} <= set(worst), "no configuration within dhat"
    bad = {name: err for name, err in worst.items() if err > 1e-10}
    assert not bad, f"ipctk {ipctk.__version__}: {bad}"
