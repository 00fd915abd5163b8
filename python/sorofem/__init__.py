"""sorofem: simulate cable-driven silicone soft robots with the finite element method.

Examples
--------
>>> import sorofem as sf
>>> mesh = sf.Mesh.box(size=(1.0, 0.1, 0.1), cells=(8, 2, 2))
>>> body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080))
>>> body.fix(mesh.nodes_in_box(min=(-1e-9, -1, -1), max=(1e-9, 1, 1)))
>>> result = sf.solve_static(body, gravity=(0, 0, -9.81))
>>> result.displacement.shape
(81, 3)
"""

from importlib import import_module

from . import (
    cables, dynamics, errors, fitting, inverse, io, materials, meshing, obstacles, plot, progress, solver, targets,
)
from ._deprecated import moved as _moved
from ._version import __version__
from .body import Body
from .cables import Cable
from .dynamics import Trajectory, simulate
from .errors import (
    ConvergenceError,
    InputError,
    Interrupted,
    MeshError,
    OutputError,
    ParameterError,
    SceneError,
    ShapeError,
    SolverError,
    SorofemError,
)
from .fitting import MaterialFit, fit_material
from .inverse import control, estimate, gradient, trajectory_gradient
from .materials import MooneyRivlin, NeoHookean, Ogden, Yeoh
from .mesh import Mesh
from .meshing import tetrahedralize  # the mesher itself (optional extra) is imported on first use
from .obstacles import Box, Obstacle, Plane, Sphere
from .scene import Scene
from .solver import SolveOptions, SolveReport
from .static import StaticResult, actuate, solve_static
from .sweeps import load_sweep, sweep
from .targets import Target

# sorofem.cables.actuate moved up a layer (it solves): the old name answers from here.
cables.__getattr__ = _moved("sorofem.cables", {"actuate": (lambda: actuate, "sorofem.actuate")})


def __getattr__(name: str) -> object:
    # sf.model: the deprecated module (it warns when imported), loaded on first use only.
    if name == "model":
        return import_module(".model", __name__)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

__all__ = [
    "__version__",
    "Mesh",
    "NeoHookean",
    "MooneyRivlin",
    "Yeoh",
    "Ogden",
    "fit_material",
    "MaterialFit",
    "Body",
    "solve_static",
    "StaticResult",
    "SolveReport",
    "SolveOptions",
    "Scene",
    "Cable",
    "Obstacle",
    "Plane",
    "Sphere",
    "Box",
    "actuate",
    "simulate",
    "Trajectory",
    "Target",
    "gradient",
    "trajectory_gradient",
    "estimate",
    "control",
    "sweep",
    "load_sweep",
    "tetrahedralize",
    "SorofemError",
    "InputError",
    "ShapeError",
    "MeshError",
    "ParameterError",
    "SceneError",
    "SolverError",
    "ConvergenceError",
    "OutputError",
    "Interrupted",
    "cables",
    "dynamics",
    "errors",
    "inverse",
    "io",
    "materials",
    "meshing",
    "obstacles",
    "plot",
    "progress",
    "solver",
    "targets",
]
