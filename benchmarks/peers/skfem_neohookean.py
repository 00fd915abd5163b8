"""A static compressible Neo-Hookean solve in scikit-fem: the peer that `make bench` times sorofem against.

The discrete problem is the one sorofem solves: P1 tetrahedra on the given mesh, strain energy density
(per unit rest volume, Pa)

    psi(F) = mu/2 (I1 - 3) - mu ln J + lambda/2 (ln J)^2,   I1 = F : F,  J = det F,

body force ``density * gravity`` (N/m^3), displacement zero on the fixed nodes, and Newton iterations
until ``||r_free|| <= tol * ||f_ext_free||`` (r = f_int - f_ext, both in N). It is written the way
scikit-fem's own hyperelasticity example is: a ``LinearForm`` for the first variation, a
``BilinearForm`` for its linearisation, ``condense`` + ``solve`` (SciPy's sparse direct solver) per
Newton step, plain Newton without line search, and load steps for large deflections.

Run this file to check the peer against Euler-Bernoulli beam theory and its own mesh convergence::

    python benchmarks/peers/skfem_neohookean.py
"""

from __future__ import annotations

import time
from typing import Any, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray
from skfem import Basis, BilinearForm, ElementTetP1, ElementVector, LinearForm, MeshTet, condense, solve as skfem_solve
from skfem.helpers import ddot, det, grad, identity, inv, mul, trace, transpose

__all__ = ["solve", "solve_with_load_steps", "box_mesh"]


def lame(youngs_modulus: float, poisson_ratio: float) -> tuple[float, float]:
    """Shear modulus mu and Lame's first parameter lambda (Pa) from E (Pa) and nu."""
    mu = youngs_modulus / (2.0 * (1.0 + poisson_ratio))
    lam = youngs_modulus * poisson_ratio / ((1.0 + poisson_ratio) * (1.0 - 2.0 * poisson_ratio))
    return mu, lam


def solve(
    points: ArrayLike,
    tets: ArrayLike,
    fixed_nodes: ArrayLike,
    youngs_modulus: float,
    poisson_ratio: float,
    density: float,
    gravity: Sequence[float],
    tol: float = 1e-8,
    load_steps: int = 1,
    max_iterations: int = 100,
) -> dict[str, Any]:
    """Solve the static Neo-Hookean problem under gravity with scikit-fem.

    Parameters
    ----------
    points : (n, 3) float array
        Rest positions (m).
    tets : (m, 4) int array
        0-based node indices of the P1 tetrahedra.
    fixed_nodes : (k,) int array
        Nodes whose displacement is zero.
    youngs_modulus, poisson_ratio, density : float
        E (Pa), nu, rho (kg/m^3).
    gravity : (3,) float
        Gravitational acceleration (m/s^2).
    tol : float
        Relative residual tolerance: ``||r_free|| <= tol * ||f_ext_free||`` ends each load step.
    load_steps : int
        The load is applied in this many equal increments, each solved to ``tol``.
    max_iterations : int
        Newton iterations allowed per load step.

    Returns
    -------
    dict
        ``displacement`` (n, 3) m; ``newton_iterations`` (linear solves, all steps); ``seconds`` (wall
        time from building the mesh to the answer); ``converged``; ``load_steps``; ``residual_history``
        (relative, last step); ``timings`` {setup, assembly, solve} s; ``failure`` (None or why).
    """
    t_start = time.perf_counter()
    points = np.ascontiguousarray(points, dtype=np.float64)
    tets = np.ascontiguousarray(tets, dtype=np.int64)
    fixed_nodes = np.asarray(fixed_nodes, dtype=np.int64)
    g = np.asarray(gravity, dtype=np.float64)
    mu, lam = lame(youngs_modulus, poisson_ratio)

    mesh = MeshTet(np.ascontiguousarray(points.T), np.ascontiguousarray(tets.T))
    # Gradients of P1 functions are constant per tet and the body-force integrand is linear:
    # one quadrature point integrates every form exactly.
    basis = Basis(mesh, ElementVector(ElementTetP1()), intorder=1)

    @LinearForm
    def internal_force(v, w):
        F = grad(w["u"]) + identity(grad(w["u"]))
        return mu * ddot(F, grad(v)) + (lam * np.log(det(F)) - mu) * ddot(transpose(inv(F)), grad(v))

    @BilinearForm
    def tangent(du, v, w):
        F = grad(w["u"]) + identity(grad(w["u"]))
        iF = inv(F)
        dF_iF = mul(grad(v), iF)
        DF_iF = mul(grad(du), iF)
        return (
            mu * ddot(grad(du), grad(v))
            - (lam * np.log(det(F)) - mu) * ddot(transpose(dF_iF), DF_iF)
            + lam * trace(dF_iF) * trace(DF_iF)
        )

    @LinearForm
    def body_force(v, w):
        return density * (g[0] * v[0] + g[1] * v[1] + g[2] * v[2])

    fixed_dofs = basis.nodal_dofs[:, fixed_nodes].ravel()
    free = np.setdiff1d(np.arange(basis.N), fixed_dofs)
    f_ext = body_force.assemble(basis)
    u = basis.zeros()
    timings = {"setup": time.perf_counter() - t_start, "assembly": 0.0, "solve": 0.0}

    iterations = 0
    history: list[float] = []
    failure = None
    with np.errstate(invalid="ignore", divide="ignore"):
        for step in range(1, load_steps + 1):
            f_step = f_ext * (step / load_steps)
            scale = np.linalg.norm(f_step[free])
            history = []
            for _ in range(max_iterations + 1):
                t0 = time.perf_counter()
                uh = basis.interpolate(u)
                residual = internal_force.assemble(basis, u=uh) - f_step
                timings["assembly"] += time.perf_counter() - t0
                rel = np.linalg.norm(residual[free]) / scale
                history.append(float(rel))
                if not np.isfinite(rel):
                    failure = f"non-finite residual in load step {step} (an element inverted: J <= 0)"
                    break
                if rel <= tol:
                    break
                if len(history) > max_iterations:
                    failure = f"no convergence in {max_iterations} iterations of load step {step}"
                    break
                t0 = time.perf_counter()
                K = tangent.assemble(basis, u=uh)
                timings["assembly"] += time.perf_counter() - t0
                t0 = time.perf_counter()
                u += skfem_solve(*condense(K, -residual, D=fixed_dofs))
                timings["solve"] += time.perf_counter() - t0
                iterations += 1
            if failure is not None:
                break

    return {
        "displacement": u[basis.nodal_dofs].T.copy(),
        "newton_iterations": iterations,
        "seconds": time.perf_counter() - t_start,
        "converged": failure is None,
        "load_steps": load_steps,
        "residual_history": history,
        "timings": timings,
        "failure": failure,
    }


def solve_with_load_steps(
    *args: Any, load_steps: Sequence[int] = (1, 2, 4, 8, 16, 32, 64, 128, 256), **kwargs: Any
) -> dict[str, Any]:
    """:func:`solve` with 1, 2, 4, ... load steps until one converges, as a scikit-fem user would.

    Returns the converged run's dict plus ``attempts`` [(load_steps, converged, iterations, seconds)]
    and ``seconds_all_attempts`` (wall time including the failed tries).
    """
    attempts = []
    result: dict[str, Any] = {}
    for steps in load_steps:
        result = solve(*args, load_steps=steps, **kwargs)
        attempts.append((steps, result["converged"], result["newton_iterations"], result["seconds"]))
        if result["converged"]:
            break
    result["attempts"] = attempts
    result["seconds_all_attempts"] = sum(a[3] for a in attempts)
    return result


def box_mesh(
    size: Sequence[float], cells: Sequence[int], origin: Sequence[float] = (0.0, 0.0, 0.0)
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """The box mesh of ``sorofem.Mesh.box``, written anew: the peer case checks that both agree.

    Node ``(i, j, k)`` has index ``i + (nx+1) (j + (ny+1) k)``; each hex is split into six tets
    around its main diagonal (Kuhn subdivision), and negatively oriented tets get nodes 2 and 3
    swapped, exactly as the core does. Returns points (n, 3) in m and tets (m, 4).
    """
    nx, ny, nz = (int(c) for c in cells)
    axes = [origin[a] + size[a] * np.arange(c + 1) / c for a, c in enumerate((nx, ny, nz))]
    z, y, x = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    points = np.column_stack([x.ravel(), y.ravel(), z.ravel()])

    k, j, i = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    corner = np.stack([i.ravel(), j.ravel(), k.ravel()], axis=1)  # (cells, 3), hex order i fastest
    strides = np.array([1, nx + 1, (nx + 1) * (ny + 1)])
    perms = [(0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0)]
    tets = np.empty((len(corner), 6, 4), dtype=np.int64)
    for p, perm in enumerate(perms):
        c = corner.copy()
        tets[:, p, 0] = c @ strides
        for step, axis in enumerate(perm):
            c[:, axis] += 1
            tets[:, p, step + 1] = c @ strides
    tets = tets.reshape(-1, 4)
    d = points[tets[:, 1:]] - points[tets[:, :1]]
    negative = np.linalg.det(d) < 0
    tets[negative] = tets[negative][:, [0, 1, 3, 2]]
    return points, tets


def _tip_deflection(points: NDArray[np.float64], displacement: NDArray[np.float64], length: float) -> float:
    tip = np.abs(points[:, 0] - length) < 1e-9
    return float(displacement[tip, 2].mean())


def _validate() -> None:
    """Mesh convergence and Euler-Bernoulli agreement on the 0.4 x 0.1 x 0.1 m cantilever."""
    E, nu, rho, L, b, h = 66e3, 0.45, 1080.0, 0.4, 0.1, 0.1
    points, tets = box_mesh((L, b, h), (8, 2, 2))
    assert points.shape == (81, 3) and tets.shape == (192, 4)
    q = rho * 9.81 / 100 * b * h
    w_eb = q * L**4 / (8 * E * b * h**3 / 12)
    G = E / (2 * (1 + nu))
    w_shear = q * L**2 / (2 * (5 / 6) * G * b * h)  # Timoshenko's shear term, L/h = 4 is stubby
    print(f"Euler-Bernoulli w = {w_eb * 1e3:.4f} mm, + Timoshenko shear = {(w_eb + w_shear) * 1e3:.4f} mm")
    previous = None
    for n in (1, 2, 4, 6):
        points, tets = box_mesh((L, b, h), (8 * n, 2 * n, 2 * n))
        fixed = np.flatnonzero(points[:, 0] < 1e-9)
        r = solve(points, tets, fixed, E, nu, rho, (0, 0, -9.81 / 100))
        w = -_tip_deflection(points, r["displacement"], L)
        change = "" if previous is None else f", change {abs(w - previous) / w:.2%}"
        print(
            f"cells {8 * n}x{2 * n}x{2 * n} ({len(tets)} tets): w = {w * 1e3:.4f} mm = {w / w_eb:.3f} w_EB, "
            f"{r['newton_iterations']} iterations, {r['seconds']:.2f} s{change}"
        )
        assert r["converged"]
        previous = w
    assert 0.8 < previous / w_eb < 1.2, "the finest mesh should be near Euler-Bernoulli"
    for L, cells in ((0.4, (8, 2, 2)), (1.0, (16, 4, 4))):
        points, tets = box_mesh((L, b, h), cells)
        fixed = np.flatnonzero(points[:, 0] < 1e-9)
        r = solve_with_load_steps(points, tets, fixed, E, nu, rho, (0, 0, -9.81))
        print(
            f"full gravity, L = {L} m, cells {cells}: tip w = {-_tip_deflection(points, r['displacement'], L):.4f} m, "
            f"attempts (steps, converged, iterations, s) = {r['attempts']}"
        )


if __name__ == "__main__":
    _validate()
