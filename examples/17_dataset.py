"""A dataset of actuation -> shape pairs for a two-cable finger, made with ``sf.sweep``, and a
small regression that predicts held-out shapes: a starting point for learned controllers.

The finger: a 10 x 2 x 2 cm silicone bar (E = 500 kPa, nu = 0.45, rho = 1080 kg/m^3), 10 x 2 x 2
cells of 6 tets, clamped at x = 0, under gravity (0, 0, -9.81) m/s^2. Two cables run its length
3 mm inside its faces: cable 0 under the top face (z = 17 mm, centred in y), cable 1 inside the
side face y = 20 mm (centred in z); 10 segments of 1e5 N/m each. Pulling cable 0 lifts the tip,
pulling cable 1 swings it sideways (+y); together they reach a 2-D patch of tip positions.

1. **Dataset.** ``sf.sweep`` solves ``SAMPLES`` Latin-hypercube samples of the two actuations
   (alpha in [0.8, 0.92] each, where both cables are taut: closer to 1 a cable goes slack and
   the map from actuation to shape has a kink) on a local Dask cluster and collects the
   deformed positions of two markers (the centre of the tip face and the centre of the finger)
   per case in ``DIR/dataset/results.parquet``.
2. **Regression.** The cases are split 80/20 at random (seeded); a polynomial of degree 4 in the
   two actuations (15 coefficients per marker coordinate, least squares) and a k-nearest-neighbour
   interpolation (k = 4, inverse distance, scipy's cKDTree) are fitted on the 80 % and predict
   the held-out 20 %.

The script exits with status 1 unless every check passes:

* ``all_converged``: every case of the sweep converged.
* ``polynomial_predicts_held_out``: the polynomial's RMS error on the held-out cases is below
  1 % of the tip's range of motion over the dataset (its largest extent along x, y or z).
* ``polynomial_beats_neighbours``: the smooth polynomial is more accurate than the
  nearest-neighbour interpolation (the map from actuation to shape is smooth).
* ``predicts_a_new_solve``: at an actuation not in the dataset, (0.87, 0.91), a direct solve
  of the finger (``Scene.solve``, no sweep) puts the tip within that 1 % of the polynomial's
  prediction.
* ``pulls_act_as_routed``: over the held-out cases, pulling cable 0 harder (smaller alpha) lifts
  the tip (d tip_z / d alpha_0 < 0 from the fit) and pulling cable 1 moves it to +y
  (d tip_y / d alpha_1 < 0), everywhere.

Outputs in ``--out DIR`` (default ``results/dataset``): the sweep's folder ``dataset/``,
``summary.json`` (errors, timings, checks) and ``dataset.png`` (the tip positions of the
dataset and the held-out predictions).

Run::

    python examples/17_dataset.py --out results/dataset [--samples 1000] [--workers 2]
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

#: The optional packages the sweep needs (the cluster extra).
REQUIRED_MODULES = ("distributed", "pyarrow")
SAMPLES = 1000
QUICK_SAMPLES = 150
ALPHA_RANGE = (0.8, 0.92)
SEED = 11
TIP = (0.1, 0.01, 0.01)  # m, rest: the centre of the tip face
MIDDLE = (0.05, 0.01, 0.01)  # m, rest: the centre of the finger
NEW_ALPHA = (0.87, 0.91)
DEGREE = 4
POWERS = [(i, j) for i in range(DEGREE + 1) for j in range(DEGREE + 1 - i)]
SCENE = """\
# A two-cable finger: 10 x 2 x 2 cm, clamped at x = 0 (examples/17_dataset.py).
[mesh]
box = { size = [0.1, 0.02, 0.02], cells = [10, 2, 2] }

[material]
youngs_modulus = 500e3
poisson_ratio = 0.45
density = 1080

[[fixed]]
box = { min = [-1e-9, -1, -1], max = [1e-9, 1, 1] }

[loads]
gravity = [0, 0, -9.81]

[[cable]]                     # under the top face: lifts the tip
start = [0, 0.01, 0.017]
direction = [1, 0, 0]
length = 0.1
divisions = 10
stiffness = 1e5

[[cable]]                     # inside the side face y = 2 cm: swings the tip to +y
start = [0, 0.017, 0.01]
direction = [1, 0, 0]
length = 0.1
divisions = 10
stiffness = 1e5
"""
KEYS = ("cable[0].actuation", "cable[1].actuation")


def _scaled(alpha: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    lo, hi = ALPHA_RANGE
    a, b = ((2.0 * np.asarray(alpha, dtype=float) - (lo + hi)) / (hi - lo)).T
    return a, b, 2.0 / (hi - lo)


def features(alpha: np.ndarray) -> np.ndarray:
    """The monomials a^i b^j, i + j <= DEGREE, of the two actuations scaled to [-1, 1] over
    ALPHA_RANGE, ``(n, 15)``."""
    a, b, _ = _scaled(alpha)
    return np.column_stack([a**i * b**j for i, j in POWERS])


def features_gradient(alpha: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """d features / d alpha_0 and d features / d alpha_1, each ``(n, 15)``."""
    a, b, scale = _scaled(alpha)
    da = [scale * i * a ** max(i - 1, 0) * b**j for i, j in POWERS]
    db = [scale * j * a**i * b ** max(j - 1, 0) for i, j in POWERS]
    return np.column_stack(da), np.column_stack(db)


def neighbours(train_x: np.ndarray, train_y: np.ndarray, x: np.ndarray, k: int = 4) -> np.ndarray:
    """Inverse-distance weighted mean of the ``k`` nearest training cases."""
    from scipy.spatial import cKDTree

    distance, index = cKDTree(train_x).query(x, k=k)
    weights = 1.0 / np.maximum(distance, 1e-12)
    return np.einsum("nk,nkd->nd", weights, train_y[index]) / weights.sum(axis=1, keepdims=True)


def _direct_tip(scene: Path, alpha: tuple[float, float]) -> np.ndarray:
    """The tip centre's position from a plain solve of the scene (no sweep) with the cables at ``alpha``."""
    finger = sf.Scene.load(scene)
    for c, a in enumerate(alpha):
        finger.body.set_actuation(c, a)
    result = finger.solve()
    return sf.Target.points([TIP], [TIP]).bind(finger.mesh).points(result.positions)[0]


def run(out_dir: str | Path = "results/dataset", quick: bool = False, samples: int | None = None,
        workers: int | None = None) -> dict[str, Any]:
    """Make the dataset, fit, check; write the outputs to ``out_dir`` and return the summary."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    n = samples or (QUICK_SAMPLES if quick else SAMPLES)
    scene = out / "finger.toml"
    scene.write_text(SCENE, encoding="utf-8")
    t0 = time.perf_counter()
    sweep = sf.sweep(scene, out / "dataset", sample={k: ALPHA_RANGE for k in KEYS}, samples=n, seed=SEED,
                     markers=[TIP, MIDDLE], workers=workers, force=True)
    t1 = time.perf_counter()
    table = sweep.table(pandas=False)
    column = lambda name: np.array(table.column(name).to_pylist(), dtype=float)  # noqa: E731
    alpha = np.column_stack([column(k) for k in KEYS])
    shape = np.column_stack([column(f"marker[{i}].{a}") for i in range(2) for a in "xyz"])
    converged = np.array(table.column("converged").to_pylist())

    rng = np.random.default_rng(SEED)
    order = rng.permutation(len(alpha))
    test, train = order[: len(alpha) // 5], order[len(alpha) // 5:]
    coefficients, *_ = np.linalg.lstsq(features(alpha[train]), shape[train], rcond=None)
    predicted = features(alpha[test]) @ coefficients
    knn = neighbours(alpha[train], shape[train], alpha[test])
    rms = lambda e: float(np.sqrt(np.mean(np.sum(e.reshape(len(e), -1, 3) ** 2, axis=2))))  # noqa: E731
    poly_error, knn_error = rms(predicted - shape[test]), rms(knn - shape[test])
    tip = shape[:, :3]
    span = float(np.max(tip.max(axis=0) - tip.min(axis=0)))
    tolerance = 0.01 * span

    new_tip = _direct_tip(scene, NEW_ALPHA)
    new_prediction = (features(np.array([NEW_ALPHA])) @ coefficients)[0, :3]
    d0, d1 = (g @ coefficients for g in features_gradient(alpha[test]))
    t2 = time.perf_counter()

    checks = {
        "all_converged": {"passed": bool(converged.all()), "value": int(converged.sum()), "limit": f"{len(alpha)} cases"},
        "polynomial_predicts_held_out": {"passed": poly_error < tolerance, "value": poly_error,
                                         "limit": f"< {tolerance:.3g} m (1 % of the tip's range {span:.3g} m)"},
        "polynomial_beats_neighbours": {"passed": poly_error < knn_error, "value": [poly_error, knn_error],
                                        "limit": "polynomial RMS < k-nearest-neighbour RMS"},
        "predicts_a_new_solve": {"passed": float(np.linalg.norm(new_prediction - new_tip)) < tolerance,
                                 "value": float(np.linalg.norm(new_prediction - new_tip)), "limit": f"< {tolerance:.3g} m"},
        "pulls_act_as_routed": {"passed": bool(np.all(d0[:, 2] < 0) and np.all(d1[:, 1] < 0)),
                                "value": [float(d0[:, 2].max()), float(d1[:, 1].max())],
                                "limit": "d tip_z / d alpha_0 < 0 and d tip_y / d alpha_1 < 0 on every held-out case"},
    }
    _plot(tip, shape[test, :3], predicted[:, :3], out / "dataset.png")
    summary = {
        "cases": len(alpha),
        "train": len(train),
        "held_out": len(test),
        "solved": sweep.solved,
        "workers": sweep.workers,
        "tip_range": span,
        "polynomial_rms": poly_error,
        "neighbours_rms": knn_error,
        "new_actuation": list(NEW_ALPHA),
        "new_tip": new_tip.tolist(),
        "new_tip_predicted": new_prediction.tolist(),
        "checks": checks,
        "passed": all(c["passed"] for c in checks.values()),
        "files": ["dataset/", "summary.json", "dataset.png"],
        "timings": {"sweep": t1 - t0, "fit_and_checks": t2 - t1},
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    return summary


def _plot(tip: np.ndarray, held_out: np.ndarray, predicted: np.ndarray, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 4.5))
    ax.plot(1e3 * tip[:, 1], 1e3 * tip[:, 2], ".", ms=2, color="0.6", label="dataset (tip centre)")
    ax.plot(1e3 * held_out[:, 1], 1e3 * held_out[:, 2], "o", mfc="none", ms=5, label="held out")
    ax.plot(1e3 * predicted[:, 1], 1e3 * predicted[:, 2], "x", ms=4, label=f"polynomial (degree {DEGREE})")
    ax.set_xlabel("tip y [mm]")
    ax.set_ylabel("tip z [mm]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("results/dataset"), metavar="DIR")
    parser.add_argument("--samples", type=int, default=SAMPLES, help=f"cases of the dataset (default {SAMPLES})")
    parser.add_argument("--workers", type=int, help="local worker processes (default: one per core)")
    args = parser.parse_args(argv)
    summary = run(args.out, samples=args.samples, workers=args.workers)
    solved = (f"{summary['solved']} solved on {summary['workers']} worker(s) in {summary['timings']['sweep']:.1f} s"
              if summary["solved"] else f"all already in {args.out / 'dataset'}")
    print(f"{summary['cases']} cases ({solved}); tip range {1e3 * summary['tip_range']:.1f} mm")
    print(f"held-out RMS error: polynomial {1e3 * summary['polynomial_rms']:.3f} mm, "
          f"4 nearest neighbours {1e3 * summary['neighbours_rms']:.3f} mm")
    for name, check in summary["checks"].items():
        print(f"[{'ok' if check['passed'] else 'FAILED'}] {name}: {check['limit']}")
    print(f"{'all checks passed' if summary['passed'] else 'SOME CHECKS FAILED'}; wrote "
          f"{', '.join(summary['files'])} to {args.out}")
    return 0 if summary["passed"] else 1


if __name__ == "__main__":
    sys.exit(main())
