"""Gradients and inverse problems: calibrate the material, control the cables.

Three functions share one machinery (a parametrisation of the body, warm-started static
solves, forward and adjoint sensitivities from the extension):

* :func:`gradient`: the value of a scalar objective ``O(x)`` of the equilibrium node
  positions ``x`` and its total derivative with respect to named parameters, through the
  adjoint (``dO/dtheta = -lambda^T dr/dtheta`` with ``H lambda = dO/dx``; one
  factorisation of the Hessian at the solution).
* :func:`estimate`: fit material parameters so that a :class:`~sorofem.Target` is met, by
  least squares (Levenberg-Marquardt on the Jacobian from forward sensitivities), L-BFGS-B
  (adjoint gradient of ``1/2 |r|^2``) or Nelder-Mead (no derivatives); several scenarios
  jointly, several starts, Gauss-Newton uncertainty; with ``dynamics=``, damping (and
  material) parameters from recorded marker tracks of a motion (:func:`marker_tracks`).
* :func:`control`: cable commands (spring alphas, tendon pulls or tensions) that bring a
  target as close as possible; with ``dynamics=``, an open-loop schedule of them (keyframes)
  that brings it there at a time T and keeps it there (:class:`ScheduleResult`).

Parameters (``params=``), each a scalar unless noted:

============================  ====================================  =========================
name                          meaning                               optimised as
============================  ====================================  =========================
``shear_modulus``             mu, Pa                                log mu
``lame_lambda``               lambda, Pa                            log lambda
``youngs_modulus``            E, Pa (nu kept)                       log E
``poisson_ratio``             nu (E kept), 0 < nu < 0.5             log(nu / (0.5 - nu))
``density``                   rho, kg/m^3                           log rho
``shear_modulus_field``       mu per element ``(m,)``               log mu_e
``lame_lambda_field``         lambda per element ``(m,)``           log lambda_e
``gravity``                   ``(3,)`` m/s^2 (:func:`gradient` only) itself
``cable_actuation``           alpha per cable ``(c,)``              log alpha
``cable_stiffness``           N/m per cable ``(c,)``                log k
``cable_pull``                m, pull per tendon ``(c,)``           itself
``cable_tension``             N, tension per tendon ``(c,)``        itself
============================  ====================================  =========================

A material name may be restricted to a region, ``"shear_modulus:soft"``, with
``regions={"soft": mask}`` (a boolean mask over elements, or element indices); elements
outside every region keep the body's material. ``(mu, lambda)`` and ``(E, nu)`` names cannot
both act on the same element.

Examples
--------
>>> import sorofem as sf
>>> mesh = sf.Mesh.box(size=(0.4, 0.1, 0.1), cells=(8, 2, 2))
>>> body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080))
>>> body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
>>> goal = sf.solve_static(body, gravity=(0, 0, -9.81)).positions
>>> target = sf.Target.nodes(range(81), goal)
>>> fit = sf.estimate(body, target, ["shear_modulus", "lame_lambda"], x0=[20e3, 0.2e6], gravity=(0, 0, -9.81))
>>> round(fit.params["shear_modulus"]), fit.forward_solves <= 15
(22759, True)
"""

from __future__ import annotations

from ._analysis import PROFILE_CONDITION
from ._control import control
from ._control_dynamics import DYNAMICS_KEYS, ScheduleResult
from ._estimate import TornHistoryWarning, estimate
from ._estimate_dynamics import DAMPING_PARAMETERS, MOTION_PARAMETERS, marker_tracks
from ._gradient import gradient
from ._parameters import PARAMETERS, parameter_names
from ._problem import DEFAULT_TOLERANCE
from ._trajectory import TRAJECTORY_PARAMETERS, TrajectoryGradientResult, trajectory_gradient
from .results import ControlResult, FitResult, GradientResult, Profile, Uncertainty

__all__ = [
    "PARAMETERS",
    "parameter_names",
    "DEFAULT_TOLERANCE",
    "PROFILE_CONDITION",
    "gradient",
    "trajectory_gradient",
    "TRAJECTORY_PARAMETERS",
    "TrajectoryGradientResult",
    "estimate",
    "marker_tracks",
    "DAMPING_PARAMETERS",
    "MOTION_PARAMETERS",
    "control",
    "GradientResult",
    "FitResult",
    "ControlResult",
    "ScheduleResult",
    "DYNAMICS_KEYS",
    "Uncertainty",
    "Profile",
    "TornHistoryWarning",
]

# Documented (and pickled) as members of this package, whichever private module holds them.
for _public in (gradient, trajectory_gradient, TrajectoryGradientResult, estimate, marker_tracks, control, parameter_names, GradientResult, FitResult, ControlResult, ScheduleResult, Uncertainty,
                Profile, TornHistoryWarning):
    _public.__module__ = __name__
