"""`sf.estimate(..., starts=N, client=...)`: the starts of a fit on a Dask cluster give the same
fit as one after the other."""

from __future__ import annotations

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
