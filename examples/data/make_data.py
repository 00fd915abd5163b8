"""Generates the data files of the example scenes (``examples/scenes/``) with sorofem itself.

Users do not have the SolidFEM samples: every file here is made by this script, small enough
to keep in the repository, and a test (``tests/test_example_scenes.py``) regenerates the
deterministic ones and compares them with the committed files.

``beam_markers.csv``
    Where six markers on the 0.4 m silicone cantilever of ``estimate.toml`` end up under
    gravity (the truth: Neo-Hookean E = 66 kPa, nu = 0.45, rho = 1080 kg/m^3, standard
    formulation on the 8 x 2 x 2 box mesh), plus Gaussian noise of 0.2 mm (seed 2024), in
    metres: what a motion-capture system would give. ``sorofem estimate`` should recover E
    within its standard error.
``cable_goal.npy``
    Where two tip points of the same cantilever (``control.toml``), with a cable along the
    middle of its bottom, 1 cm inside, are with the cable pulled to alpha = 0.85 (``(2, 3)``
    float64, m): the goal ``sorofem control`` should reach.
``swing_tracks.csv``
    Four markers on the same cantilever (``swing_estimate.toml``), held straight and released
    under gravity at t = 0, filmed at 50 Hz for 0.6 s as it swings down and back (the truth:
    the material above, Rayleigh damping alpha_M = 2 1/s and beta_K = 5 ms, implicit Euler at
    dt = 10 ms, every step to 1e-12), plus Gaussian noise of 0.1 mm (seed 18); the mid-span
    marker is hidden for 0.3 s < t <= 0.4 s. One row per marker seen in a frame, columns time
    (s), marker (its index in the scene's ``[target] points``), x, y, z (m). ``sorofem
    estimate`` should recover both coefficients within their standard errors.
``finger.stl``
    The tapered silicone finger of ``examples/10_surface_to_robot.py`` (120 mm, rounded square
    section 25 -> 15 mm, 96 triangles), binary STL in millimetres.
``finger.vtu``
    That surface filled with tetrahedra by ``sf.tetrahedralize`` (edge length 8 mm; needs the
    optional mesher), in metres: ``finger.toml`` reads it, so the scene runs without the mesher.
    fTetWild's output varies slightly from run to run; the test regenerates it only to check
    its volume.
``h_robot.stl``
    An H-shaped walking robot, 80 mm wide, 60 mm tall, 20 mm thick (two legs joined by a
    bridge), binary STL in millimetres: ``h_robot.stl`` is meshed when ``h_robot.toml`` is
    loaded (``[mesh] surface``).

Run::

    python examples/data/make_data.py [--out examples/data]
"""

from __future__ import annotations

import argparse
import importlib.util
from pathlib import Path

import meshio
import numpy as np

import sorofem as sf

HERE = Path(__file__).resolve().parent
EXAMPLES = HERE.parent

GRAVITY = (0.0, 0.0, -9.81)  # m/s^2
#: The estimate scene's truth and its markers (rest positions on the top face and the tip, m).
ESTIMATE_TRUTH = {"youngs_modulus": 66e3, "poisson_ratio": 0.45, "density": 1080.0}
MARKERS = [[0.1, 0.05, 0.1], [0.2, 0.05, 0.1], [0.3, 0.05, 0.1], [0.4, 0.05, 0.1], [0.4, 0.0, 0.0], [0.4, 0.1, 0.0]]
MARKER_NOISE = 2e-4  # m
SEED = 2024
#: The control scene's goal: alpha of its cable, and the two tip points observed (rest, m).
CONTROL_ALPHA = 0.85
CONTROL_POINTS = [[0.4, 0.05, 0.05], [0.4, 0.05, 0.1]]
#: The swing of the estimate-in-time scene: its true Rayleigh damping, run, markers (rest, m),
#: camera (a frame every FRAME_EVERY steps), noise and the interval the mid-span marker is hidden.
SWING_DAMPING = {"mass_damping": 2.0, "stiffness_damping": 0.005}  # 1/s, s
SWING_DT, SWING_STEPS, SWING_FRAME_EVERY = 0.01, 60, 2  # s, -, -
SWING_MARKERS = [[0.4, 0.05, 0.1], [0.4, 0.0, 0.05], [0.4, 0.1, 0.0], [0.2, 0.05, 0.1]]
SWING_NOISE = 1e-4  # m
SWING_SEED = 18
SWING_HIDDEN = (3, 0.3, 0.4)  # marker, hidden for t in (start, end], s
#: The H robot, mm (x: width, z: height, y: thickness).
H_WIDTH, H_HEIGHT, H_THICKNESS = 80.0, 60.0, 20.0
H_LEG, H_BRIDGE = 20.0, (25.0, 45.0)  # leg width; the bridge spans these heights
FINGER_EDGE = 0.008  # m


def cantilever(material: sf.NeoHookean, cable_alpha: float | None = None) -> sf.Body:
    """The 0.4 m cantilever of ``estimate.toml`` and ``control.toml`` (8 x 2 x 2 box cells,
    clamped at x = 0), with the control scene's cable when ``cable_alpha`` is given."""
    mesh = sf.Mesh.box(size=(0.4, 0.1, 0.1), cells=(8, 2, 2))
    body = sf.Body(mesh, material)
    body.fix(mesh.nodes_on_plane((0.0, 0.0, 0.0), (1.0, 0.0, 0.0)))
    if cable_alpha is not None:
        body.add_cable(sf.Cable.line((0.0, 0.05, 0.01), (1.0, 0.0, 0.0), 0.4, 10, stiffness=1e5, actuation=cable_alpha))
    return body


def beam_markers() -> np.ndarray:
    """Noisy marker positions ``(6, 3)`` of the estimate scene's truth."""
    body = cantilever(sf.NeoHookean(**ESTIMATE_TRUTH))
    result = sf.solve_static(body, GRAVITY, tolerance=1e-12)
    markers = sf.Target.points(MARKERS, MARKERS).bind(body.mesh).points(result.positions)
    return markers + np.random.default_rng(SEED).normal(0.0, MARKER_NOISE, markers.shape)


def cable_goal() -> np.ndarray:
    """The control scene's two tip points with its cable at :data:`CONTROL_ALPHA`, ``(2, 3)``."""
    body = cantilever(sf.NeoHookean(**ESTIMATE_TRUTH), CONTROL_ALPHA)
    result = sf.solve_static(body, GRAVITY, tolerance=1e-12)
    return sf.Target.points(CONTROL_POINTS, CONTROL_POINTS).bind(body.mesh).points(result.positions)


def swing_tracks() -> np.ndarray:
    """Rows ``[time, marker, x, y, z]`` of the noisy, partly hidden swing (see the module
    docstring), in time then marker order."""
    body = cantilever(sf.NeoHookean(**ESTIMATE_TRUTH))
    traj = sf.simulate(body, SWING_DT, SWING_STEPS, gravity=GRAVITY, damping=tuple(SWING_DAMPING.values()),
                       tolerance=1e-12, method="newton", progress=False)
    frames = np.arange(SWING_FRAME_EVERY, SWING_STEPS + 1, SWING_FRAME_EVERY)
    bound = sf.Target.points(SWING_MARKERS, SWING_MARKERS).bind(body.mesh)
    exact = np.stack([bound.points(traj.positions[k]) for k in frames])
    noisy = exact + np.random.default_rng(SWING_SEED).normal(0.0, SWING_NOISE, exact.shape)
    hidden, start, end = SWING_HIDDEN
    rows = [[k * SWING_DT, m, *noisy[i, m]] for i, k in enumerate(frames) for m in range(len(SWING_MARKERS))
            if not (m == hidden and start < k * SWING_DT <= end + 1e-12)]
    return np.array(rows)


def finger_surface() -> tuple[np.ndarray, np.ndarray]:
    """The finger of example 10, in millimetres."""
    spec = importlib.util.spec_from_file_location("example_10", EXAMPLES / "10_surface_to_robot.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    points, triangles = module.finger_surface()
    return points * 1e3, triangles


def h_surface() -> tuple[np.ndarray, np.ndarray]:
    """The H robot: its outline in the x-z plane (12 corners, counter-clockwise seen from -y)
    extruded along y, the caps split into the two legs and the bridge; outward normals."""
    w, h, leg = H_WIDTH, H_HEIGHT, H_LEG
    lo, hi = H_BRIDGE
    outline = np.array([[0, 0], [leg, 0], [leg, lo], [w - leg, lo], [w - leg, 0], [w, 0], [w, h], [w - leg, h],
                        [w - leg, hi], [leg, hi], [leg, h], [0, h]], dtype=np.float64)
    n = len(outline)
    # Cap triangles (indices into the outline), counter-clockwise: left leg, bridge, right leg.
    cap = np.array([[0, 1, 2], [0, 2, 9], [0, 9, 10], [0, 10, 11],
                    [2, 3, 8], [2, 8, 9],
                    [5, 6, 7], [5, 7, 8], [5, 8, 3], [5, 3, 4]])
    front = np.c_[outline[:, 0], np.zeros(n), outline[:, 1]]  # y = 0
    back = front + [0.0, H_THICKNESS, 0.0]
    points = np.vstack([front, back])
    j = np.arange(n)
    k = (j + 1) % n
    # Seen from -y (x right, z up) the outline runs counter-clockwise, so the front cap's
    # outward normal is -y: reverse its triangles' order; the sides go front j -> k -> back.
    triangles = np.vstack([cap[:, ::-1], cap + n, np.c_[j, k, k + n], np.c_[j, k + n, j + n]])
    return points, triangles.astype(np.int64)


def write_stl(path: Path, points: np.ndarray, triangles: np.ndarray) -> None:
    points, triangles = sf.meshing.check_surface(points, triangles, path.name)  # closed, oriented
    meshio.write(path, meshio.Mesh(points, [("triangle", triangles)]), binary=True)


def write_all(out: Path, mesher: bool | None = None) -> list[Path]:
    """Write every file into ``out``; the tetrahedral finger only with the mesher (``None``:
    if it is installed). Returns the files written."""
    out.mkdir(parents=True, exist_ok=True)
    written = []
    path = out / "beam_markers.csv"
    header = "# x, y, z [m]: markers of examples/scenes/estimate.toml (examples/data/make_data.py)\nx,y,z\n"
    path.write_text(header + "".join(f"{x:.9e},{y:.9e},{z:.9e}\n" for x, y, z in beam_markers()), encoding="utf-8")
    written.append(path)
    path = out / "cable_goal.npy"
    np.save(path, cable_goal())
    written.append(path)
    path = out / "swing_tracks.csv"
    header = ("# time [s], marker (index in [target] points), x, y, z [m]: the swing of "
              "examples/scenes/swing_estimate.toml (examples/data/make_data.py)\ntime,marker,x,y,z\n")
    path.write_text(header + "".join(f"{t:.2f},{int(m)},{x:.9e},{y:.9e},{z:.9e}\n" for t, m, x, y, z in swing_tracks()),
                    encoding="utf-8")
    written.append(path)
    for name, (points, triangles) in (("finger.stl", finger_surface()), ("h_robot.stl", h_surface())):
        write_stl(out / name, points, triangles)
        written.append(out / name)
    if mesher or (mesher is None and sf.meshing.mesher_available()):
        mesh = sf.tetrahedralize(out / "finger.stl", edge_length=FINGER_EDGE, scale=1e-3)
        mesh.write(out / "finger.vtu")
        written.append(out / "finger.vtu")
    return written


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=HERE, metavar="DIR")
    args = parser.parse_args(argv)
    for path in write_all(args.out):
        print(f"wrote {path} ({path.stat().st_size} bytes)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
