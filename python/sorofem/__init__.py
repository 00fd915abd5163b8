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

from importlib.metadata import PackageNotFoundError, version as _version

from . import cables, dynamics, errors, inverse, io, plot, targets
from .cables import Cable, actuate
from .dynamics import Trajectory, simulate
from .errors import (
    ConvergenceError,
    InputError,
    MeshError,
    ParameterError,
    SceneError,
    ShapeError,
    SolverError,
    SorofemError,
)
from .model import Body, Mesh, NeoHookean, SolveReport, StaticResult, solve_static
from .scene import Scene
from .targets import Target
from .inverse import control, estimate, gradient
from .meshing import tetrahedralize  # the mesher itself (optional extra) is imported on first use

try:
    __version__ = _version("sorofem")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0.0.0"

__all__ = [
    "__version__",
    "Mesh",
    "NeoHookean",
    "Body",
    "solve_static",
    "StaticResult",
    "SolveReport",
    "Scene",
    "Cable",
    "actuate",
    "simulate",
    "Trajectory",
    "Target",
    "gradient",
    "estimate",
    "control",
    "tetrahedralize",
    "SorofemError",
    "InputError",
    "ShapeError",
    "MeshError",
    "ParameterError",
    "SceneError",
    "SolverError",
    "ConvergenceError",
    "cables",
    "dynamics",
    "errors",
    "inverse",
    "io",
    "meshing",
    "plot",
    "targets",
]
