"""Regressions of the defects found while restructuring the package (issue 14), one test each,
named after the defect, plus the deprecation aliases of the names that moved."""

from __future__ import annotations

import importlib
import sys
import warnings

import numpy as np
import pytest
from fdcheck import check_jacobian

import sorofem as sf

G = (0.0, 0.0, -9.81)


def _beam(material: sf.NeoHookean | None = None, formulation: str = "standard") -> sf.Body:
    mesh = sf.Mesh.box(size=(0.4, 0.1, 0.1), cells=(4, 2, 2))
    body = sf.Body(mesh, material or sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080), formulation)
    body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    return body


def test_changing_the_formulation_after_a_solve_rebuilds_the_model():
    """`body.formulation = "mixed"` after a solve used to keep solving the standard formulation
    (the model was rebuilt only when the supports or cables changed) while `to_dict()` said mixed."""
    body = _beam()
    standard = sf.solve_static(body, G)
    assert standard.pressure is None
    body.formulation = "mixed"
    mixed = sf.solve_static(body, G, initial=standard)
    assert mixed.pressure is not None and mixed.pressure.shape == (body.mesh.n_nodes,)
    assert mixed.to_dict()["formulation"] == "mixed" and standard.to_dict()["formulation"] == "standard"
    fresh = sf.solve_static(_beam(formulation="mixed"), G)
    np.testing.assert_allclose(mixed.positions, fresh.positions, atol=1e-9)
    body.volumetric = "linear"
    assert sf.solve_static(body, G).to_dict()["formulation_options"] == {"volumetric": "linear",
                                                                        "pressure_mass": "consistent"}


def test_changing_the_formulation_checks_lambda_again():
    """... and skipped the lambda > 0 check the constructor does for the mixed formulation."""
    body = _beam(sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.0))
    with pytest.raises(sf.ParameterError, match="lame_lambda > 0") as info:
        body.formulation = "mixed"
    assert info.value.parameter == "poisson_ratio" and body.formulation == "standard"
    with pytest.raises(sf.InputError, match="formulation"):
        body.formulation = "hybrid"
    mixed = _beam(formulation="mixed")
    with pytest.raises(sf.ParameterError, match="lame_lambda > 0"):
        mixed.material = sf.NeoHookean(shear_modulus=2e4, lame_lambda=0.0)
    assert body.replace(formulation="standard").formulation == "standard"
    with pytest.raises(sf.ParameterError):
        body.replace(formulation="mixed")


def test_reading_J_after_another_material_was_solved_keeps_the_sensitivity_state():
    """`result.J` used to call `set_material` on the shared core model, discarding the
    sensitivities of the solve made since with another material."""
    body = _beam()
    softer = body.replace(material=sf.NeoHookean(youngs_modulus=33e3, poisson_ratio=0.45, density=1080))
    first = sf.solve_static(body, G)
    second = sf.solve_static(softer, G)
    model = softer.core_model()
    before = model.adjoint(np.ones((body.mesh.n_nodes, 3)))
    j, von_mises = first.J, first.von_mises  # the other material's result
    after = model.adjoint(np.ones((body.mesh.n_nodes, 3)))  # raised ParameterError before the fix
    np.testing.assert_array_equal(before["mu"], after["mu"])
    # Each result's fields are its own material's, not the model's at the time they are read.
    np.testing.assert_allclose(j, sf.solve_static(_beam(), G).J, rtol=1e-12)
    assert not np.allclose(von_mises, second.von_mises)


def test_merit_history_says_what_it_is():
    """`energy_history` was documented as the total potential energy (J), but the mixed
    formulation's line search decreases half the squared residual (N^2)."""
    standard = sf.solve_static(_beam(), G).report
    mixed = sf.solve_static(_beam(formulation="mixed"), G).report
    assert standard.merit == "energy" and mixed.merit == "residual"
    assert standard.merit_history[-1] < standard.merit_history[0]  # the potential energy goes down
    assert all(m >= 0 for m in mixed.merit_history) and mixed.merit_history[-1] < 1e-12 * mixed.merit_history[0]
    assert standard.to_dict()["merit"] == "energy" and "energy_history" not in standard.to_dict()
    with pytest.warns(DeprecationWarning, match="merit_history"):
        assert standard.energy_history == standard.merit_history


@pytest.mark.parametrize(
    "module, name, replacement",
    [
        ("sorofem.cables", "actuate", lambda: sf.actuate),
        ("sorofem.viewer", "COLOUR_FIELDS", lambda: sf.plot.COLOR_FIELDS),
        ("sorofem.dynamics", "has_dynamics", None),
    ],
)
def test_moved_names_answer_from_their_old_place_with_a_warning(module, name, replacement):
    if module == "sorofem.viewer":
        pytest.importorskip("numpy")  # the viewer package itself imports without viser
    mod = importlib.import_module(module)
    with pytest.warns(DeprecationWarning, match=name):
        value = getattr(mod, name)
    if replacement is None:
        assert value() is True
    else:
        assert value is replacement()
    with pytest.raises(AttributeError):
        getattr(mod, "no_such_name")


def test_sorofem_model_is_a_deprecated_module():
    sys.modules.pop("sorofem.model", None)
    with pytest.warns(DeprecationWarning, match="sorofem.model is deprecated"):
        model = importlib.import_module("sorofem.model")
    assert model.Body is sf.Body and model.solve_static is sf.solve_static and model.NeoHookean is sf.NeoHookean
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert sf.model is model  # already imported: no second warning


def test_one_conversion_of_youngs_modulus_and_poisson_ratio():
    """E, nu <-> mu, lambda is written once (sorofem.materials): the material, the inverse
    problems' chain rule and the scene all use it."""
    from sorofem.materials import NEO_HOOKEAN, lame_from_young, young_from_lame

    form = NEO_HOOKEAN.forms[1]
    assert form.to_core is lame_from_young and form.from_core is young_from_lame
    E, nu = 66e3, 0.45
    mu, lam = lame_from_young(E, nu)
    assert (float(mu), float(lam)) == (sf.NeoHookean(youngs_modulus=E, poisson_ratio=nu).shear_modulus,
                                       sf.NeoHookean(youngs_modulus=E, poisson_ratio=nu).lame_lambda)
    jacobian = np.array(form.jacobian(E, nu)).T  # d(mu, lambda) / d(E, nu)
    fd = check_jacobian(lambda x: np.array(lame_from_young(*x), dtype=float), np.array([E, nu]), jacobian,
                        step=1e-6, rtol=1e-6)
    assert fd.passed, str(fd)


def test_inverse_docstring_lists_every_parameter_name():
    """The table of sorofem.inverse's docstring is written by hand: it must name every parameter
    the declaration gives (sorofem.inverse.PARAMETERS)."""
    doc = sf.inverse.__doc__ or ""
    missing = [name for name in sf.inverse.PARAMETERS if f"``{name}``" not in doc]
    assert not missing, f"sorofem.inverse's docstring table lacks {missing}"
