"""Calibrate the hammerbot's silicone with a Yeoh model against its target surface: does the
richer model lower the misfit of the Neo-Hookean fit, and what do the data say about c20, c30?

Data and model as in example 07 (SolidFEM's samples in ``../shared/data/solidfem`` beside the
repository, skipped when missing): ``hammerbot_fine.tet`` (2346 nodes, 9011 tets, scaled by
0.01 to metres), clamped on its 92 nodes at x = -5 cm, rho = 1070 kg/m^3, gravity
(0, -9.8, 0) m/s^2, the visual surface ``hammerbot_fine.obj`` compared vertex to vertex with the
goal ``hammer_target.obj`` (the robot sagging under gravity). All fits use the mixed
formulation with the silicone nearly incompressible, as example 07's last fit does:

1. **Neo-Hookean** (example 07's "silicone"): nu = 0.4999 fixed, E fitted; mu = E / (2 (1 + nu)).
2. **Yeoh, c10 alone** (c20 = c30 = 0: the decoupled Neo-Hookean), d1 = 2 / K fixed at the bulk
   modulus K of fit 1. At small strain 2 c10 is the shear modulus, so 2 c10 must reproduce the
   mu of fit 1 (the two forms differ only in how the volume change enters, and the volume
   hardly changes here).
3. **Yeoh, c10 and c20**, from fit 2 with c20 = 0, and the misfit profiled along c20 (c10
   re-fitted at each value).
4. Full run only: **Yeoh, c10, c20 and c30**, from fit 3 with c30 = 0, within c20 in
   [-50, 50] kPa and c30 in [-500, 500] kPa (about 3 and 30 times c10), then again from there
   within bounds six times wider (``c10_c20_c30_wide``).

Each fit is Levenberg-Marquardt on forward sensitivities (``sf.estimate`` with the coefficient
names), c10 in log space, c20 and c30 as they are (either sign). c20's standard error is taken
from the curvature of its profile (``profile_std``), which does not depend on how c20 (Pa) and
log c10 are scaled against each other.

What it finds (``summary.json``; the quick run gives the same figures for what it computes):
the sag reaches ``I1b - 3`` of 0.09 to 0.13 at most, depending on the fit (99 % of the elements
below 0.07), so the higher
Yeoh terms have little to act on. Neo-Hookean: mu = 33.267 +- 0.044 kPa, RMS misfit 1.6485 mm.
Yeoh c10 alone: 2 c10 = 33.274 +- 0.044 kPa (the same shear modulus), 1.6492 mm. Adding c20
gives c20 = 6.8 +- 4.1 kPa (95 % profile interval -1.0 .. 15.3 kPa: consistent with 0) and
lowers the misfit by 0.6 micrometres (0.04 %); c10 and c20 trade off along the profile (c10
from 18.2 to 14.3 kPa as c20 goes from -20 to 40 kPa) while the misfit moves by 0.9 %. The
three-term fit ends on both bounds (c20 = -50 kPa, c30 = 500 kPa, c10 = 17.17 kPa) at 1.628 mm
(1.3 % below Neo-Hookean); with bounds six times wider it runs to c20 = -300 kPa, c30 = 2.8 MPa
at 1.573 mm (4.6 % below): it buys misfit by softening the material about twofold near ``I1b - 3 = 0.04`` and
stiffening it beyond, i.e. by fitting the goal's model error (the goal is not an equilibrium of
the clamp, see example 07), not a property of the silicone. One sagging pose determines the
small-strain shear modulus to 0.13 %; it does not determine c20 or c30.

The script exits with status 1 unless every check passes:

* ``converged``: every fit converged.
* ``small_strain_shear_modulus``: 2 c10 of the Yeoh fit with c20 = c30 = 0 equals the
  Neo-Hookean fit's mu within two combined standard errors.
* ``nested_misfit``: each richer Yeoh fit's RMS misfit is at most that of the one it extends
  (c10 -> c10, c20 -> c10, c20, c30 -> the same within wider bounds), to 1e-9 m: the richer
  model contains the poorer.
* ``drucker_stable``: at the fitted Yeoh coefficients, ``dW/dI1b = c10 + 2 c20 (I1b - 3) + 3 c30
  (I1b - 3)^2 > 0`` in every element of the fitted equilibrium (the fit is a stable material
  over the strains it saw).
* ``fit_is_profile_minimum``: no point of the c20 profile (c10 re-fitted there) has a smaller
  loss than the (c10, c20) fit.
* ``balance``: at the richest Yeoh fit's equilibrium, clamp reactions + weight = 0 (relative
  1e-6).

Outputs in ``--out DIR``: ``summary.json``, ``fit.png`` (goal against the richest fit's surface)
and ``profile.png`` (the misfit along c20, c10 re-fitted).

``quick=True`` (what the test suite runs) stops after fit 3 and profiles c20 at 4 points
instead of 7.

Run::

    python examples/15_hammerbot_yeoh.py --out results/hammerbot_yeoh [--quick]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

import sorofem as sf

DATA = Path(__file__).resolve().parent.parent.parent / "shared" / "data" / "solidfem"
MESH_FILE = DATA / "hammerbot_fine.tet"
VISUAL_FILE = DATA / "hammerbot_fine.obj"
GOAL_FILE = DATA / "hammer_target.obj"
#: Files the example needs; tests/test_examples.py skips it when one is missing.
REQUIRED_FILES = (MESH_FILE, VISUAL_FILE, GOAL_FILE)

SCALE = 0.01  # the files are in centimetres
DENSITY = 1070.0  # kg/m^3
GRAVITY = np.array([0.0, -9.8, 0.0])  # m/s^2
CLAMP_X = -0.05  # m
SILICONE_NU = 0.4999
#: Where c20 and c30 may go (Pa): wide enough that no fit ends on a bound, narrow enough that
#: the material stays stable over the strains the sag reaches.
C20_BOUNDS = (-50e3, 50e3)
C30_BOUNDS = (-500e3, 500e3)
C10_BOUNDS = (1e3, 1e6)
#: Six times wider: where the three-term fit goes when let.
WIDE_C20_BOUNDS = (-300e3, 300e3)
WIDE_C30_BOUNDS = (-3e6, 3e6)
#: The values of c20 (Pa) the misfit is profiled at, quick and full.
PROFILE_C20 = {True: (-10e3, 0.0, 10e3, 20e3), False: (-20e3, -10e3, 0.0, 10e3, 20e3, 30e3, 40e3)}
SOLVE_TOLERANCE = 1e-8
NESTED_TOLERANCE = 1e-9  # m
BALANCE_TOLERANCE = 1e-6


def build(material: Any) -> sf.Body:
    mesh = sf.Mesh.read(MESH_FILE, scale=SCALE)
    body = sf.Body(mesh, material, formulation="mixed")
    body.fix(mesh.nodes_on_plane((CLAMP_X, 0.0, 0.0), (1.0, 0.0, 0.0)))
    return body


def first_invariant_excess(result: sf.StaticResult) -> np.ndarray:
    """``I1b - 3 = J^(-2/3) tr(F^T F) - 3`` per tetrahedron of ``result``, ``(n_tets,)``."""
    tets = result.mesh.tets
    rest, now = result.mesh.points[tets], result.positions[tets]
    dm = np.transpose(rest[:, 1:] - rest[:, :1], (0, 2, 1))
    ds = np.transpose(now[:, 1:] - now[:, :1], (0, 2, 1))
    f = ds @ np.linalg.inv(dm)
    j = np.linalg.det(f)
    return j ** (-2.0 / 3.0) * np.einsum("eij,eij->e", f, f) - 3.0


def profile_std(profile: Any, sigma: float) -> float:
    """Standard error of the profiled parameter from the curvature of its profile: with the
    others re-fitted, ``1/2 |r|^2 ~ a theta^2 + b theta + c`` near the optimum (a parabola
    fitted to the profile's points), and the Gauss-Newton variance is ``sigma^2 / (2 a)``.
    Unlike the covariance of the full Jacobian it does not depend on how the parameters are
    scaled against each other."""
    ok = np.isfinite(profile.loss)
    a = np.polyfit(profile.values[ok], profile.loss[ok], 2)[0]
    return float(sigma / math.sqrt(2.0 * a)) if a > 0 else math.inf


def fit_entry(fit: sf.inverse.FitResult) -> dict[str, Any]:
    """What ``summary.json`` keeps of a fit: its ``to_dict`` and the printed report."""
    return {**fit.to_dict(), "report": fit.summary()}


def rounded(value: float, std: float) -> str:
    """``value +- std`` with the digits the standard error supports (two significant digits of
    it), in kPa."""
    if not math.isfinite(std) or std <= 0:
        return f"{value / 1e3:.4g} kPa (no standard error)"
    decimals = max(0, 1 - int(math.floor(math.log10(std / 1e3))))
    return f"{value / 1e3:.{decimals}f} +- {std / 1e3:.{decimals}f} kPa"


def run(out_dir: str | Path = "results/hammerbot_yeoh", quick: bool = False) -> dict[str, Any]:
    """Fit, write ``summary.json``, ``fit.png`` and ``profile.png`` to ``out_dir`` and return the summary
    (``checks`` inside)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    target = sf.Target.surface(GOAL_FILE, scale=SCALE, rest=VISUAL_FILE)
    options = {"gravity": GRAVITY, "tolerance": SOLVE_TOLERANCE}

    # 1. Neo-Hookean, nearly incompressible: E alone (example 07's "silicone").
    neo_body = build(sf.NeoHookean(youngs_modulus=100e3, poisson_ratio=SILICONE_NU, density=DENSITY))
    bound = target.bind(neo_body.mesh)
    neo = sf.estimate(neo_body, bound, ["youngs_modulus"], x0=[100e3], **options)
    mu = float(neo.material.shear_modulus)
    mu_std = float(neo.uncertainty.std[0]) / (2.0 * (1.0 + SILICONE_NU))
    bulk = float(neo.youngs_modulus) / (3.0 * (1.0 - 2.0 * SILICONE_NU))

    # 2.-4. Yeoh with the same bulk modulus, richer step by step, each from the last optimum.
    yeoh_body = build(sf.Yeoh(c10=mu / 2, d1=2.0 / bulk, density=DENSITY))
    c10 = sf.estimate(yeoh_body, bound, ["c10"], x0=[mu / 2], bounds=[C10_BOUNDS], **options)
    fits = {"c10": c10}
    fits["c10_c20"] = sf.estimate(
        yeoh_body, bound, ["c10", "c20"], x0=[c10.params["c10"], 0.0], bounds=[C10_BOUNDS, C20_BOUNDS],
        profile="c20", profile_values=PROFILE_C20[quick], **options)
    if not quick:
        c20 = fits["c10_c20"]
        fits["c10_c20_c30"] = sf.estimate(
            yeoh_body, bound, ["c10", "c20", "c30"], x0=[c20.params["c10"], c20.params["c20"], 0.0],
            bounds=[C10_BOUNDS, C20_BOUNDS, C30_BOUNDS], profile=False, **options)
        c30 = fits["c10_c20_c30"]
        fits["c10_c20_c30_wide"] = sf.estimate(
            yeoh_body, bound, ["c10", "c20", "c30"], x0=[c30.params[n] for n in ("c10", "c20", "c30")],
            bounds=[C10_BOUNDS, WIDE_C20_BOUNDS, WIDE_C30_BOUNDS], profile=False, **options)
    richest = fits[list(fits)[-1]]
    final = richest.results[0]

    c10_std = float(c10.uncertainty.std[0])
    shear_difference = abs(2.0 * c10.params["c10"] - mu)
    shear_limit = 2.0 * math.hypot(2.0 * c10_std, mu_std)
    rms = {name: float(f.residual) for name, f in fits.items()}
    names = list(rms)
    excess = first_invariant_excess(final)
    p = richest.params
    slope = p["c10"] + 2.0 * p.get("c20", 0.0) * excess + 3.0 * p.get("c30", 0.0) * excess**2
    weight = float(DENSITY * final.mesh.volumes.sum()) * GRAVITY
    balance = float(np.linalg.norm(final.reactions.sum(axis=0) + weight) / np.linalg.norm(weight))
    with_c20 = fits["c10_c20"]
    profile = with_c20.profile
    c20_std = profile_std(profile, with_c20.uncertainty.sigma)

    checks = {
        "converged": {
            "passed": bool(neo.converged and all(f.converged for f in fits.values())),
            "value": {"neo_hookean": neo.message, **{n: f.message for n, f in fits.items()}},
            "limit": "every fit converged",
        },
        "small_strain_shear_modulus": {
            "passed": shear_difference <= shear_limit,
            "value": {"two_c10": 2.0 * c10.params["c10"], "two_c10_std": 2.0 * c10_std,
                      "neo_hookean_mu": mu, "neo_hookean_mu_std": mu_std, "difference": shear_difference},
            "limit": "|2 c10 - mu| <= 2 sqrt(std(2 c10)^2 + std(mu)^2)",
        },
        "nested_misfit": {
            "passed": all(rms[b] <= rms[a] + NESTED_TOLERANCE for a, b in zip(names, names[1:])),
            "value": rms,
            "limit": f"RMS misfit of each richer fit <= that of the fit it extends + {NESTED_TOLERANCE:g} m",
        },
        "drucker_stable": {
            "passed": bool(slope.min() > 0),
            "value": {"min_dW_dI1b": float(slope.min()), "I1b_minus_3_range": [float(excess.min()),
                                                                               float(excess.max())]},
            "limit": "c10 + 2 c20 (I1b - 3) + 3 c30 (I1b - 3)^2 > 0 Pa in every element",
        },
        "fit_is_profile_minimum": {
            "passed": bool(np.nanmin(profile.loss) >= with_c20.loss * (1.0 - 1e-9)),
            "value": {"fit_loss": with_c20.loss, "profile_losses": profile.loss.tolist()},
            "limit": "no point of the c20 profile (c10 re-fitted) has a smaller loss than the (c10, c20) fit",
        },
        "balance": {
            "passed": balance < BALANCE_TOLERANCE,
            "value": balance,
            "limit": f"|sum R + W| / |W| < {BALANCE_TOLERANCE:g} at the richest Yeoh fit",
        },
    }

    sf.plot.plot_fit(richest, out / "fit.png")
    summary = {
        "example": "15_hammerbot_yeoh",
        "quick": quick,
        "silicone_poisson_ratio": SILICONE_NU,
        "bulk_modulus": bulk,
        "d1": 2.0 / bulk,
        "neo_hookean": {**fit_entry(neo), "shear_modulus": mu, "shear_modulus_std": mu_std},
        "yeoh": {name: fit_entry(f) for name, f in fits.items()},
        "rms_misfit": {"neo_hookean": float(neo.residual), **{f"yeoh_{n}": v for n, v in rms.items()}},
        "misfit_reduction": {f"yeoh_{n}": 1.0 - v / float(neo.residual) for n, v in rms.items()},
        "I1b_minus_3": {"min": float(excess.min()), "max": float(excess.max()),
                        "p99": float(np.percentile(excess, 99))},
        "c20": {"value": with_c20.params["c20"], "std_from_profile": c20_std,
                "interval_95": list(profile.interval), "interval_closed": list(profile.closed),
                "profile_values": profile.values.tolist(), "profile_rms": profile.rms.tolist(),
                "profile_c10": profile.params["c10"].tolist()},
        "checks": checks,
        "passed": all(c["passed"] for c in checks.values()),
        "files": ["summary.json", "fit.png", "profile.png"],
    }
    sf.plot.plot_profile(with_c20).savefig(out / "profile.png")
    summary["timings"] = {"total": time.perf_counter() - t0}
    (out / "summary.json").write_text(json.dumps(summary, indent=2, default=float) + "\n", encoding="utf-8")
    return summary


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("results/hammerbot_yeoh"), metavar="DIR")
    parser.add_argument("--quick", action="store_true", help="no three-term fit, 4 profile points")
    args = parser.parse_args(argv)
    missing = [str(f) for f in REQUIRED_FILES if not f.is_file()]
    if missing:
        print(f"skipped: missing data {', '.join(missing)}", file=sys.stderr)
        return 0
    summary = run(args.out, quick=args.quick)
    neo = summary["neo_hookean"]
    print(f"Neo-Hookean (nu = {SILICONE_NU}): mu = {rounded(neo['shear_modulus'], neo['shear_modulus_std'])}, "
          f"RMS misfit {summary['rms_misfit']['neo_hookean'] * 1e3:.4f} mm")
    c20 = summary["c20"]
    for name, fit in summary["yeoh"].items():
        unc = fit["uncertainty"]
        shown = []
        for p, v in fit["params"].items():
            if unc["at_bound"][p]:
                shown.append(f"{p} = {v / 1e3:g} kPa (at its {unc['at_bound'][p]} bound)")
            elif name == "c10_c20" and p == "c20":
                lo, hi = c20["interval_95"]
                shown.append(f"c20 = {rounded(v, c20['std_from_profile'])} (from the profile; 95 % interval "
                             f"{lo / 1e3:.1f} .. {hi / 1e3:.1f} kPa)")
            else:
                std = unc["std"][p]
                shown.append(f"{p} = {rounded(v, std if isinstance(std, float) else math.inf)}")
        print(f"Yeoh ({name.replace('_', ', ')}): {', '.join(shown)}; RMS misfit "
              f"{summary['rms_misfit'][f'yeoh_{name}'] * 1e3:.4f} mm "
              f"({100 * summary['misfit_reduction'][f'yeoh_{name}']:+.3f} % below Neo-Hookean)")
    for name, check in summary["checks"].items():
        print(f"[{'ok' if check['passed'] else 'FAILED'}] {name}: {check['limit']}")
    print(f"{'all checks passed' if summary['passed'] else 'SOME CHECKS FAILED'} in {summary['timings']['total']:.1f} s; "
          f"wrote {', '.join(summary['files'])} to {args.out}")
    return 0 if summary["passed"] else 1


if __name__ == "__main__":
    sys.exit(main())
