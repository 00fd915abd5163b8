"""The evaluations of an inverse problem: scenarios (a target, loads and solve options each),
warm-started static solves of all scenarios at a parameter vector, and the residuals with their
Jacobian (forward sensitivities or adjoints) or gradient."""

from __future__ import annotations

import pickle
import threading
import uuid
from collections import OrderedDict
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np
import scipy.sparse as sp
from numpy.typing import ArrayLike, NDArray

from ..body import set_cable_values
from ..cables import cable_index
from ..errors import InputError, SolverError
from ..materials import Material
from ..mesh import Mesh
from ..progress import Progress
from ..solver import SolveOptions
from ..static import StaticResult, solve_static
from ..targets import BoundContactForce, BoundTarget, Target
from ._parameters import COMMAND_PARAMETERS, Parameters, State

__all__ = ["Scenario", "scenarios", "bind", "Problem", "ProblemSpec", "RemoteScenarios", "fitted_material",
           "final_results", "DEFAULT_TOLERANCE"]

#: Solve options a scenario may carry besides gravity, actuation and target.
_SOLVE_KEYS = ("tolerance", "max_iterations", "load_steps")
#: Default Newton tolerance of the inverse functions: tighter than a plain solve's, because
#: sensitivities are only as accurate as the equilibrium they linearise.
DEFAULT_TOLERANCE = 1e-10


@dataclass
class Scenario:
    target: BoundTarget | BoundContactForce
    gravity: NDArray[np.float64]
    actuation: NDArray[np.float64] | None
    solve: SolveOptions
    name: str
    initial: NDArray[np.float64] | None = None  # the warm start of the next solve
    given_initial: NDArray[np.float64] | None = None  # the user's, where every start begins


def bind(target: Any, body: Any) -> BoundTarget | BoundContactForce:
    """A target bound to ``body``'s mesh (a :class:`~sorofem.Target`, or one already bound); a
    contact force to the body itself. ``body`` may be just a mesh for targets on positions."""
    if isinstance(target, (BoundTarget, BoundContactForce)):
        return target
    if isinstance(target, Target):
        if isinstance(body, Mesh):
            return target.bind(body)
        return target.bind(body.mesh, body=body)
    raise InputError(f"target: expected a sorofem.Target, got {type(target).__name__}")


def scenarios(
    body: Any, target: Any, scenarios: Sequence[Mapping[str, Any]] | None, gravity: ArrayLike, solve: SolveOptions
) -> list[Scenario]:
    """The scenarios of an inverse problem: each one a target bound to the mesh, its gravity,
    actuation and solve options, from the user's dicts (default: one with ``target`` and
    ``gravity``)."""
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
        opts = solve.replace(**{k: spec[k] for k in _SOLVE_KEYS if k in spec})
        initial = spec.get("initial")
        out.append(
            Scenario(
                bind(t, body),
                np.asarray(spec.get("gravity", gravity), dtype=np.float64).reshape(3),
                actuation,
                opts,
                str(spec.get("name", f"scenario {i}")),
                None if initial is None else np.asarray(getattr(initial, "positions", initial), dtype=np.float64),
            )
        )
        out[-1].given_initial = out[-1].initial
    return out


class Problem:
    """Residuals of all scenarios as a function of s (scaled theta), with their Jacobian
    (forward sensitivities or adjoints, whichever needs fewer solves) or the gradient of
    ``1/2 |r|^2`` (one adjoint per scenario). Counts forward (static) solves."""

    def __init__(self, body: Any, params: Parameters, scenarios: list[Scenario], regularization: float = 0.0) -> None:
        self.body = body
        self.params = params
        self.scenarios = scenarios
        self.model = body.core_model()
        self.forces, self.prescribed = body.forces, body.prescribed_displacement
        self.forward_solves = 0
        self.newton_iterations = 0
        self.evaluations = 0
        self.reg = _regularizer(body, params, regularization)
        self.n_data = sum(sc.target.n_residuals for sc in scenarios)
        #: Progress line ticked after every forward solve (None: no progress reporting).
        self.progress: Progress | None = None
        #: A :class:`RemoteScenarios` that evaluates the scenarios side by side on a Dask
        #: cluster; None: here, one after the other.
        self.remote: Any = None

    def _tick(self) -> None:
        if self.progress is not None:
            self.progress.set(self.forward_solves)

    def _solve(self, sc: Scenario, st: State) -> NDArray[np.float64]:
        model = self.model
        model.set_material_model(*st.core(self.params.model))
        alpha = st.actuation.copy()
        if sc.actuation is not None:
            untouched = np.ones(len(alpha), dtype=bool)
            for b in self.params.blocks:
                if b.kind in COMMAND_PARAMETERS:
                    untouched[b.cables] = False
            alpha[untouched] = sc.actuation[untouched]
        kinds = [kind for kind, _ in self.body.commands]
        set_cable_values(model, list(zip(kinds, alpha)), st.stiffness)
        g = sc.gravity if st.gravity is None else st.gravity
        opts = sc.solve
        attempts = [(sc.initial, opts.load_steps)]
        if sc.initial is not None:
            attempts.append((None, opts.load_steps))
        attempts.append((None, 4 * opts.load_steps))
        for k, (init, steps) in enumerate(attempts):
            self.forward_solves += 1
            try:
                out = model.solve(
                    g, self.forces.copy(), self.prescribed.copy(), init, options=opts.replace(load_steps=steps).to_core(),
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
        self.evaluations += 1
        if self.remote is not None:
            terms = self.remote.scenario_terms(self, s, want)
        else:
            terms = [self.scenario_terms(k, s, want) for k in range(len(self.scenarios))]
        rs = [r for r, _ in terms]
        blocks = [extra for _, extra in terms] if want == "jacobian" else []
        grad = np.zeros(p.size)
        if want == "gradient":
            for _, part in terms:
                grad += part
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

    def scenario_terms(self, k: int, s: NDArray[np.float64], want: str) -> tuple[NDArray[np.float64], Any]:
        """Scenario ``k``'s residual at ``s`` (its solve warm-started from ``initial``, which it
        then updates) and its share of ``extra`` (see :meth:`evaluate`): its rows of the Jacobian,
        or its term of the gradient."""
        p = self.params
        theta = p.from_s(s)
        st = p.state(theta)
        dts = p.dtheta_ds(s)
        sc = self.scenarios[k]
        x = self._solve(sc, st)
        r = sc.target.residual(x)
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
            return r, J * dts[None, :]
        if want == "gradient":
            g = (sc.target.jacobian(x).T @ r).reshape(-1, 3)
            return r, p.pullback(self.model.adjoint(g), theta) * dts
        return r, None

    def fix_contact_stiffness(self, s: NDArray[np.float64]) -> None:
        """Fix the barrier stiffness, which a model with contact takes at its first solve from
        the material then, by solving the first scenario at ``s`` (what the first evaluation at
        ``s`` does); the scenario's warm start is left as it was. Nothing to do once fixed."""
        settings = self.model.contact_settings()
        if settings is None or settings["stiffness"] is not None:
            return
        sc = self.scenarios[0]
        initial = sc.initial
        self._solve(sc, self.params.state(self.params.from_s(s)))
        sc.initial = initial

    def restore(self) -> None:
        """Give the model back the body's own material and cable values."""
        self.body.core_model()

    def rms(self, r: NDArray[np.float64]) -> float:
        data = r[: self.n_data]
        return float(np.sqrt(data @ data / max(self.n_data // 3, 1)))


@dataclass(frozen=True)
class ProblemSpec:
    """What builds an inverse problem again where a Dask worker evaluates it (a start, or
    scenarios): the arguments of the fit, the body travelling without its compiled model."""

    body: Any
    target: Any
    params: Any
    regions: Any
    scenarios: Any
    gravity: Any
    solve: SolveOptions
    regularization: float = 0.0

    def build(self) -> Problem:
        return Problem(self.body, Parameters(self.body, self.params, self.regions),
                       scenarios(self.body, self.target, self.scenarios, self.gravity, self.solve),
                       self.regularization)


#: The problems a worker has built, by fit, each with the lock its evaluations take (a worker
#: of several threads may run two scenarios of one fit at once; they share its model). A
#: worker serves the fits of one client at a time, so a couple are kept.
_BUILT: "OrderedDict[str, tuple[Problem, threading.Lock]]" = OrderedDict()
_BUILT_LOCK = threading.Lock()
_KEPT_PROBLEMS = 2


def _scenario_terms_on_worker(spec: bytes, fit: str, k: int, initial: NDArray[np.float64] | None,
                              s: NDArray[np.float64], want: str) -> tuple[Any, ...]:
    """:meth:`Problem.scenario_terms` of scenario ``k`` where a Dask worker runs it, warm-started
    from the driver's ``initial``: its terms (``None`` and the error where its solve failed), its
    new equilibrium and the solves it took. ``spec`` is the pickled :class:`ProblemSpec`, read at
    the fit's first task on this worker."""
    with _BUILT_LOCK:
        built = _BUILT.pop(fit, None)
        if built is None:
            built = (pickle.loads(spec).build(), threading.Lock())
        _BUILT[fit] = built
        while len(_BUILT) > _KEPT_PROBLEMS:
            _BUILT.popitem(last=False)
    problem, lock = built
    with lock:
        sc = problem.scenarios[k]
        sc.initial = initial
        solves, iterations = problem.forward_solves, problem.newton_iterations
        try:
            r, extra = problem.scenario_terms(k, s, want)
        except SolverError as error:  # returned with the solves it took, which the driver counts
            r, extra = None, error
        return r, extra, sc.initial, problem.forward_solves - solves, problem.newton_iterations - iterations


class RemoteScenarios:
    """The scenarios of each evaluation of a :class:`Problem` solved side by side on the workers
    of a Dask ``client``. Each one is warm-started from the equilibrium the driver keeps for it,
    so the evaluations are those of the driver's own loop, bit for bit, whichever worker solves
    them. (To round-off with a tendon pulled by a length: a solve starts its tension from the
    last solve of the same model, which differs between a worker's model and the driver's.)
    The body (its barrier stiffness fixed first, see :meth:`Problem.fix_contact_stiffness`)
    goes with every task, pickled once here: a worker builds the problem at the fit's first task
    it runs and keeps it. (Scattered once instead, the body would be a dependency of every task,
    which Dask's memory manager may leave on one worker only, and a task elsewhere then waits for
    a transfer from it: with Dask 2026.8, one such transfer failed in a stress test of a
    thousand evaluations and left its task waiting for ever.)"""

    def __init__(self, client: Any, spec: ProblemSpec) -> None:
        self.client = client
        self.fit = uuid.uuid4().hex
        self.spec = pickle.dumps(spec, protocol=pickle.HIGHEST_PROTOCOL)

    def scenario_terms(self, problem: Problem, s: NDArray[np.float64], want: str) -> list[tuple[Any, Any]]:
        futures = [self.client.submit(_scenario_terms_on_worker, self.spec, self.fit, k, sc.initial, s, want,
                                      pure=False)
                   for k, sc in enumerate(problem.scenarios)]
        terms = []
        for sc, (r, extra, x, solves, iterations) in zip(problem.scenarios, self.client.gather(futures)):
            problem.forward_solves += solves
            problem.newton_iterations += iterations
            if r is None:
                # As the loop here: the scenarios before it keep their new equilibria (the next
                # warm starts), and its error is raised (the optimisers take a SolverError as a
                # rejected step).
                problem._tick()
                raise extra
            sc.initial = x
            terms.append((r, extra))
        problem._tick()
        return terms


def _regularizer(body: Any, params: Parameters, weight: float) -> sp.csr_matrix | None:
    """Rows ``sqrt(weight) (s_e - s_f)`` for every pair of face-adjacent elements of each
    field block: Tikhonov smoothing of log mu (or log lambda) across faces."""
    if not weight:
        return None
    rows, cols, vals = [], [], []
    row = 0
    tets = body.mesh.tets
    for b in params.blocks:
        if not b.is_field:
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


def fitted_material(body: Any, st: State) -> Material:
    """The material of ``body``'s class with the core's values of ``st`` (scalars where uniform)."""

    def compact(a: NDArray[np.float64]) -> Any:
        return float(a[0]) if np.all(a == a[0]) else a

    values = {name: compact(st.material[name]) for name in body.material.model.core_form.names}
    return body.material.with_values(values, compact(st.material["density"]))


def final_results(body: Any, material: Material, st: State, scs: list[Scenario], p: Parameters) -> list[StaticResult]:
    """One StaticResult per scenario at the fitted parameters (warm-started, cheap): solved by a
    copy of ``body`` with ``material`` and the fitted cable values, which shares its model."""
    fitted = body.replace(material=material)
    controlled = [c for b in p.blocks if b.kind in COMMAND_PARAMETERS for c in b.cables]
    results = []
    for sc in scs:
        alpha = st.actuation.copy()
        if sc.actuation is not None:
            alpha = np.where(np.isin(np.arange(len(alpha)), controlled), alpha, sc.actuation)
        for c, (kind, _) in enumerate(body.commands):
            if kind == "actuation":
                fitted.set_actuation(c, float(alpha[c]))
                fitted.set_cable_stiffness(c, float(st.stiffness[c]))
            elif kind == "pull":
                fitted.pull(c, displacement=float(alpha[c]))
            else:
                fitted.pull(c, tension=float(alpha[c]))
        g = sc.gravity if st.gravity is None else st.gravity
        # The last warm start may be a rejected trial's equilibrium, far from this one: fall back
        # as the evaluations do (from rest, then in more load steps).
        attempts = [(sc.initial, sc.solve), (None, sc.solve), (None, sc.solve.replace(load_steps=4 * sc.solve.load_steps))]
        for k, (initial, options) in enumerate(attempts):
            try:
                results.append(solve_static(fitted, g, options=options, initial=initial))
                break
            except SolverError:
                if k == len(attempts) - 1:
                    raise
    return results
