"""sorofem.material_library: every entry is a valid, cited, physically plausible material."""

from __future__ import annotations

import doctest
import json

import numpy as np
import pytest

import sorofem as sf
from sorofem import material_library
from sorofem.fitting import lateral_stretch, model_spec, nominal_stress, stable_range
from sorofem.material_library import ASSUMED_POISSON_RATIO, library

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
    assert f"{entry.density / 1000:g}" in entry.density_source.quote or f"{entry.density:g}" in entry.density_source.quote
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
    for params in (entry.incompressible_params, entry.ready_params):
        stress = nominal_stress(entry.model, mode, stretch, params, terms=entry.terms)
        assert np.all(stress > 0) and np.all(np.diff(stretch * stress) > 0)
        if lo < 1.0:
            compression = nominal_stress(entry.model, mode, np.linspace(lo, 1.0 - 1e-3, 20), params, terms=entry.terms)
            assert np.all(compression < 0)
    rng = stable_range(entry.model, mode, entry.incompressible_params, terms=entry.terms)
    assert rng is not None and rng.lower <= lo and rng.upper >= hi


@pytest.mark.parametrize("name", NAMES)
def test_ready_material_solves_a_body_on_the_entrys_uniaxial_curve(name: str) -> None:
    """The ready material in a Body: a unit cube whose boundary is prescribed to the isochoric
    uniaxial stretch F = diag(l, l^-1/2, l^-1/2) has, from its reactions' first moment (P V), the
    Cauchy stress difference s11 - s22 = l P_uniaxial(l) of the entry's incompressible curve
    (at J = 1 the volumetric term, assumed or not, adds no stress)."""
    entry, material = library[name], sf.materials.library[name]
    assert material.density == entry.density
    stretch = 1.6
    F = np.diag([stretch, stretch**-0.5, stretch**-0.5])
    mesh = sf.Mesh.box(size=[1.0, 1.0, 1.0], cells=[2, 2, 2])
    X = mesh.points
    boundary = np.flatnonzero(np.any((X < 1e-12) | (X > 1 - 1e-12), axis=1))
    body = sf.Body(mesh, material)
    body.fix(boundary, displacement=X[boundary] @ (F - np.eye(3)).T)
    result = sf.solve_static(body, load_steps=4)
    cauchy = (result.reactions.T @ X[body.fixed_nodes]) @ F.T
    expected = stretch * nominal_stress(entry.model, "uniaxial", [stretch], entry.incompressible_params,
                                        terms=entry.terms)[0]
    assert abs(cauchy[0, 0] - cauchy[1, 1] - expected) < 1e-6 * expected, (cauchy, expected)


@pytest.mark.parametrize("name", NAMES)
def test_assumed_compressibility_is_declared_and_gives_its_poisson_ratio(name: str) -> None:
    entry = library[name]
    record = entry.to_dict()
    assert (record["d1_assumed"] is not None) == ("d1" not in entry.params) == entry.d1_assumed
    assert record["ready_d1"] == entry.ready_params["d1"] > 0
    if entry.d1_assumed:
        # Lateral contraction of the ready (compressible) material at small uniaxial strain: t = l^-nu.
        t = lateral_stretch(entry.model, "uniaxial", [1.0001], entry.ready_params, terms=entry.terms)[0]
        assert abs(-np.log(t) / np.log(1.0001) - ASSUMED_POISSON_RATIO) < 1e-3


def test_the_two_elastosil_fits_agree_at_small_strain() -> None:
    """Two tutorials of the same toolkit, two models, one silicone: shear moduli within 10 %."""
    yeoh, neo = library["elastosil-m4601"], library["elastosil-m4601-neo-hookean"]
    assert yeoh.product == neo.product
    assert 0.9 < yeoh.shear_modulus / neo.shear_modulus < 1.1


def test_docstring_examples_run() -> None:
    result = doctest.testmod(material_library)
    assert result.failed == 0 and result.attempted > 0
