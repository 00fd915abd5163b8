"""sorofem.material_library: every entry is a valid, cited, physically plausible material."""

from __future__ import annotations

import doctest
import json

import numpy as np
import pytest

from sorofem import material_library
from sorofem.fitting import model_spec, nominal_stress, stable_range
from sorofem.material_library import library

NAMES = sorted(library)


def test_library_is_not_empty_and_read_only() -> None:
    assert "ecoflex-00-30" in library
    with pytest.raises(TypeError):
        library["x"] = library["ecoflex-00-30"]  # type: ignore[index]


@pytest.mark.parametrize("name", NAMES)
def test_entry_params_are_valid_for_its_model(name: str) -> None:
    entry = library[name]
    assert entry.name == name
    spec = model_spec(entry.model, entry.terms if entry.model in ("yeoh", "ogden") else None)
    assert set(entry.params) <= set(spec.param_names), set(entry.params) - set(spec.param_names)
    assert all(np.isfinite(v) for v in entry.params.values())
    assert all(entry.params[k] != 0 for k in entry.params if k.startswith("alpha"))
    assert all(entry.params[k] >= 0 for k in entry.params if k.startswith("d"))
    assert entry.shear_modulus > 0
    assert 900 <= entry.density <= 1600, entry.density  # silicones: about 1.0-1.5 g/cc


@pytest.mark.parametrize("name", NAMES)
def test_entry_is_cited(name: str) -> None:
    entry = library[name]
    for source in (entry.source, entry.density_source):
        assert source.location and source.url.startswith("http") and source.quote
    # The quoted text holds the numbers the entry was converted from.
    coefficients = [v for k, v in entry.params.items() if not k.startswith("d")]
    assert sum(f"{abs(v) / 1e6:g}" in entry.source.quote or f"{abs(v):g}" in entry.source.quote
               for v in coefficients) == len(coefficients)
    assert f"{entry.density / 1000:g}" in entry.density_source.quote
    assert json.loads(json.dumps(entry.to_dict(), allow_nan=False))["source"]["quote"] == entry.source.quote


@pytest.mark.parametrize("name", NAMES)
def test_entry_is_plausible_against_its_stated_values(name: str) -> None:
    """Within a factor of 2 of a stress the sources state (batch, rate and Mullins effects
    alone move silicone data by tens of percent)."""
    entry = library[name]
    for stated in entry.stated:
        model = nominal_stress(entry.model, stated.mode, [stated.stretch], entry.incompressible_params,
                               terms=entry.terms)[0]
        assert 0.5 < model / stated.value < 2.0, (stated.what, model, stated.value)


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("mode", ["uniaxial", "equibiaxial", "planar"])
def test_entry_curves_are_positive_and_stable_over_their_range(name: str, mode: str) -> None:
    entry = library[name]
    lo, hi = (1 + entry.source.strain_range[0], 1 + entry.source.strain_range[1]) if entry.source.strain_range \
        else entry.checked_stretch
    stretch = np.linspace(max(lo, 1.0) + 1e-3, hi, 50)
    for bulk in (None, entry.bulk_modulus):
        params = entry.incompressible_params if bulk is None else dict(entry.params)
        stress = nominal_stress(entry.model, mode, stretch, params, terms=entry.terms)
        assert np.all(stress > 0) and np.all(np.diff(stretch * stress) > 0)
        if lo < 1.0:
            compression = nominal_stress(entry.model, mode, np.linspace(lo, 1.0 - 1e-3, 20), params, terms=entry.terms)
            assert np.all(compression < 0)
    rng = stable_range(entry.model, mode, entry.incompressible_params, terms=entry.terms)
    assert rng is not None and rng.lower <= lo and rng.upper >= hi


def test_docstring_examples_run() -> None:
    result = doctest.testmod(material_library)
    assert result.failed == 0 and result.attempted > 0
