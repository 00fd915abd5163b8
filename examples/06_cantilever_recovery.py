"""Recover the silicone's mu and lambda from a simulated sag of the 0.4 m cantilever, with physics checks.

The 0.4 x 0.1 x 0.1 m cantilever of example 01 on the paper's 8 x 2 x 2 grid (81 nodes, 192 tets),
clamped at x = 0, rho = 1080 kg/m^3, gravity (0, 0, -9.81) m/s^2, is solved once with the true
material, E = 66 kPa, nu = 0.45 (mu = 22.76 kPa, lambda = 204.8 kPa); its 81 equilibrium node
positions are the target. Starting from mu0 = 20 kPa, lambda0 = 0.2 MPa, ``sf.estimate`` fits
(mu, lambda) again, for the standard and the mixed formulation (each fitted against its own
synthetic data), with three methods:

* ``least-squares``: Levenberg-Marquardt in (log mu, log lambda), Jacobian from two forward
  sensitivities per solve (one factorisation of the Hessian at the solution);
* ``nelder-mead``: no derivatives;
* ``l-bfgs-b``: adjoint gradient of 1/2 |r|^2 (reported, not required to reach 1e-6).

The data are noise-free, so the fit must return the truth. The script exits with status 1
unless every check passes:

* ``<formulation>_least_squares_recovers``, ``<formulation>_nelder_mead_recovers``: mu and
  lambda within 1e-6 relative of the truth.
* ``<formulation>_least_squares_budget``: at most 15 forward (static) solves, the final
  report solve included.
* ``<formulation>_residual_vanishes``: RMS node misfit of the least-squares fit below 1e-9 m.
* ``<formulation>_uncertainty_consistent``: the Gauss-Newton relative standard deviations are
  below 1e-6 (zero-noise data pin both parameters) and the Jacobian has full rank.

Outputs in ``--out DIR`` (default ``results/cantilever_recovery``): ``summary.json`` (per
formulation and method: fitted values, relative errors, iterations, forward solves, Newton
iterations, time, the history) and ``convergence.png`` (loss per iteration).

Run::

    python examples/06_cantilever_recovery.py --out results/cantilever_recovery
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

import sorofem as sf

YOUNGS_MODULUS = 66e3  # Pa
POISSON_RATIO = 0.45
DENSITY = 1080.0  # kg/m^3
GRAVITY = (0.0, 0.0, -9.81)  # m/s^2
SIZE = (0.4, 0.1, 0.1)  # m
CELLS = (8, 2, 2)
X0 = (20e3, 0.2e6)  # initial (mu, lambda), Pa
RECOVERY = 1e-6
BUDGET = 15
METHODS = ("least-squares", "nelder-mead", "l-bfgs-b")


def build(formulation: str) -> sf.Body:
    mesh = sf.Mesh.box(size=SIZE, cells=CELLS)
    material = sf.NeoHookean(youngs_modulus=YOUNGS_MODULUS, poisson_ratio=POISSON_RATIO, density=DENSITY)
    body = sf.Body(mesh, material, formulation=formulation)
    body.fix(mesh.nodes_on_plane((0.0, 0.0, 0.0), (1.0, 0.0, 0.0)))
    return body


def run(out_dir: str | Path = "results/cantilever_recovery") -> dict[str, Any]:
    """Fit, write the outputs to ``out_dir`` and return the summary (``checks`` inside)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    truth = sf.NeoHookean(youngs_modulus=YOUNGS_MODULUS, poisson_ratio=POISSON_RATIO)
    true = {"shear_modulus": truth.shear_modulus, "lame_lambda": truth.lame_lambda}
    fits: dict[str, dict[str, Any]] = {}
    checks: dict[str, dict[str, Any]] = {}
    for formulation in ("standard", "mixed"):
        body = build(formulation)
        goal = sf.solve_static(body, GRAVITY, tolerance=1e-12).positions
        target = sf.Target.nodes(np.arange(body.mesh.n_nodes), goal)
        fits[formulation] = {}
        for method in METHODS:
            fit = sf.estimate(body, target, ["shear_modulus", "lame_lambda"], x0=X0, gravity=GRAVITY, method=method,
                              ftol=1e-20 if method == "l-bfgs-b" else 1e-12, max_evaluations=400)
            errors = {k: abs(fit.params[k] / v - 1) for k, v in true.items()}
            fits[formulation][method] = {
                **fit.to_dict(),
                "relative_error": errors,
                "history": fit.history,
            }
            if method != "l-bfgs-b":
                key = method.replace("-", "_")
                checks[f"{formulation}_{key}_recovers"] = {
                    "passed": max(errors.values()) <= RECOVERY,
                    "value": errors,
                    "limit": f"|theta / theta_true - 1| <= {RECOVERY:g} for mu and lambda",
                }
            if method == "least-squares":
                checks[f"{formulation}_least_squares_budget"] = {
                    "passed": fit.forward_solves <= BUDGET,
                    "value": fit.forward_solves,
                    "limit": f"<= {BUDGET} forward solves",
                }
                checks[f"{formulation}_residual_vanishes"] = {
                    "passed": fit.residual < 1e-9,
                    "value": fit.residual,
                    "limit": "RMS node misfit < 1e-9 m",
                }
                unc = fit.uncertainty
                checks[f"{formulation}_uncertainty_consistent"] = {
                    "passed": bool(unc is not None and np.all(unc.relative_std < 1e-6) and unc.singular_values[-1] > 0),
                    "value": None if unc is None else unc.to_dict(),
                    "limit": "relative std < 1e-6, full-rank Jacobian",
                }
    _plot(fits, out / "convergence.png")
    summary = {
        "truth": {**true, "youngs_modulus": YOUNGS_MODULUS, "poisson_ratio": POISSON_RATIO},
        "x0": {"shear_modulus": X0[0], "lame_lambda": X0[1]},
        "mesh": {"size": SIZE, "cells": CELLS},
        "fits": fits,
        "checks": checks,
        "passed": all(c["passed"] for c in checks.values()),
        "files": ["summary.json", "convergence.png"],
        "timings": {"total": time.perf_counter() - t0},
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=float) + "\n", encoding="utf-8")
    return summary


def _plot(fits: dict[str, dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
    for ax, (formulation, by_method) in zip(axes, fits.items()):
        for method, fit in by_method.items():
            losses = [h["loss"] for h in fit["history"] if np.isfinite(h["loss"])]
            solves = [h["forward_solves"] for h in fit["history"] if np.isfinite(h["loss"])]
            ax.semilogy(solves, np.maximum(losses, 1e-30), marker=".", label=method)
        ax.set_title(f"{formulation} formulation")
        ax.set_xlabel("forward solves")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("loss 1/2 |r|^2 [m^2]")
    axes[0].legend()
    fig.subplots_adjust(left=0.1, right=0.98, bottom=0.13, top=0.92, wspace=0.08)
    fig.savefig(path)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("results/cantilever_recovery"), metavar="DIR")
    args = parser.parse_args(argv)
    summary = run(args.out)
    for formulation, by_method in summary["fits"].items():
        for method, fit in by_method.items():
            p, e = fit["params"], fit["relative_error"]
            print(f"{formulation:8s} {method:13s} mu {p['shear_modulus']:.8g} Pa (err {e['shear_modulus']:.1e}), "
                  f"lambda {p['lame_lambda']:.8g} Pa (err {e['lame_lambda']:.1e}); {fit['iterations']} iterations, "
                  f"{fit['forward_solves']} forward solves, {fit['time']:.2f} s")
    for name, check in summary["checks"].items():
        print(f"[{'ok' if check['passed'] else 'FAILED'}] {name}: {check['limit']}")
    print(f"{'all checks passed' if summary['passed'] else 'SOME CHECKS FAILED'} in {summary['timings']['total']:.1f} s; "
          f"wrote {', '.join(summary['files'])} to {args.out}")
    return 0 if summary["passed"] else 1


if __name__ == "__main__":
    sys.exit(main())
