"""Hypothesis strategies of hostile input shared by the property suite (tests/test_properties_*.py)
and the mesh-reader fuzz target (tests/fuzz_mesh_readers.py), and the checks every outcome must
pass: only sorofem's own errors, never NaN or Infinity in an output file.

Values are drawn from the edges that broke sorofem before (issue 20): integers beyond 32 and 64
bits, zero and negatives, subnormal, huge and non-finite floats, NUL bytes and overlong names,
wrong types and shapes. Sizes stay small where they are legal, so that no example runs long.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any, Callable

import numpy as np
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

import sorofem as sf

#: `make test` (CI too): the same examples on every run, no example database, no deadline
#: (timings belong to benchmarks); `make fuzz`: many random ones.
settings.register_profile(
    "ci", derandomize=True, database=None, deadline=None, print_blob=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture, HealthCheck.data_too_large],
)
settings.register_profile(
    "fuzz", deadline=None, max_examples=20_000, print_blob=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture, HealthCheck.data_too_large],
)
settings.load_profile(os.environ.get("SOROFEM_HYPOTHESIS_PROFILE", "ci"))

INTEGERS = st.sampled_from([-(2**63), -1, 0, 1, 2, 3, 7, 2**31 - 1, 2**31, 2**63 - 1, 2**63, 2**64, 10**40])
FLOATS = st.sampled_from([0.0, -0.0, 5e-324, 1e-320, 1e-105, 1e-9, 0.45, 0.5, 1.0, -1.0, 2.5, 1e5, 1e9, 1e150, 1e300,
                          -1e300, 1.7e308, math.inf, -math.inf, math.nan])
STRINGS = st.sampled_from(["", "\x00", "a\x00b", "x" * 300, "../nope/none.vtu", "none.vtu", "x.unknownext", "standard",
                           "mixed", "displacement", "least-squares", "shear_modulus", "é", "~"])
SCALARS = st.one_of(INTEGERS, FLOATS, STRINGS, st.booleans(), st.none())
#: A value of any kind: scalars, short vectors, nested and ragged lists, tables, arrays.
VALUES = st.recursive(
    SCALARS,
    lambda inner: st.one_of(st.lists(inner, max_size=4), st.dictionaries(STRINGS, inner, max_size=2)),
    max_leaves=6,
)
VECTORS = st.one_of(
    st.lists(FLOATS, min_size=3, max_size=3), st.lists(INTEGERS, min_size=3, max_size=3), VALUES,
    st.builds(lambda a: np.asarray(a), st.lists(FLOATS, min_size=0, max_size=4)),
)


def sorofem_errors(call: Callable[[], Any]) -> Any:
    """``call()``; an exception must be one of sorofem's (it names what is wrong). Returns the
    result, or None when sorofem refused the input."""
    try:
        return call()
    except sf.SorofemError as exc:
        assert str(exc), f"{type(exc).__name__} without a message"
        return None
    except FileNotFoundError as exc:  # a missing file is reported as such, naming it
        assert exc.args and str(exc)
        return None


def assert_clean_outputs(folder: Path) -> None:
    """No NaN or Infinity in any file a run wrote: JSON parses strictly, VTU arrays are finite."""
    import meshio

    if not folder.exists():
        return
    for path in folder.rglob("*"):
        if path.suffix == ".json":
            json.loads(path.read_text(), parse_constant=_refuse_constant)
        elif path.suffix == ".jsonl":
            for line in path.read_text().splitlines():
                json.loads(line, parse_constant=_refuse_constant)
        elif path.suffix == ".vtu":
            mesh = meshio.read(path)
            assert np.all(np.isfinite(mesh.points)), path
            for name, values in mesh.point_data.items():
                assert np.all(np.isfinite(values)), (path, name)
            for name, blocks in mesh.cell_data.items():
                for block in blocks:
                    assert np.all(np.isfinite(block)), (path, name)


def _refuse_constant(name: str) -> None:
    raise AssertionError(f"JSON output holds {name}")
