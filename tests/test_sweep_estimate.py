"""`sf.estimate(..., starts=N, client=...)`: the starts of a fit on a Dask cluster give the same
fit as one after the other, with a target on positions or on a contact force."""

from __future__ import annotations

import importlib
import json
import pickle

import numpy as np
import pytest

pytest.importorskip("distributed", reason='needs the cluster extra: pip install ".[cluster]"')

import sorofem as sf  # noqa: E402

G = (0.0, 0.0, -9.81)


def _body(mu: float = 1.0, lam: float = 1.0) -> sf.Body:
    mesh = sf.Mesh.box(size=(0.4, 0.1, 0.1), cells=(4, 1, 1))
    body = sf.Body(mesh, sf.NeoHookean(shear_modulus=mu, lame_lambda=lam, density=1080))
    body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    return body


def test_a_body_pickles_without_its_compiled_model():
    body = _body(22.76e3, 0.2048e6)
    before = sf.solve_static(body, G)
    copy = pickle.loads(pickle.dumps(body))
    after = sf.solve_static(copy, G)
    assert np.array_equal(before.positions, after.positions)



@pytest.mark.parametrize("client", ["tcp://127.0.0.1:8786", object()], ids=["an address", "an object"])
def test_a_client_that_is_not_one_is_named(client, tmp_path):
    """Not a Client (an address belongs in ``scheduler=`` of a sweep): a named error before any
    solve, not an AttributeError from deep inside."""
    target = sf.Target.nodes([0], np.zeros((1, 3)))
    with pytest.raises(sf.ParameterError, match="client: expected a dask.distributed.Client, got "):
        sf.estimate(_body(), target, params=["shear_modulus"], starts=2, client=client, gravity=G)
    scene = tmp_path / "beam.toml"
    scene.write_text('[mesh]\nbox = { size = [0.4, 0.1, 0.1], cells = [4, 1, 1] }\n[material]\n'
                     'youngs_modulus = 66e3\npoisson_ratio = 0.45\n[[fixed]]\nbox = { min = [-1e-9, -1, -1], '
                     'max = [1e-9, 1, 1] }\n', encoding="utf-8")
    with pytest.raises(sf.ParameterError, match="client: expected a dask.distributed.Client, got "):
        sf.sweep(scene, tmp_path / "out", grid={"material.youngs_modulus": [5e4]}, client=client)
    assert not (tmp_path / "out").exists()

def test_starts_on_a_cluster_give_the_same_fit(tmp_path):
    from dask.distributed import Client

    truth = sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080)
    goal = sf.solve_static(_body(truth.shear_modulus, truth.lame_lambda), G, tolerance=1e-12).positions
    target = sf.Target.nodes(np.arange(goal.shape[0]), goal)
    args = dict(params=["shear_modulus", "lame_lambda"], x0=[20e3, 0.2e6], bounds=[(10e3, 60e3), (0.1e6, 1e6)],
                starts=3, seed=1, gravity=G)
    here = sf.estimate(_body(), target, **args, history_path=tmp_path / "here.jsonl")
    with sf.sweeps.local_cluster(2) as cluster, Client(cluster, set_as_default=False) as client:
        there = sf.estimate(_body(), target, **args, client=client, history_path=tmp_path / "there.jsonl")
    assert there.params == here.params and there.loss == here.loss
    assert there.params["shear_modulus"] == pytest.approx(truth.shear_modulus, rel=1e-6)
    assert [s["params"] for s in there.starts] == [s["params"] for s in here.starts]
    assert there.forward_solves == here.forward_solves
    # The history file has every iteration of every start, in start order.
    records = [json.loads(line) for line in (tmp_path / "there.jsonl").read_text().splitlines()]
    assert records[0]["kind"] == "header" and [e["start"] for e in records if e.get("kind") == "end"] == [0, 1, 2, 3]
    lines = [e for e in records if e.get("kind", "iteration") == "iteration"]
    assert [(e["start"], e["iteration"], e["loss"]) for e in lines] == [
        (e["start"], e["iteration"], e["loss"]) for e in there.history]
    assert [e["start"] for e in lines] == sorted(e["start"] for e in lines) and {e["start"] for e in lines} == {0, 1, 2, 3}



def test_scenarios_of_one_start_on_a_cluster_give_the_same_fit():
    """One start, three load cases: each evaluation solves the scenarios on the workers side by
    side, each warm-started from the driver's last equilibrium of it, so the fit is the one of
    the loop here, bit for bit."""
    from dask.distributed import Client

    truth = sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080)
    scenarios = []
    for gravity in [(0, 0, -9.81), (0, -9.81, 0), (0, 0, 9.81)]:
        goal = sf.solve_static(_body(truth.shear_modulus, truth.lame_lambda), gravity, tolerance=1e-12).positions
        scenarios.append({"gravity": gravity, "target": sf.Target.nodes(np.arange(goal.shape[0]), goal)})
    args = dict(params=["shear_modulus", "lame_lambda"], x0=[20e3, 0.2e6], bounds=[(10e3, 60e3), (0.1e6, 1e6)],
                scenarios=scenarios)
    here = sf.estimate(_body(), None, **args)
    with sf.sweeps.local_cluster(2) as cluster, Client(cluster, set_as_default=False) as client:
        there = sf.estimate(_body(), None, **args, client=client)
        # Each worker built the problem once for the fit and keeps at most a couple.
        kept = client.run(lambda: len(importlib.import_module("sorofem.inverse._problem")._BUILT))
    assert there.params == here.params and there.loss == here.loss
    assert there.params["shear_modulus"] == pytest.approx(truth.shear_modulus, rel=1e-6)
    assert (there.forward_solves, there.newton_iterations) == (here.forward_solves, here.newton_iterations)
    assert np.array_equal(there.uncertainty.covariance, here.uncertainty.covariance)
    assert set(kept.values()) <= {0, 1} and sum(kept.values()) >= 1


def test_a_scenario_that_does_not_converge_on_a_worker_fails_the_fit_as_here():
    """A scenario allowed one Newton iteration fails every solve: the fit raises its error,
    the same with the scenarios on a cluster as in the loop here."""
    from dask.distributed import Client

    goal = sf.solve_static(_body(22.76e3, 0.2048e6), G).positions
    target = sf.Target.nodes(np.arange(goal.shape[0]), goal)
    args = dict(params=["shear_modulus"], x0=[20e3], scenarios=[{"gravity": G}, {"gravity": G, "max_iterations": 1}])
    with pytest.raises(sf.SolverError) as here:
        sf.estimate(_body(), target, **args)
    with sf.sweeps.local_cluster(2) as cluster, Client(cluster, set_as_default=False) as client:
        with pytest.raises(sf.SolverError) as there:
            sf.estimate(_body(), target, **args, client=client)
    assert type(there.value) is type(here.value) and str(there.value) == str(here.value)

def _finger(youngs_modulus: float) -> tuple[sf.Body, sf.Plane]:
    """A 100 x 20 x 20 mm finger clamped at x = 0, its tendon pulled 4 mm, pressing on a
    frictionless table 4 mm under its tip."""
    mesh = sf.Mesh.box(size=(0.1, 0.02, 0.02), cells=(10, 2, 2))
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=youngs_modulus, poisson_ratio=0.3))
    body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    x = np.linspace(0.0, 0.095, 10)
    tendon = body.add_cable(sf.Cable(np.c_[x, np.full_like(x, 0.01), np.full_like(x, 0.003)], model="tendon"))
    body.pull(tendon, displacement=0.004)
    table = sf.Plane((0.0, 0.0, -0.004), (0.0, 0.0, 1.0))
    body.add_obstacle(table)
    return body, table


def test_issue_17_a_body_with_contact_pickles_with_its_barrier_stiffness():
    """The barrier stiffness is fixed at the first solve from the material then: a copy solved
    with another material must keep the original's, or it is another problem."""
    body, _ = _finger(100e3)
    before = sf.solve_static(body, tolerance=1e-11)
    assert before.active_contacts > 0, "the finger should press on the table"
    copy = pickle.loads(pickle.dumps(body))
    copy.material = sf.NeoHookean(youngs_modulus=300e3, poisson_ratio=0.3)
    body.material = copy.material
    np.testing.assert_array_equal(sf.solve_static(copy, tolerance=1e-11).positions,
                                  sf.solve_static(body, tolerance=1e-11).positions)


def test_issue_17_a_bound_contact_force_target_pickles_and_binds_again():
    body, table = _finger(100e3)
    result = sf.solve_static(body, tolerance=1e-11)
    bound = sf.Target.contact_force(table, 0.05).bind(body.mesh, body=body)
    body_copy, bound_copy = pickle.loads(pickle.dumps((body, bound)))
    assert bound_copy.body is body_copy and bound_copy.model is body_copy.core_model()
    sf.solve_static(body_copy, tolerance=1e-11)
    assert bound_copy.residual(result.positions) == pytest.approx(bound.residual(result.positions), rel=1e-12)


def test_issue_17_a_contact_force_fit_on_a_cluster_is_the_fit_here():
    """The Young's modulus of the finger from the force it presses the table with: the starts on
    two workers end where they end one after the other (before the fix, each worker's body fixed
    its own barrier stiffness from its start's material, and a bound target did not pickle)."""
    from dask.distributed import Client

    force = float(np.linalg.norm(sf.solve_static(_finger(100e3)[0], tolerance=1e-11).obstacle_forces[0]))
    args = dict(params=["youngs_modulus"], x0=[70e3], bounds=[(30e3, 300e3)], starts=2, seed=3)
    body, table = _finger(70e3)
    here = sf.estimate(body, sf.Target.contact_force(table, force), **args)
    body, table = _finger(70e3)
    bound = sf.Target.contact_force(table, force).bind(body.mesh, body=body)
    with sf.sweeps.local_cluster(2) as cluster, Client(cluster, set_as_default=False) as client:
        there = sf.estimate(body, bound, **args, client=client)
    assert there.params == here.params and there.loss == here.loss
    assert [s["params"] for s in there.starts] == [s["params"] for s in here.starts]
    # The truth's own barrier stiffness came from its own material: close, not equal.
    assert there.params["youngs_modulus"] == pytest.approx(100e3, rel=1e-3)
    # Here, the first solve of the first start also fixed the barrier stiffness it shares.
    assert there.forward_solves == here.forward_solves + 1


def test_contact_force_scenarios_on_a_cluster_agree_with_the_fit_here_to_round_off():
    """Two scenarios of the finger pressing the table, solved side by side: a bound
    contact-force target travels in each scenario and the barrier stiffness fixed here with the
    body. Its tendon, pulled by a length, starts each solve from the tension of its model's last
    solve, another scenario's on a worker than here: the same fit to round-off, not bit for bit
    (obstacles alone give it bit for bit)."""
    from dask.distributed import Client

    force = float(np.linalg.norm(sf.solve_static(_finger(100e3)[0], tolerance=1e-11).obstacle_forces[0]))
    args = dict(params=["youngs_modulus"], x0=[70e3], bounds=[(30e3, 300e3)])
    fits = []
    for on_cluster in (False, True):
        body, table = _finger(70e3)
        target = sf.Target.contact_force(table, force).bind(body.mesh, body=body)
        scenarios = [{"target": target}, {"target": target, "gravity": (0, 0, -9.81)}]
        if not on_cluster:
            fits.append(sf.estimate(body, None, scenarios=scenarios, **args))
            continue
        with sf.sweeps.local_cluster(2) as cluster, Client(cluster, set_as_default=False) as client:
            fits.append(sf.estimate(body, None, scenarios=scenarios, **args, client=client))
    here, there = fits
    assert there.params["youngs_modulus"] == pytest.approx(here.params["youngs_modulus"], rel=1e-10)
    assert there.params["youngs_modulus"] == pytest.approx(100e3, rel=1e-3)
    assert there.iterations == here.iterations
    # The barrier stiffness fixed before the body went to the workers: one solve more.
    assert there.forward_solves == here.forward_solves + 1
