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
  jointly, several starts, Gauss-Newton uncertainty.
* :func:`control`: cable actuations that bring a target as close as possible.

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

import copy
import json
import math
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from .errors import InputError, ParameterError, SolverError
from .progress import Progress
from .targets import BoundTarget, Target

__all__ = [
    "PARAMETERS",
    "gradient",
    "estimate",
    "control",
    "GradientResult",
    "FitResult",
    "ControlResult",
    "Uncertainty",
]

#: Parameter names understood by :func:`gradient`, :func:`estimate` and :func:`control`.
PARAMETERS: tuple[str, ...] = (
    "shear_modulus",
    "lame_lambda",
    "youngs_modulus",
    "poisson_ratio",
    "density",
    "shear_modulus_field",
    "lame_lambda_field",
    "gravity",
    "cable_actuation",
    "cable_stiffness",
)
_MATERIAL = {"shear_modulus", "lame_lambda", "youngs_modulus", "poisson_ratio", "density",
             "shear_modulus_field", "lame_lambda_field"}
_FIELDS = {"shear_modulus_field", "lame_lambda_field"}
_CABLE = {"cable_actuation", "cable_stiffness"}
#: Solve options a scenario may carry besides gravity, actuation and target.
_SOLVE_KEYS = ("tolerance", "max_iterations", "load_steps")
#: Default Newton tolerance of the inverse functions: tighter than a plain solve's, because
#: sensitivities are only as accurate as the equilibrium they linearise.
DEFAULT_TOLERANCE = 1e-10


# ---------------------------------------------------------------------------
# Parametrisation: a vector theta of named parameters -> the core's per-element material,
# gravity and cable values, with the chain rule back.


@dataclass
class _Block:
    name: str
    kind: str
    elements: NDArray[np.int64]  # elements a material block acts on
    cables: NDArray[np.int64]  # cables a cable block acts on
    size: int
    offset: int = 0

    @property
    def slice(self) -> slice:
        return slice(self.offset, self.offset + self.size)


@dataclass
class _State:
    mu: NDArray[np.float64]
    lam: NDArray[np.float64]
    rho: NDArray[np.float64]
    E: NDArray[np.float64]
    nu: NDArray[np.float64]
    gravity: NDArray[np.float64] | None
    actuation: NDArray[np.float64]
    stiffness: NDArray[np.float64]


class _Params:
    """Named parameter blocks of a body; theta is the concatenation of their values."""

    def __init__(
        self,
        body: Any,
        names: str | Sequence[str],
        regions: Mapping[str, ArrayLike] | None = None,
        cables: Sequence[Any] | None = None,
    ) -> None:
        from .cables import cable_index

        if isinstance(names, str):
            names = [names]
        if not names:
            raise InputError("params: expected at least one parameter name")
        m = body.mesh.n_tets
        n_cables = len(body.cables)
        cable_ids = (
            np.arange(n_cables, dtype=np.int64)
            if cables is None
            else np.array([cable_index(body, c) for c in cables], dtype=np.int64)
        )
        self.body = body
        self.blocks: list[_Block] = []
        enu = np.zeros(m, dtype=bool)
        lame = np.zeros(m, dtype=bool)
        offset = 0
        for name in names:
            if not isinstance(name, str):
                raise InputError(f"params: expected parameter names (str), got {name!r}")
            kind, _, region = name.partition(":")
            if kind not in PARAMETERS:
                raise InputError(f"params: unknown parameter {name!r}; expected one of {list(PARAMETERS)} (material ones optionally ':region')")
            elements = np.arange(m, dtype=np.int64)
            if region:
                if kind not in _MATERIAL:
                    raise InputError(f"params: {kind!r} cannot be restricted to a region ({name!r})")
                if not regions or region not in regions:
                    raise InputError(f"params: region {region!r} of {name!r} is not in regions= (given: {sorted(regions or {})})")
                elements = _element_set(regions[region], m, f"regions[{region!r}]")
            if kind in ("youngs_modulus", "poisson_ratio"):
                enu[elements] = True
            elif kind in ("shear_modulus", "lame_lambda") or kind in _FIELDS:
                lame[elements] = True
            if kind in _CABLE:
                if n_cables == 0:
                    raise InputError(f"params: {name!r} needs cables; the body has none")
                size = len(cable_ids)
            elif kind == "gravity":
                size = 3
            elif kind in _FIELDS:
                size = len(elements)
            else:
                size = 1
            if any(b.name == name for b in self.blocks):
                raise InputError(f"params: {name!r} given twice")
            self.blocks.append(_Block(name, kind, elements, cable_ids, size, offset))
            offset += size
        if np.any(enu & lame):
            raise InputError(
                "params: (shear_modulus, lame_lambda) and (youngs_modulus, poisson_ratio) act on the same elements; "
                "choose one pair"
            )
        self.size = offset
        self.enu = enu
        mu0, lam0, rho0 = body.material.per_element(m)
        self.mu0, self.lam0, self.rho0 = mu0, lam0, rho0
        self.E0 = mu0 * (3 * lam0 + 2 * mu0) / (lam0 + mu0)
        self.nu0 = lam0 / (2 * (lam0 + mu0))
        self.alpha0 = np.array(body.actuations, dtype=np.float64)
        self.k0 = np.array([c.stiffness for c in body.cables], dtype=np.float64)

    # -- values ---------------------------------------------------------------------------

    def current(self, gravity: ArrayLike | None = None) -> NDArray[np.float64]:
        """theta of the body as it is (material blocks: the mean over their elements)."""
        theta = np.zeros(self.size)
        for b in self.blocks:
            source = {
                "shear_modulus": self.mu0, "lame_lambda": self.lam0, "density": self.rho0,
                "youngs_modulus": self.E0, "poisson_ratio": self.nu0,
                "shear_modulus_field": self.mu0, "lame_lambda_field": self.lam0,
            }.get(b.kind)
            if b.kind in _FIELDS:
                theta[b.slice] = source[b.elements]
            elif source is not None:
                theta[b.slice] = float(np.mean(source[b.elements]))
            elif b.kind == "gravity":
                theta[b.slice] = np.zeros(3) if gravity is None else np.asarray(gravity, dtype=np.float64)
            elif b.kind == "cable_actuation":
                theta[b.slice] = self.alpha0[b.cables]
            else:
                theta[b.slice] = self.k0[b.cables]
        return theta

    def from_user(self, values: Any, what: str) -> NDArray[np.float64]:
        """theta from a user's list (one entry per name; arrays for fields, gravity, cables)
        or dict name -> value."""
        if isinstance(values, Mapping):
            values = [values[b.name] if b.name in values else self.current()[b.slice] for b in self.blocks]
        values = list(np.atleast_1d(np.asarray(values, dtype=object))) if np.ndim(values) <= 1 else list(values)
        if len(values) != len(self.blocks):
            # A flat vector of the full size is accepted too.
            flat = np.asarray(values, dtype=np.float64).reshape(-1)
            if flat.size == self.size:
                return flat
            raise InputError(f"{what}: expected {len(self.blocks)} value(s), one per parameter {self.names}, got {len(values)}")
        theta = np.zeros(self.size)
        for b, v in zip(self.blocks, values):
            arr = np.asarray(v, dtype=np.float64).reshape(-1)
            if arr.size == 1:
                arr = np.full(b.size, float(arr[0]))
            if arr.size != b.size:
                raise InputError(f"{what}: {b.name!r} expects {b.size} value(s), got {arr.size}")
            theta[b.slice] = arr
        return theta

    @property
    def names(self) -> list[str]:
        return [b.name for b in self.blocks]

    def as_dict(self, theta: NDArray[np.float64]) -> dict[str, Any]:
        """name -> float (scalar blocks) or array."""
        out: dict[str, Any] = {}
        for b in self.blocks:
            v = theta[b.slice]
            out[b.name] = float(v[0]) if b.size == 1 and b.kind not in _CABLE | _FIELDS else v.copy()
        return out

    def state(self, theta: NDArray[np.float64]) -> _State:
        mu, lam, rho = self.mu0.copy(), self.lam0.copy(), self.rho0.copy()
        E, nu = self.E0.copy(), self.nu0.copy()
        gravity = None
        alpha, k = self.alpha0.copy(), self.k0.copy()
        for b in self.blocks:
            v = theta[b.slice]
            if b.kind == "shear_modulus":
                mu[b.elements] = v[0]
            elif b.kind == "lame_lambda":
                lam[b.elements] = v[0]
            elif b.kind == "shear_modulus_field":
                mu[b.elements] = v
            elif b.kind == "lame_lambda_field":
                lam[b.elements] = v
            elif b.kind == "density":
                rho[b.elements] = v[0]
            elif b.kind == "youngs_modulus":
                E[b.elements] = v[0]
            elif b.kind == "poisson_ratio":
                nu[b.elements] = v[0]
            elif b.kind == "gravity":
                gravity = v.copy()
            elif b.kind == "cable_actuation":
                alpha[b.cables] = v
            elif b.kind == "cable_stiffness":
                k[b.cables] = v
        e = self.enu
        mu[e] = E[e] / (2 * (1 + nu[e]))
        lam[e] = E[e] * nu[e] / ((1 + nu[e]) * (1 - 2 * nu[e]))
        return _State(mu, lam, rho, E, nu, gravity, alpha, k)

    # -- chain rule -----------------------------------------------------------------------

    def _partials(self, b: _Block, st: _State) -> dict[str, NDArray[np.float64]]:
        """d(core parameters)/d theta_b for a scalar block (per element arrays, or cables)."""
        m = len(self.mu0)
        el = b.elements
        zeros = lambda: np.zeros(m)  # noqa: E731
        if b.kind in ("shear_modulus", "lame_lambda", "density"):
            key = {"shear_modulus": "mu", "lame_lambda": "lam", "density": "rho"}[b.kind]
            d = zeros()
            d[el] = 1.0
            return {key: d}
        E, nu = st.E[el], st.nu[el]
        dmu, dlam = zeros(), zeros()
        if b.kind == "youngs_modulus":
            dmu[el] = 1 / (2 * (1 + nu))
            dlam[el] = nu / ((1 + nu) * (1 - 2 * nu))
        else:  # poisson_ratio
            dmu[el] = -E / (2 * (1 + nu) ** 2)
            dlam[el] = E * (1 + 2 * nu**2) / ((1 + nu) ** 2 * (1 - 2 * nu) ** 2)
        return {"mu": dmu, "lam": dlam}

    def pullback(self, adjoint: Mapping[str, Any], theta: NDArray[np.float64]) -> NDArray[np.float64]:
        """dO/dtheta from the extension's dO/d(core parameters)."""
        st = self.state(theta)
        grad = np.zeros(self.size)
        for b in self.blocks:
            if b.kind == "shear_modulus_field":
                grad[b.slice] = np.asarray(adjoint["mu"])[b.elements]
            elif b.kind == "lame_lambda_field":
                grad[b.slice] = np.asarray(adjoint["lam"])[b.elements]
            elif b.kind == "gravity":
                grad[b.slice] = np.asarray(adjoint["gravity"])
            elif b.kind in _CABLE:
                grad[b.slice] = np.asarray(adjoint[b.kind])[b.cables]
            else:
                grad[b.offset] = sum(float(np.dot(np.asarray(adjoint[k]), d)) for k, d in self._partials(b, st).items())
        return grad

    def directions(self, theta: NDArray[np.float64]) -> list[dict[str, Any]]:
        """One forward-sensitivity direction (the extension's keys) per component of theta."""
        st = self.state(theta)
        out: list[dict[str, Any]] = []
        m = len(self.mu0)
        for b in self.blocks:
            if b.kind in _FIELDS:
                key = "mu" if b.kind == "shear_modulus_field" else "lam"
                for e in b.elements:
                    d = np.zeros(m)
                    d[e] = 1.0
                    out.append({key: d})
            elif b.kind == "gravity":
                out.extend({"gravity": np.eye(3)[i]} for i in range(3))
            elif b.kind in _CABLE:
                for c in b.cables:
                    d = np.zeros(len(self.alpha0))
                    d[c] = 1.0
                    out.append({b.kind: d})
            else:
                out.append(self._partials(b, st))
        return out

    # -- scaling: s = log theta (logit for nu, identity for gravity) ------------------------

    def _kinds(self) -> NDArray[np.int64]:
        """Per component: 0 log, 1 logit(2 nu), 2 identity."""
        kinds = np.zeros(self.size, dtype=np.int64)
        for b in self.blocks:
            kinds[b.slice] = 1 if b.kind == "poisson_ratio" else 2 if b.kind == "gravity" else 0
        return kinds

    def check(self, theta: NDArray[np.float64], what: str) -> None:
        kinds = self._kinds()
        for b in self.blocks:
            v = theta[b.slice]
            if b.kind == "poisson_ratio" and not np.all((v > 0) & (v < 0.5)):
                raise ParameterError(f"{what}: {b.name} must lie in (0, 0.5), got {v.tolist()}", b.name)
            if kinds[b.offset] == 0 and not np.all(v > 0):
                raise ParameterError(f"{what}: {b.name} must be > 0, got {v.tolist()}", b.name)
            if not np.all(np.isfinite(v)):
                raise ParameterError(f"{what}: {b.name} must be finite, got {v.tolist()}", b.name)

    def to_s(self, theta: NDArray[np.float64]) -> NDArray[np.float64]:
        k = self._kinds()
        with np.errstate(divide="ignore"):
            return np.where(k == 0, np.log(np.abs(theta)), np.where(k == 1, np.log(theta / np.abs(0.5 - theta)), theta))

    def from_s(self, s: NDArray[np.float64]) -> NDArray[np.float64]:
        k = self._kinds()
        with np.errstate(over="ignore"):
            return np.where(k == 0, np.exp(s), np.where(k == 1, 0.5 / (1 + np.exp(-s)), s))

    def dtheta_ds(self, s: NDArray[np.float64]) -> NDArray[np.float64]:
        k = self._kinds()
        theta = self.from_s(s)
        return np.where(k == 0, theta, np.where(k == 1, theta * (1 - 2 * theta), 1.0))

    def bounds_s(self, bounds: Any) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Bounds in s; user bounds are one (lo, hi) per name (None = open) in theta units."""
        lo, hi = np.full(self.size, -np.inf), np.full(self.size, np.inf)
        if bounds is None:
            return lo, hi
        if isinstance(bounds, Mapping):
            bounds = [bounds.get(name) for name in self.names]
        if len(bounds) != len(self.blocks):
            raise InputError(f"bounds: expected one (lo, hi) per parameter {self.names}, got {len(bounds)}")
        kinds = self._kinds()
        for b, pair in zip(self.blocks, bounds):
            if pair is None:
                continue
            a, c = pair
            for value, target in ((a, lo), (c, hi)):
                if value is None:
                    continue
                v = np.full(b.size, float(value))
                if kinds[b.offset] == 0 and value <= 0:
                    continue  # log space: 0 is no bound
                if kinds[b.offset] == 1 and (value <= 0 or value >= 0.5):
                    continue
                target[b.slice] = self.to_s(_fill(self.size, b, v))[b.slice]
        if np.any(lo > hi):
            raise InputError(f"bounds: lower bound above upper bound for {self.names}")
        return lo, hi


def _fill(size: int, b: _Block, v: NDArray[np.float64]) -> NDArray[np.float64]:
    out = np.ones(size)
    out[b.slice] = v
    return out


def _element_set(value: ArrayLike, m: int, name: str) -> NDArray[np.int64]:
    arr = np.asarray(value)
    if arr.dtype == np.bool_:
        if arr.shape != (m,):
            raise InputError(f"{name}: a boolean element mask must have shape ({m},), got {arr.shape}")
        arr = np.flatnonzero(arr)
    arr = arr.astype(np.int64).reshape(-1)
    if arr.size == 0 or arr.min() < 0 or arr.max() >= m:
        raise InputError(f"{name}: expected a non-empty set of element indices in [0, {m})")
    return arr


# ---------------------------------------------------------------------------
# Scenarios and evaluations


@dataclass
class _Scenario:
    target: BoundTarget
    gravity: NDArray[np.float64]
    actuation: NDArray[np.float64] | None
    solve: dict[str, Any]
    name: str
    initial: NDArray[np.float64] | None = None  # the warm start of the next solve
    given_initial: NDArray[np.float64] | None = None  # the user's, where every start begins


def _bind(target: Any, mesh: Any) -> BoundTarget:
    if isinstance(target, BoundTarget):
        return target
    if isinstance(target, Target):
        return target.bind(mesh)
    raise InputError(f"target: expected a sorofem.Target, got {type(target).__name__}")


def _scenarios(
    body: Any, target: Any, scenarios: Sequence[Mapping[str, Any]] | None, gravity: ArrayLike, solve: dict[str, Any]
) -> list[_Scenario]:
    from .cables import cable_index

    specs = list(scenarios) if scenarios else [{}]
    out = []
    for i, spec in enumerate(specs):
        unknown = set(spec) - {"gravity", "actuation", "target", "name", "initial", *_SOLVE_KEYS}
        if unknown:
            raise InputError(f"scenarios[{i}]: unknown keys {sorted(unknown)}; expected gravity, actuation, target, name, initial, {', '.join(_SOLVE_KEYS)}")
        t = spec.get("target", target)
        if t is None:
            raise InputError(f"scenarios[{i}]: no target (give target= or a 'target' per scenario)")
        act = spec.get("actuation")
        actuation = None
        if act is not None:
            actuation = np.array(body.actuations, dtype=np.float64)
            items = act.items() if isinstance(act, Mapping) else enumerate(np.atleast_1d(act))
            for c, a in items:
                actuation[cable_index(body, c)] = float(a)
        opts = {**solve, **{k: spec[k] for k in _SOLVE_KEYS if k in spec}}
        initial = spec.get("initial")
        out.append(
            _Scenario(
                _bind(t, body.mesh),
                np.asarray(spec.get("gravity", gravity), dtype=np.float64).reshape(3),
                actuation,
                opts,
                str(spec.get("name", f"scenario {i}")),
                None if initial is None else np.asarray(getattr(initial, "positions", initial), dtype=np.float64),
            )
        )
        out[-1].given_initial = out[-1].initial
    return out


class _Problem:
    """Residuals of all scenarios as a function of s (scaled theta), with their Jacobian
    (forward sensitivities or adjoints, whichever needs fewer solves) or the gradient of
    ``1/2 |r|^2`` (one adjoint per scenario). Counts forward (static) solves."""

    def __init__(self, body: Any, params: _Params, scenarios: list[_Scenario], regularization: float = 0.0) -> None:
        self.body = body
        self.params = params
        self.scenarios = scenarios
        self.model = body._core_model()
        self.forward_solves = 0
        self.newton_iterations = 0
        self.evaluations = 0
        self.reg = _regularizer(body, params, regularization)
        self.n_data = sum(sc.target.n_residuals for sc in scenarios)
        #: Progress line ticked after every forward solve (None: no progress reporting).
        self.progress: Progress | None = None

    def _tick(self) -> None:
        if self.progress is not None:
            self.progress.set(self.forward_solves)

    def _solve(self, sc: _Scenario, st: _State) -> NDArray[np.float64]:
        model = self.model
        model.set_material(st.mu, st.lam, st.rho)
        alpha = st.actuation.copy()
        if sc.actuation is not None:
            untouched = np.ones(len(alpha), dtype=bool)
            for b in self.params.blocks:
                if b.kind == "cable_actuation":
                    untouched[b.cables] = False
            alpha[untouched] = sc.actuation[untouched]
        for c in range(len(alpha)):
            model.set_actuation(c, float(alpha[c]))
            model.set_cable_stiffness(c, float(st.stiffness[c]))
        g = sc.gravity if st.gravity is None else st.gravity
        opts = sc.solve
        attempts = [(sc.initial, opts["load_steps"])]
        if sc.initial is not None:
            attempts.append((None, opts["load_steps"]))
        attempts.append((None, 4 * opts["load_steps"]))
        for k, (init, steps) in enumerate(attempts):
            self.forward_solves += 1
            try:
                out = model.solve(
                    g, self.body._forces.copy(), self.body._prescribed.copy(), init,
                    opts["tolerance"], opts["max_iterations"], steps,
                )
            except SolverError:  # no convergence, or a singular (unstable) Hessian
                self._tick()
                if k == len(attempts) - 1:
                    raise
                continue
            self._tick()
            self.newton_iterations += int(out.get("iterations", 0))
            sc.initial = np.asarray(out["positions"], dtype=np.float64)
            return sc.initial
        raise AssertionError("unreachable")

    def evaluate(self, s: NDArray[np.float64], want: str = "residual") -> tuple[NDArray[np.float64], Any]:
        """``(r, extra)``: extra is the Jacobian dr/ds (``want="jacobian"``), the gradient of
        ``1/2 |r|^2`` w.r.t. s (``"gradient"``) or None."""
        p = self.params
        theta = p.from_s(s)
        st = p.state(theta)
        dts = p.dtheta_ds(s)
        self.evaluations += 1
        rs, blocks = [], []
        grad = np.zeros(p.size)
        for sc in self.scenarios:
            x = self._solve(sc, st)
            r = sc.target.residual(x)
            rs.append(r)
            if want == "jacobian":
                Jx = sc.target.jacobian(x)
                if p.size <= len(r):
                    cols = []
                    for d in p.directions(theta):
                        dx = np.asarray(self.model.forward(d)["dx"]).reshape(-1)
                        cols.append(Jx @ dx)
                    J = np.column_stack(cols) if cols else np.zeros((len(r), 0))
                else:
                    dense = Jx.toarray()
                    J = np.vstack([p.pullback(self.model.adjoint(row.reshape(-1, 3)), theta) for row in dense])
                blocks.append(J * dts[None, :])
            elif want == "gradient":
                g = (sc.target.jacobian(x).T @ r).reshape(-1, 3)
                grad += p.pullback(self.model.adjoint(g), theta) * dts
        if self.reg is not None:
            rs.append(self.reg @ s)
            if want == "jacobian":
                blocks.append(self.reg.toarray())
            elif want == "gradient":
                grad += self.reg.T @ (self.reg @ s)
        r_all = np.concatenate(rs)
        if want == "jacobian":
            return r_all, np.vstack(blocks)
        if want == "gradient":
            return r_all, grad
        return r_all, None

    def restore(self) -> None:
        """Give the model back the body's own material and cable values."""
        self.model.set_material(*self.body.material.per_element(self.body.mesh.n_tets))
        for c, (cable, alpha) in enumerate(zip(self.body.cables, self.body.actuations)):
            self.model.set_actuation(c, alpha)
            self.model.set_cable_stiffness(c, cable.stiffness)

    def rms(self, r: NDArray[np.float64]) -> float:
        data = r[: self.n_data]
        return float(np.sqrt(data @ data / max(self.n_data // 3, 1)))


def _regularizer(body: Any, params: _Params, weight: float) -> sp.csr_matrix | None:
    """Rows ``sqrt(weight) (s_e - s_f)`` for every pair of face-adjacent elements of each
    field block: Tikhonov smoothing of log mu (or log lambda) across faces."""
    if not weight:
        return None
    rows, cols, vals = [], [], []
    row = 0
    tets = body.mesh.tets
    for b in params.blocks:
        if b.kind not in _FIELDS:
            continue
        local = {int(e): i for i, e in enumerate(b.elements)}
        faces: dict[tuple[int, ...], int] = {}
        for e in b.elements:
            t = tets[e]
            for skip in range(4):
                key = tuple(sorted(int(t[j]) for j in range(4) if j != skip))
                other = faces.pop(key, None)
                if other is None:
                    faces[key] = int(e)
                else:
                    rows += [row, row]
                    cols += [b.offset + local[other], b.offset + local[int(e)]]
                    vals += [1.0, -1.0]
                    row += 1
    if row == 0:
        return None
    return sp.csr_matrix((np.sqrt(weight) * np.array(vals), (rows, cols)), shape=(row, params.size))


# ---------------------------------------------------------------------------
# Gradient


@dataclass
class GradientResult:
    """Value and gradient of an objective at the equilibrium.

    Attributes
    ----------
    value
        O(x) at the equilibrium.
    gradient
        name -> dO/dtheta (float for scalar parameters, arrays for fields, gravity, cables),
        in units of O per unit of the parameter.
    core
        The extension's raw adjoint: dO/d(mu, lam, rho per element, gravity, cable values).
    result
        The :class:`~sorofem.StaticResult` the gradient was taken at.
    """

    value: float
    gradient: dict[str, Any]
    core: dict[str, NDArray[np.float64]]
    result: Any

    @property
    def vector(self) -> NDArray[np.float64]:
        """All gradient entries concatenated in the order of ``params``."""
        return np.concatenate([np.atleast_1d(np.asarray(v, dtype=np.float64)) for v in self.gradient.values()])


def gradient(
    body: Any,
    objective: Any,
    params: str | Sequence[str] = ("shear_modulus", "lame_lambda"),
    gravity: ArrayLike = (0.0, 0.0, 0.0),
    *,
    regions: Mapping[str, ArrayLike] | None = None,
    cables: Sequence[Any] | None = None,
    tolerance: float = DEFAULT_TOLERANCE,
    max_iterations: int = 50,
    load_steps: int = 1,
    initial: Any = None,
) -> GradientResult:
    """Value and adjoint gradient of an objective of the static equilibrium.

    Parameters
    ----------
    body
        The body, at the parameter values where the gradient is wanted.
    objective
        A :class:`~sorofem.Target` (objective ``1/2 |r|^2``, m^2) or a callable
        ``f(positions (n, 3)) -> (value, d value / d positions (n, 3))``.
    params
        Names from :data:`PARAMETERS` (see the module docstring).
    gravity, tolerance, max_iterations, load_steps, initial
        As for :func:`sorofem.solve_static`.
    regions, cables
        Element regions for ``"name:region"`` parameters; the cables of cable parameters
        (default: all).

    Returns
    -------
    GradientResult

    Examples
    --------
    >>> g = sf.gradient(body, sf.Target.nodes([80], [[0.4, 0.1, -0.2]]), ["shear_modulus"],
    ...                 gravity=(0, 0, -9.81))  # doctest: +SKIP
    >>> g.gradient["shear_modulus"]  # m^2 / Pa                          # doctest: +SKIP
    """
    from .model import solve_static

    p = _Params(body, params, regions, cables)
    theta = p.current(gravity)
    result = solve_static(
        body, gravity, tolerance=tolerance, max_iterations=max_iterations, load_steps=load_steps, initial=initial
    )
    if isinstance(objective, (Target, BoundTarget)):
        value, dx = _bind(objective, body.mesh).misfit(result.positions)
    elif callable(objective):
        value, dx = objective(result.positions)
        dx = np.asarray(dx, dtype=np.float64).reshape(body.mesh.n_nodes, 3)
    else:
        raise InputError(f"objective: expected a Target or a callable, got {type(objective).__name__}")
    model = body._core_model()
    # solve_static just left the model at this equilibrium with the body's own parameters.
    core = {k: np.asarray(v) for k, v in model.adjoint(np.ascontiguousarray(dx)).items()}
    grad = p.pullback(core, theta)
    return GradientResult(float(value), p.as_dict(grad), core, result)


# ---------------------------------------------------------------------------
# Estimation


@dataclass
class Uncertainty:
    """Gauss-Newton uncertainty at a least-squares optimum.

    Attributes
    ----------
    sigma
        Residual standard deviation, m: ``sqrt(|r|^2 / (N - p))``.
    covariance
        ``sigma^2 (J^T J)^-1`` in the original parameter units (``J = dr/dtheta``); infinite
        along directions the data do not determine.
    std, relative_std
        Standard deviation of each parameter, absolute and over its value.
    correlation
        Correlation matrix.
    singular_values
        Of the scaled Jacobian ``dr/d log theta`` (m per unit relative change), descending:
        a small one means a combination of parameters the data hardly see.
    condition
        Ratio of the largest to the smallest singular value.
    identifiable
        name -> whether the parameter is pinned by the data: its relative std is below 10 %
        and it has a weight above 1 % in no near-null direction (singular value below 1e-6
        of the largest).
    """

    names: list[str]
    sigma: float
    covariance: NDArray[np.float64]
    std: NDArray[np.float64]
    relative_std: NDArray[np.float64]
    correlation: NDArray[np.float64]
    singular_values: NDArray[np.float64]
    condition: float
    identifiable: dict[str, bool]

    def to_dict(self) -> dict[str, Any]:
        return {
            "sigma": self.sigma,
            "std": dict(zip(self.names, map(float, self.std))),
            "relative_std": dict(zip(self.names, map(float, self.relative_std))),
            "correlation": self.correlation.tolist(),
            "singular_values": self.singular_values.tolist(),
            "condition": self.condition,
            "identifiable": self.identifiable,
        }


def _uncertainty(
    names: list[str], theta: NDArray[np.float64], dts: NDArray[np.float64], r: NDArray[np.float64],
    J_s: NDArray[np.float64], n_data: int,
) -> Uncertainty:
    p = len(theta)
    dof = max(n_data - p, 1)
    sigma = float(np.sqrt(r[:n_data] @ r[:n_data] / dof))
    _, sv, vt = np.linalg.svd(J_s, full_matrices=False)
    null = sv <= 1e-6 * (sv[0] if sv.size and sv[0] > 0 else 1.0)
    inv_sq = np.where(null, np.inf, 1.0 / np.where(null, 1.0, sv) ** 2)
    with np.errstate(invalid="ignore"):
        cov_s = np.einsum("ki,k,kj->ij", vt, inv_sq, vt) * sigma**2 if not np.any(null) else None
    scale = dts
    if cov_s is None:
        # Directions the data do not see: those parameters get an infinite variance.
        weak = np.any(np.abs(vt[null]) > 1e-2, axis=0)
        good = ~null
        cov_s = np.einsum("ki,k,kj->ij", vt[good], inv_sq[good], vt[good]) * sigma**2
        cov_s[weak, :] = np.inf
        cov_s[:, weak] = np.inf
    else:
        weak = np.zeros(p, dtype=bool)
    cov = cov_s * np.outer(scale, scale)
    std = np.sqrt(np.abs(np.diag(cov)))
    with np.errstate(invalid="ignore", divide="ignore"):
        rel = std / np.abs(theta)
        corr = cov_s / np.sqrt(np.outer(np.diag(cov_s), np.diag(cov_s)))
    cond = float(sv[0] / sv[-1]) if sv.size and sv[-1] > 0 else math.inf
    ident = {n: bool(rel[i] < 0.1 and not weak[i]) for i, n in enumerate(names)} if p == len(names) else {}
    return Uncertainty(names, sigma, cov, std, rel, np.nan_to_num(corr, nan=0.0), sv, cond, ident)


@dataclass
class FitResult:
    """Outcome of :func:`estimate`.

    Attributes
    ----------
    params
        name -> fitted value (float, or an array for fields and cables).
    material
        The fitted :class:`~sorofem.NeoHookean` (per-element arrays when regions or fields).
    loss
        ``1/2 |r|^2`` at the optimum, m^2 (regularisation included).
    residual
        Root-mean-square distance of the observed points from their goals, m.
    forward_solves
        Static solves, all starts together (warm-started; failed attempts included).
    newton_iterations
        Newton iterations over those solves.
    iterations
        Optimiser iterations of the best start.
    history
        Per iteration: ``{"start", "iteration", "params", "loss", "rms", "forward_solves", "time"}``.
    uncertainty
        :class:`Uncertainty` (None for fields: too many parameters to invert).
    starts
        Per start: its initial point, final params, loss and forward solves.
    results
        One :class:`~sorofem.StaticResult` per scenario at the optimum.
    """

    params: dict[str, Any]
    material: Any
    loss: float
    residual: float
    forward_solves: int
    newton_iterations: int
    iterations: int
    method: str
    converged: bool
    message: str
    time: float
    history: list[dict[str, Any]] = field(default_factory=list)
    uncertainty: Uncertainty | None = None
    starts: list[dict[str, Any]] = field(default_factory=list)
    results: list[Any] = field(default_factory=list)

    @property
    def youngs_modulus(self) -> Any:
        """E of the fitted material, Pa."""
        return self.material.youngs_modulus

    @property
    def poisson_ratio(self) -> Any:
        """nu of the fitted material."""
        return self.material.poisson_ratio

    @property
    def shear_modulus(self) -> Any:
        return self.material.shear_modulus

    @property
    def lame_lambda(self) -> Any:
        return self.material.lame_lambda

    @property
    def result(self) -> Any:
        """The first scenario's equilibrium at the optimum."""
        return self.results[0] if self.results else None

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON summary."""
        plain = lambda v: v.tolist() if isinstance(v, np.ndarray) else v  # noqa: E731
        return {
            "params": {k: plain(v) for k, v in self.params.items()},
            "material": self.material.to_dict(),
            "loss": self.loss,
            "residual_rms": self.residual,
            "forward_solves": self.forward_solves,
            "newton_iterations": self.newton_iterations,
            "iterations": self.iterations,
            "method": self.method,
            "converged": self.converged,
            "message": self.message,
            "time": self.time,
            "uncertainty": None if self.uncertainty is None else self.uncertainty.to_dict(),
            "starts": [{k: plain(v) for k, v in s.items()} for s in self.starts],
        }

    def __repr__(self) -> str:
        vals = ", ".join(f"{k}={v:.6g}" if isinstance(v, float) else f"{k}=<{np.size(v)} values>" for k, v in self.params.items())
        return f"FitResult({vals}, residual={self.residual:.3g} m, forward_solves={self.forward_solves}, method={self.method!r})"


class _Recorder:
    """History of one run: kept in memory, printed when verbose, appended to a JSON-lines file."""

    def __init__(self, problem: _Problem, verbose: bool, path: Path | None, start: int, t0: float) -> None:
        self.problem, self.verbose, self.path, self.start, self.t0 = problem, verbose, path, start, t0
        self.entries: list[dict[str, Any]] = []

    def __call__(self, s: NDArray[np.float64], loss: float, rms: float) -> None:
        p = self.problem.params
        values = p.as_dict(p.from_s(s))
        entry = {
            "start": self.start,
            "iteration": len(self.entries),
            "params": {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in values.items()},
            "loss": float(loss),
            "rms": float(rms),
            "forward_solves": self.problem.forward_solves,
            "time": time.perf_counter() - self.t0,
        }
        self.entries.append(entry)
        bar = self.problem.progress
        if bar is not None:
            shown = f"it {entry['iteration']}"
            if math.isfinite(loss):
                shown += f", loss {loss:.4e}, rms {rms:.3g} m"
            bar.set(self.problem.forward_solves, postfix=shown)
        if self.verbose:
            shown = " ".join(
                f"{k}={v:.6g}" if isinstance(v, float) else f"{k}={np.array2string(v[:4], precision=5)}"
                for k, v in values.items()
            )
            line = (
                f"[start {self.start} it {entry['iteration']:3d}] loss {loss:.6e} rms {rms:.3e} m {shown} "
                f"solves {entry['forward_solves']} t {entry['time']:.2f} s"
            )
            if bar is not None and bar.active:
                bar.print(line)  # above the progress line
            else:
                print(line, file=sys.stderr, flush=True)
        if self.path is not None:
            with self.path.open("a", encoding="utf-8") as fh:
                fh.write(json.dumps(entry) + "\n")


def _levenberg_marquardt(
    problem: _Problem,
    s0: NDArray[np.float64],
    lo: NDArray[np.float64],
    hi: NDArray[np.float64],
    record: _Recorder,
    max_evaluations: int,
    xtol: float,
    ftol: float,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64], int, bool, str]:
    """Levenberg-Marquardt in s with Marquardt's diagonal scaling and Nielsen's damping
    update; each evaluation is one static solve per scenario plus its sensitivities. Bounds
    by projection. Returns (s, r, J, iterations, converged, message)."""
    s = np.clip(s0, lo, hi)
    r, J = problem.evaluate(s, "jacobian")
    cost = 0.5 * r @ r
    record(s, cost, problem.rms(r))
    damping, grow = 1e-3, 2.0
    evaluations, iterations = 1, 0
    while True:
        A = J.T @ J
        g = J.T @ r
        d = np.maximum(np.diag(A), 1e-12 * max(np.diag(A).max(initial=0.0), 1e-300))
        g_free = np.where(((s <= lo) & (g > 0)) | ((s >= hi) & (g < 0)), 0.0, g)
        if cost == 0.0 or np.max(np.abs(g_free)) <= 1e-15 * max(cost, 1e-300):
            return s, r, J, iterations, True, "gradient vanishes"
        # Parameters on a bound that the gradient pushes outwards stay there (active set).
        free = ~(((s <= lo) & (g > 0)) | ((s >= hi) & (g < 0)))
        step = np.zeros_like(s)
        if not np.any(free):
            return s, r, J, iterations, True, "every parameter is held at a bound"
        M = (A + damping * np.diag(d))[np.ix_(free, free)]
        try:
            step[free] = np.linalg.solve(M, -g[free])
        except np.linalg.LinAlgError:
            step[free] = -np.linalg.lstsq(M, g[free], rcond=None)[0]
        s_new = np.clip(s + step, lo, hi)
        step = s_new - s
        if np.linalg.norm(step) <= xtol * (np.linalg.norm(s) + xtol):
            return s, r, J, iterations, True, f"step below xtol = {xtol:g}"
        if evaluations >= max_evaluations:
            return s, r, J, iterations, False, f"stopped after {evaluations} evaluations (max_evaluations)"
        try:
            r_new, J_new = problem.evaluate(s_new, "jacobian")
            cost_new = 0.5 * r_new @ r_new
        except SolverError:
            cost_new = math.inf
        evaluations += 1
        predicted = -(g @ step + 0.5 * step @ A @ step)
        ratio = (cost - cost_new) / predicted if predicted > 0 else -1.0
        if cost_new < cost and ratio > 0:
            reduction = cost - cost_new
            s, r, J, cost = s_new, r_new, J_new, cost_new
            iterations += 1
            record(s, cost, problem.rms(r))
            damping *= max(1.0 / 3.0, 1.0 - (2.0 * ratio - 1.0) ** 3)
            grow = 2.0
            if reduction <= ftol * (cost + reduction):
                return s, r, J, iterations, True, f"relative loss decrease below ftol = {ftol:g}"
        else:
            damping *= grow
            grow *= 2.0


def _scipy_minimize(
    problem: _Problem,
    s0: NDArray[np.float64],
    lo: NDArray[np.float64],
    hi: NDArray[np.float64],
    record: _Recorder,
    method: str,
    max_evaluations: int,
    xtol: float,
    ftol: float,
) -> tuple[NDArray[np.float64], int, bool, str]:
    """L-BFGS-B (adjoint gradient) or Nelder-Mead on ``1/2 |r|^2`` over its initial value."""
    from scipy.optimize import minimize

    r0, _ = problem.evaluate(s0, "residual")
    scale = max(0.5 * r0 @ r0, 1e-300)
    last: dict[str, Any] = {"s": s0.copy(), "loss": 0.5 * r0 @ r0, "rms": problem.rms(r0)}
    record(s0, last["loss"], last["rms"])
    gradient_based = method == "l-bfgs-b"

    def fun(s: NDArray[np.float64]) -> Any:
        try:
            r, g = problem.evaluate(np.asarray(s, dtype=np.float64), "gradient" if gradient_based else "residual")
        except SolverError:
            return (1e10, np.zeros_like(s)) if gradient_based else 1e10
        loss = 0.5 * r @ r
        last.update(s=np.array(s), loss=loss, rms=problem.rms(r))
        return (loss / scale, g / scale) if gradient_based else loss / scale

    def callback(xk: NDArray[np.float64], *args: Any) -> None:
        if np.array_equal(xk, last["s"]):
            record(xk, last["loss"], last["rms"])
        else:
            record(xk, math.nan, math.nan)

    bounds = list(zip(np.where(np.isfinite(lo), lo, None), np.where(np.isfinite(hi), hi, None)))
    if gradient_based:
        res = minimize(
            fun, s0, jac=True, method="L-BFGS-B", bounds=bounds, callback=callback,
            options={"maxfun": max_evaluations, "maxiter": max_evaluations, "ftol": ftol, "gtol": xtol * 1e-3},
        )
    else:
        simplex = np.vstack([s0] + [s0 + 0.1 * e for e in np.eye(len(s0))])
        res = minimize(
            fun, s0, method="Nelder-Mead", bounds=bounds if np.any(np.isfinite(lo) | np.isfinite(hi)) else None,
            callback=callback,
            options={"maxfev": max_evaluations, "xatol": xtol, "fatol": ftol, "initial_simplex": simplex},
        )
    return np.asarray(res.x, dtype=np.float64), int(res.get("nit", 0)), bool(res.success), str(res.message)


def _fitted_material(body: Any, st: _State) -> Any:
    from .model import NeoHookean

    def compact(a: NDArray[np.float64]) -> Any:
        return float(a[0]) if np.all(a == a[0]) else a

    return NeoHookean(shear_modulus=compact(st.mu), lame_lambda=compact(st.lam), density=compact(st.rho))


def _body_with(body: Any, material: Any) -> Any:
    """A shallow copy of ``body`` with another material (same mesh, supports, loads, cables;
    shares the compiled model, which every solve re-parametrises)."""
    other = copy.copy(body)
    other.material = material
    other._forces = body._forces.copy()
    other._cables = list(body._cables)
    other._actuations = list(body._actuations)
    return other


def _read_history(path: Path, names: list[str]) -> list[dict[str, Any]]:
    entries = []
    for line_no, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        if not line.strip():
            continue
        try:
            entry = json.loads(line)
        except json.JSONDecodeError:
            continue  # a line cut short by an interruption
        if sorted(entry.get("params", {})) != sorted(names):
            raise InputError(f"history_path: {path}:{line_no} has parameters {sorted(entry.get('params', {}))}, not {sorted(names)}")
        entries.append(entry)
    return entries


def estimate(
    body: Any,
    target: Any,
    params: str | Sequence[str] = ("shear_modulus", "lame_lambda"),
    x0: Any = None,
    *,
    bounds: Any = None,
    method: str = "least-squares",
    starts: int | Sequence[Any] | None = None,
    scenarios: Sequence[Mapping[str, Any]] | None = None,
    regions: Mapping[str, ArrayLike] | None = None,
    regularization: float = 0.0,
    gravity: ArrayLike = (0.0, 0.0, 0.0),
    tolerance: float = DEFAULT_TOLERANCE,
    max_iterations: int = 50,
    load_steps: int = 1,
    max_evaluations: int = 200,
    xtol: float = 1e-10,
    ftol: float = 1e-12,
    seed: int = 0,
    verbose: bool = False,
    history_path: str | os.PathLike[str] | None = None,
    resume: bool = False,
    progress: bool | None = None,
) -> FitResult:
    """Fit material parameters so that the body's equilibrium meets a target.

    Minimises ``1/2 sum_scenarios |r|^2`` over the parameters, optimised in log space (logit
    for the Poisson ratio), so that mu and lambda, orders of magnitude apart, are equally
    well scaled.

    Parameters
    ----------
    body
        The body: mesh, supports, loads, cables; its material gives the values of the
        parameters not fitted.
    target
        A :class:`~sorofem.Target` (each scenario may bring its own).
    params
        Names from :data:`PARAMETERS` (material ones optionally ``"name:region"``).
    x0
        Initial values, one per name (arrays for fields), or a dict; default: the body's.
    bounds
        One ``(lo, hi)`` per name (None for open), in the parameter's units.
    method
        ``"least-squares"``: Levenberg-Marquardt on the Jacobian from forward sensitivities
        (one back-substitution per parameter, or one adjoint per residual if there are fewer
        residuals); ``"l-bfgs-b"``: adjoint gradient of ``1/2 |r|^2``; ``"nelder-mead"``:
        values only.
    starts
        More starting points: a list of x0-like values, or a number of random starts drawn
        log-uniformly within ``bounds`` (or within a factor 3 of ``x0``), ``seed`` seeding it.
        The best run wins; all are reported in ``fit.starts``.
    scenarios
        Several load cases fitted jointly: dicts with any of ``gravity``, ``actuation`` (one
        alpha per cable, or a dict cable -> alpha), ``target``, ``tolerance``,
        ``max_iterations``, ``load_steps``, ``initial``, ``name``. Default: one scenario with
        ``gravity`` and ``target``.
    regions
        name -> element mask (or indices) for ``"name:region"`` parameters.
    regularization
        Weight (m^2) of the smoothing of field parameters across element faces:
        adds ``weight sum (log mu_e - log mu_f)^2 / 2`` to the loss.
    gravity, tolerance, max_iterations, load_steps
        Solve options of the default scenario (every static solve is warm-started from the
        previous equilibrium of its scenario).
    max_evaluations
        Budget of objective evaluations per start (each is one solve per scenario).
    xtol, ftol
        Stop when a step changes log-parameters by less than ``xtol`` (relative), or the loss
        decreases by less than ``ftol`` relative (Nelder-Mead: simplex size and spread of the
        normalised loss).
    verbose
        Print one line per iteration on stderr.
    history_path
        Append each iteration as a JSON line here, as it goes.
    resume
        Read ``history_path`` and start from its best point (no extra starts).
    progress
        A progress line on stderr, ticked after every forward solve, with the iteration, the
        loss and the RMS misfit: ``None`` (default) only when stderr is a terminal and the fit
        lasts more than half a second, ``True`` always, ``False`` never (see
        :mod:`sorofem.progress`). The number of solves is not known in advance: the line
        counts them and shows the elapsed time (no ETA).

    Returns
    -------
    FitResult

    Raises
    ------
    InputError
        Unknown parameter or method, bad bounds or scenarios.
    ConvergenceError
        The very first equilibrium cannot be found.

    Examples
    --------
    >>> fit = sf.estimate(body, target, ["shear_modulus", "lame_lambda"], x0=[20e3, 0.2e6],
    ...                   gravity=(0, 0, -9.81))          # doctest: +SKIP
    >>> fit.params, fit.youngs_modulus, fit.uncertainty.relative_std  # doctest: +SKIP
    """
    methods = ("least-squares", "l-bfgs-b", "nelder-mead")
    if method not in methods:
        raise InputError(f"method: expected one of {list(methods)}, got {method!r}")
    t0 = time.perf_counter()
    p = _Params(body, params, regions)
    if any(b.kind == "gravity" for b in p.blocks):
        raise InputError("params: 'gravity' can be differentiated (sf.gradient) but not estimated here")
    solve = {"tolerance": tolerance, "max_iterations": max_iterations, "load_steps": load_steps}
    scs = _scenarios(body, target, scenarios, gravity, solve)
    problem = _Problem(body, p, scs, regularization)
    lo, hi = p.bounds_s(bounds)

    theta0 = p.current() if x0 is None else p.from_user(x0, "x0")
    p.check(theta0, "x0")
    history_file = None if history_path is None else Path(history_path)
    if resume:
        if history_file is None or not history_file.is_file():
            raise InputError(f"resume: needs an existing history_path, got {history_path!r}")
        entries = [e for e in _read_history(history_file, p.names) if math.isfinite(e.get("loss", math.nan))]
        if entries:
            best = min(entries, key=lambda e: e["loss"])
            theta0 = p.from_user(best["params"], "history")
        first_start = 1 + max((int(e.get("start", 0)) for e in entries), default=-1)
        start_points = [theta0]
    else:
        first_start = 0
        start_points = [theta0]
        if isinstance(starts, int):
            rng = np.random.default_rng(seed)
            s0 = p.to_s(theta0)
            a = np.where(np.isfinite(lo), lo, s0 - np.log(3.0))
            b = np.where(np.isfinite(hi), hi, s0 + np.log(3.0))
            start_points += [p.from_s(rng.uniform(a, b)) for _ in range(starts)]
        elif starts is not None:
            start_points += [p.from_user(v, f"starts[{i}]") for i, v in enumerate(starts)]

    runs = []
    bar = Progress(desc=f"estimate ({method})", unit="solves", enabled=progress)
    problem.progress = bar
    try:
        for k, theta_start in enumerate(start_points):
            p.check(theta_start, f"start {k}")
            if len(start_points) > 1:
                bar.desc = f"estimate ({method}) start {k + 1}/{len(start_points)}"
            for sc in scs:  # every start from the same beginning
                sc.initial = sc.given_initial
            solves_before = problem.forward_solves
            record = _Recorder(problem, verbose, history_file, first_start + k, t0)
            s0 = np.clip(p.to_s(theta_start), lo, hi)
            if method == "least-squares":
                s, r, J, iters, ok, msg = _levenberg_marquardt(problem, s0, lo, hi, record, max_evaluations, xtol, ftol)
            else:
                s, iters, ok, msg = _scipy_minimize(problem, s0, lo, hi, record, method, max_evaluations, xtol, ftol)
                r, J = None, None
            runs.append(
                {"start": theta_start, "s": s, "r": r, "J": J, "iterations": iters, "converged": ok, "message": msg,
                 "history": record.entries, "forward_solves": problem.forward_solves - solves_before}
            )
        best = min(runs, key=lambda run: run["history"][-1]["loss"] if run["history"] and math.isfinite(run["history"][-1]["loss"]) else math.inf)
        # Final evaluation at the optimum: residual and the Jacobian for the uncertainty.
        s = best["s"]
        fields = any(b.kind in _FIELDS for b in p.blocks)
        if best["J"] is not None and method == "least-squares":
            r, J = best["r"], best["J"]
        else:
            r, J = problem.evaluate(s, "residual" if fields else "jacobian")
        theta = p.from_s(s)
        st = p.state(theta)
        material = _fitted_material(body, st)
        # J is dr/ds: for log parameters that is dr/dlog(theta), what the singular values
        # should measure; the covariance is mapped back with dtheta/ds.
        unc = None if fields or J is None else _uncertainty(p.names, theta, p.dtheta_ds(s), r, J[: problem.n_data], problem.n_data)
        results = _final_results(body, material, st, scs, p)
    finally:
        bar.close()
        problem.restore()
    loss = 0.5 * float(r @ r)
    return FitResult(
        params=p.as_dict(theta),
        material=material,
        loss=loss,
        residual=problem.rms(r),
        forward_solves=problem.forward_solves + len(results),
        newton_iterations=problem.newton_iterations,
        iterations=best["iterations"],
        method=method,
        converged=best["converged"],
        message=best["message"],
        time=time.perf_counter() - t0,
        history=[e for run in runs for e in run["history"]],
        uncertainty=unc,
        starts=[
            {"x0": p.as_dict(run["start"]), "params": p.as_dict(p.from_s(run["s"])),
             "loss": run["history"][-1]["loss"] if run["history"] else math.nan,
             "forward_solves": run["forward_solves"], "iterations": run["iterations"], "converged": run["converged"]}
            for run in runs
        ],
        results=results,
    )


def _final_results(body: Any, material: Any, st: _State, scs: list[_Scenario], p: _Params) -> list[Any]:
    """One StaticResult per scenario at the fitted parameters (warm-started, cheap)."""
    from .model import solve_static

    fitted = _body_with(body, material)
    results = []
    for sc in scs:
        alpha = st.actuation.copy()
        if sc.actuation is not None:
            alpha = np.where(np.isin(np.arange(len(alpha)), [c for b in p.blocks if b.kind == "cable_actuation" for c in b.cables]), alpha, sc.actuation)
        fitted._actuations = [float(a) for a in alpha]
        model = fitted._core_model()
        for c in range(len(alpha)):
            model.set_actuation(c, float(alpha[c]))
            model.set_cable_stiffness(c, float(st.stiffness[c]))
        g = sc.gravity if st.gravity is None else st.gravity
        results.append(
            solve_static(fitted, g, tolerance=sc.solve["tolerance"], max_iterations=sc.solve["max_iterations"],
                         load_steps=sc.solve["load_steps"], initial=sc.initial)
        )
    return results


# ---------------------------------------------------------------------------
# Control


@dataclass
class ControlResult:
    """Outcome of :func:`control`.

    Attributes
    ----------
    actuation
        ``(c,)`` alpha of each controlled cable (in the order of ``cables``).
    distance
        Root-mean-square distance of the target's points from their goals, m.
    max_distance
        Largest distance of a target point from its goal, m.
    reachable
        ``distance <= tolerance``.
    tolerance
        The distance counted as reached, m.
    points
        ``(k, 3)`` where the target's points end up (the closest reachable configuration).
    result
        The :class:`~sorofem.StaticResult` at ``actuation``.
    message
        What happened, including "not reachable" and which bounds are active.
    """

    actuation: NDArray[np.float64]
    distance: float
    max_distance: float
    reachable: bool
    tolerance: float
    points: NDArray[np.float64]
    result: Any
    forward_solves: int
    iterations: int
    message: str
    time: float
    active_bounds: list[str] = field(default_factory=list)
    history: list[dict[str, Any]] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        return {
            "actuation": self.actuation.tolist(),
            "distance": self.distance,
            "max_distance": self.max_distance,
            "reachable": self.reachable,
            "tolerance": self.tolerance,
            "points": self.points.tolist(),
            "forward_solves": self.forward_solves,
            "iterations": self.iterations,
            "message": self.message,
            "time": self.time,
            "active_bounds": self.active_bounds,
        }


def control(
    body: Any,
    target: Any,
    cables: Sequence[Any] | None = None,
    bounds: Sequence[tuple[float, float]] | None = None,
    x0: ArrayLike | None = None,
    *,
    method: str = "l-bfgs-b",
    tolerance: float = 1e-3,
    gravity: ArrayLike = (0.0, 0.0, 0.0),
    solve_tolerance: float = DEFAULT_TOLERANCE,
    max_iterations: int = 50,
    load_steps: int = 1,
    max_evaluations: int = 100,
    xtol: float = 1e-10,
    ftol: float = 1e-14,
    initial: Any = None,
    verbose: bool = False,
    progress: bool | None = None,
) -> ControlResult:
    """Cable actuations that bring a target as close as possible.

    Minimises ``1/2 |r|^2`` over the actuation alpha of the chosen cables (in log alpha,
    within ``bounds``), with the adjoint gradient (``"l-bfgs-b"``) or without
    (``"nelder-mead"``). When the target cannot be reached, the result is the closest
    reachable configuration and ``reachable`` is False.

    Parameters
    ----------
    body
        The body with its cables; their actuations are left unchanged.
    target
        A :class:`~sorofem.Target`.
    cables
        The cables to actuate (:class:`~sorofem.Cable` or indices), default all.
    bounds
        One ``(lo, hi)`` alpha range per cable (default ``(0.3, 1.0)``).
    x0
        Initial alphas (default: the middle of the bounds; a cable at rest length is slack
        and has no gradient).
    tolerance
        Distance (RMS over the target's points, m) counted as reached; default 1 mm.
    gravity, solve_tolerance, max_iterations, load_steps
        Options of the static solves.
    max_evaluations
        Budget of solves.
    initial
        Positions ``(n_nodes, 3)`` or a :class:`~sorofem.StaticResult` to warm-start the first
        solve from (e.g. the previous control's ``result`` when following a moving target).
    verbose
        Print one line per iteration on stderr.
    progress
        A progress line on stderr, ticked after every forward solve, with the iteration and
        the loss: ``None`` (default) only when stderr is a terminal and the search lasts more
        than half a second, ``True`` always, ``False`` never (see :mod:`sorofem.progress`).

    Returns
    -------
    ControlResult

    Examples
    --------
    >>> ctl = sf.control(body, sf.Target.points(rest, goal), cables=[cable], bounds=[(0.3, 1.0)],
    ...                  gravity=(0, 0, -9.81))  # doctest: +SKIP
    >>> ctl.actuation, ctl.reachable, ctl.distance  # doctest: +SKIP
    """
    if method not in ("l-bfgs-b", "nelder-mead"):
        raise InputError(f"method: expected 'l-bfgs-b' or 'nelder-mead', got {method!r}")
    t0 = time.perf_counter()
    p = _Params(body, ["cable_actuation"], cables=cables)
    n = p.size
    if bounds is None:
        bounds = [(0.3, 1.0)] * n
    if len(bounds) != n:
        raise InputError(f"bounds: expected one (lo, hi) per controlled cable ({n}), got {len(bounds)}")
    lo_a = np.array([b[0] for b in bounds], dtype=np.float64)
    hi_a = np.array([b[1] for b in bounds], dtype=np.float64)
    if not np.all((lo_a > 0) & (lo_a <= hi_a)):
        raise InputError(f"bounds: expected 0 < lo <= hi for every cable, got {list(map(tuple, bounds))}")
    lo, hi = np.log(lo_a), np.log(hi_a)
    theta0 = np.sqrt(lo_a * hi_a) if x0 is None else np.asarray(x0, dtype=np.float64).reshape(-1)
    if theta0.shape != (n,) or not np.all(theta0 > 0):
        raise InputError(f"x0: expected {n} alphas > 0, got {np.asarray(x0).tolist()}")
    solve = {"tolerance": solve_tolerance, "max_iterations": max_iterations, "load_steps": load_steps}
    scs = _scenarios(body, target, None if initial is None else [{"initial": initial}], gravity, solve)
    problem = _Problem(body, p, scs)
    problem.progress = bar = Progress(desc=f"control ({method})", unit="solves", enabled=progress)
    record = _Recorder(problem, verbose, None, 0, t0)
    try:
        s, iters, _, msg = _scipy_minimize(problem, np.clip(np.log(theta0), lo, hi), lo, hi, record, method, max_evaluations, xtol, ftol)
        alpha = np.exp(s)
        st = p.state(alpha)
        results = _final_results(body, body.material, st, scs, p)
    finally:
        bar.close()
        problem.restore()
    result = results[0]
    bound = scs[0].target
    distance = bound.rms(result.positions)
    reachable = distance <= tolerance
    active = [
        f"cable {int(c)}: alpha at its {'lower' if abs(s[i] - lo[i]) < 1e-9 else 'upper'} bound {alpha[i]:.4g}"
        for i, c in enumerate(p.blocks[0].cables)
        if abs(s[i] - lo[i]) < 1e-9 or abs(s[i] - hi[i]) < 1e-9
    ]
    if reachable:
        message = f"reached: RMS distance {distance:.3g} m <= tolerance {tolerance:g} m"
    else:
        message = (
            f"not reachable: the closest configuration found is {distance:.3g} m (RMS) from the target, "
            f"above the tolerance {tolerance:g} m" + (f"; {'; '.join(active)}" if active else "")
        )
    return ControlResult(
        actuation=alpha,
        distance=distance,
        max_distance=bound.max_distance(result.positions),
        reachable=bool(reachable),
        tolerance=float(tolerance),
        points=bound.points(result.positions),
        result=result,
        forward_solves=problem.forward_solves + len(results),
        iterations=iters,
        message=message + f" ({msg})",
        time=time.perf_counter() - t0,
        active_bounds=active,
        history=record.entries,
    )
