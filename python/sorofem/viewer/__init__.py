"""Interactive 3-D views in the browser (``sorofem view``), built on viser: a scene's static
equilibrium with live cable sliders, or the playback of a time integration.

The view shows the deformed boundary surface coloured by displacement magnitude (viridis, scaled
to the current maximum) or, chosen in the "colour by" dropdown, by von Mises stress, pressure
(mixed formulation) or J (diverging maps centred on 0 and 1), with a colour bar in mm or kPa;
the cables as red polylines, the fixed nodes as blue points and, optionally, the rest shape or
the surface as a wireframe in the same colours. Shift + drag on the body pulls the node under
the pointer with a spring (:meth:`View.grab`, :meth:`View.drag_to`, :meth:`View.release`), as
runSofa and MuJoCo's viewer do. The control panel has one slider per cable for its command
(the actuation alpha of a spring chain, the pull in mm or the tension in N of a tendon) that
moves it by continuation from the equilibrium shown, as :func:`sorofem.actuate` does, and a
dropdown that switches between the standard and the mixed formulation; the status gives each
tendon's solved tension and pull (a slack tendon is drawn grey and said to be slack). The
body's obstacles are drawn in translucent grey (a plane as a square around the body) and the
contact forces as arrows, with their scale and each obstacle's total force in the panel. A
scene with ``[dynamics]`` is shown at its static equilibrium, and its button "simulate
[dynamics]" (:meth:`View.simulate`; disabled, with a hint, when the scene has none) integrates
the motion with the formulation and cable actuations set in the page, showing the steps done
and a cancel button, and plays it in the same page with the playback controls below, until
"back to static" (:meth:`View.show_static`). A trajectory of your own plays with
:func:`view_trajectory`.

``sorofem view`` (:func:`serve`) gives every browser tab its own view (its own body, sliders,
checkboxes, playback and camera: :func:`serving.per_client` on viser's client handles);
:func:`build_view` on a ``viser.ViserServer`` draws one view that every tab shares.

**Playback** (:func:`build_trajectory_view`, :func:`view_trajectory`): a
:class:`~sorofem.Trajectory` returned by :func:`sorofem.simulate`, or the ``.pvd`` series that
:meth:`~sorofem.Trajectory.write_pvd` and ``sorofem run`` write, is shown frame by frame with a
frame slider, a play/pause button, the playback speed (multiples of real time) and a loop
toggle. Each frame redraws the one surface, coloured by displacement magnitude (one colour
scale, 0 .. the largest displacement of the whole motion, shown by a colour bar), and moves the
cables and the obstacles on a path (a :class:`~sorofem.Trajectory` draws its body's obstacles; a
``.pvd`` does not record them); nothing is re-created.

Needs the optional extra ``viewer`` (viser, trimesh): ``pip install ".[viewer]"`` from a checkout
of sorofem (README, "Install"). :func:`build_view` takes any
``viser.ViserServer``, so it runs without a browser (that is how it is tested); ``_cli`` starts the
server and waits.

Examples
--------
>>> import viser                                             # doctest: +SKIP
>>> import sorofem as sf
>>> from sorofem.viewer import build_view
>>> server = viser.ViserServer(host="127.0.0.1", port=8080)  # doctest: +SKIP
>>> view = build_view(sf.Scene.load("examples/scenes/cable_cantilever.toml"), server)  # doctest: +SKIP
>>> view.sliders[0].value = 0.7     # re-solves, as dragging the slider does  # doctest: +SKIP
>>> view.result.actuations                                   # doctest: +SKIP
[0.7]
>>> motion = view.simulate()     # a scene with [dynamics]: as the button; plays  # doctest: +SKIP
>>> view.show_static()           # as "back to static"       # doctest: +SKIP

Play a motion (serves on http://127.0.0.1:8080 until Ctrl-C):

>>> from sorofem.viewer import view_trajectory
>>> trajectory = sf.simulate(body, dt=0.01, steps=200, gravity=(0, 0, -9.81))  # doctest: +SKIP
>>> view_trajectory(trajectory)                              # doctest: +SKIP
>>> view_trajectory("results/run")   # a run's folder, or results/run/trajectory.pvd  # doctest: +SKIP
"""

from __future__ import annotations

import copy
import os
from pathlib import Path
from typing import Any

from .._deprecated import moved
from ..errors import InputError
from ..scene import Scene
from . import serving
from .colours import COLOR_FIELDS, colour_by_magnitude, colour_field, nodal_field
from .frames import Frames, load_frames
from .playback import TrajectoryView, build_trajectory_view, simulate_in_chunks, view_trajectory
from .serving import PerClient, per_client
from .static_view import View, build_view, rebuild_body

__all__ = [
    "View",
    "build_view",
    "colour_by_magnitude",
    "COLOR_FIELDS",
    "nodal_field",
    "colour_field",
    "rebuild_body",
    "Frames",
    "load_frames",
    "TrajectoryView",
    "build_trajectory_view",
    "view_trajectory",
    "simulate_in_chunks",
    "PerClient",
    "per_client",
    "serve",
]


def serve(path: str | os.PathLike[str], host: str = "127.0.0.1", port: int = 8080, trajectory: bool = False) -> int:
    """``sorofem view PATH``: serve a view until interrupted (Ctrl-C); returns the exit code 0.

    ``PATH`` is a scene (its static equilibrium with cable sliders; with ``trajectory=True`` its
    ``[dynamics]`` are simulated and played), a ``.pvd`` time series, or a folder holding
    ``trajectory.pvd`` (``sorofem run``'s ``--out`` folder), which is played. Each browser tab
    gets its own view (:func:`per_client`): the scene is solved once, and each tab moves its own
    copy of the body from that equilibrium, with a compiled model of its own (a model keeps the
    last solve's tendon tensions, pressures and barrier stiffness as the next warm start, which
    must not come from another tab).
    """
    viser = serving.require_viser()
    path = Path(path)
    playback = path.is_dir() or path.suffix.lower() == ".pvd"
    if playback:
        source: Any = load_frames(path)
    else:
        scene = Scene.load(path)
        if trajectory:
            if scene.dynamics is None:
                raise InputError(f"{path}: --trajectory needs a [dynamics] table in the scene")
            source = Frames.from_trajectory(scene.simulate(), source=str(path))
    if playback or trajectory:
        frames = load_frames(source)
        what = f"{path} ({frames.n_frames} frames)"

        def build(client: Any) -> Any:
            return build_trajectory_view(frames, client, play=True)
    else:
        equilibrium = scene.solve()
        what = str(path)

        def build(client: Any) -> Any:
            # A deep copy travels without the compiled model (Body.__getstate__), as a pickled
            # body does: each tab builds its own.
            return build_view(scene, client, body=copy.deepcopy(scene.body), equilibrium=equilibrium)
    server = viser.ViserServer(host=host, port=port, verbose=False)
    tabs = per_client(server, build)
    print(f"sorofem view: {what} at http://{host}:{server.get_port()} (Ctrl-C to stop)", flush=True)
    serving.wait_until_interrupted(server, tabs.close)
    return 0


#: Old private name of :func:`serve`.
_cli = serve

__getattr__ = moved(__name__, {"COLOUR_FIELDS": (lambda: COLOR_FIELDS, "sorofem.plot.COLOR_FIELDS")})

# Documented (and pickled) as members of this package, whichever module holds them.
for _public in (View, build_view, colour_by_magnitude, nodal_field, colour_field, rebuild_body, Frames, load_frames,
                TrajectoryView, build_trajectory_view, view_trajectory, simulate_in_chunks, PerClient, per_client):
    _public.__module__ = __name__
