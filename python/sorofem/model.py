"""Deprecated: the model-building API moved to :mod:`sorofem.mesh`, :mod:`sorofem.materials`,
:mod:`sorofem.body`, :mod:`sorofem.solver` and :mod:`sorofem.static`. Import from ``sorofem``
(``sf.Mesh``, ``sf.Body``, ...) or from those modules; this module goes in the next release.

Outside the layering: nothing in sorofem imports it.
"""

from __future__ import annotations

import warnings

from .body import FORMULATIONS, PRESSURE_MASSES, VOLUMETRIC_MEASURES, Body
from .materials import NeoHookean
from .mesh import Mesh
from .solver import SolveReport
from .static import StaticResult, solve_static

__all__ = [
    "FORMULATIONS",
    "VOLUMETRIC_MEASURES",
    "PRESSURE_MASSES",
    "Mesh",
    "NeoHookean",
    "Body",
    "SolveReport",
    "StaticResult",
    "solve_static",
]

warnings.warn(
    "sorofem.model is deprecated: import Mesh, NeoHookean, Body, solve_static, StaticResult and SolveReport from "
    "sorofem (or sorofem.mesh, sorofem.materials, sorofem.body, sorofem.static, sorofem.solver)",
    DeprecationWarning,
    stacklevel=2,
)
