"""Material models: each model's parameter names, units, valid ranges and conversions, declared once.

A :class:`MaterialModel` lists the parameters a user may give (:class:`Parameter`: name,
symbol, units, valid :class:`Range`, the :class:`Transform` the inverse problems optimise it
in) and the :class:`Form` s in which they may be given: the first form is the core's own
parameters (what the extension's ``Model.set_material_model`` takes, under the model's
``core_name``), every other form comes with its conversion to the core's parameters and that
conversion's Jacobian (for the chain rule of :func:`sorofem.estimate`). Everything that reads or
writes material parameters reads this declaration: :class:`Material` (the validation and
conversions behind every material class), :class:`sorofem.Body` (formulation-specific ranges),
:mod:`sorofem.inverse` (parameter names and transforms, ``PARAMETERS``), the ``[material]``
table of scene files and the command line.

The models, by their scene name (:data:`MODELS`): ``"neo-hookean"`` (:class:`NeoHookean`, the
default), ``"mooney-rivlin"`` (:class:`MooneyRivlin`), ``"yeoh"`` (:class:`Yeoh`) and
``"ogden"`` (:class:`Ogden`); see :mod:`sorofem.materials.decoupled` for the energies.
:data:`library` holds published silicones, ready to use.

Density is common to every model (:data:`DENSITY`). Adding a model on the Python side is one
declaration and a short :class:`Material` subclass naming its keyword arguments (as
:mod:`sorofem.materials.decoupled` does for Mooney-Rivlin)::

    MOONEY_RIVLIN = MaterialModel("mooney-rivlin", "decoupled Mooney-Rivlin", "W = c10 (I1b - 3) + ...",
                                  parameters=(C10, C01, D1), forms=(Form(("c10", "c01", "d1")),),
                                  core_name="mooney_rivlin")

    class MooneyRivlin(Material, model=MOONEY_RIVLIN):
        def __init__(self, c10, c01, d1, *, density=0.0):
            super().__init__({"c10": c10, "c01": c01, "d1": d1}, density)

and one entry in :data:`MODELS` (the scene's ``[material] model``).

Examples
--------
>>> import sorofem as sf
>>> from sorofem.materials import NEO_HOOKEAN
>>> [p.name for p in NEO_HOOKEAN.parameters]
['shear_modulus', 'lame_lambda', 'youngs_modulus', 'poisson_ratio']
>>> NEO_HOOKEAN.parameter("poisson_ratio").range.describe()
'>= 0 and < 0.5'
>>> sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45).to_core()[0]  # mu, Pa
22758.620689655174
>>> ecoflex = sf.materials.library["ecoflex-00-30"]
>>> type(ecoflex).__name__, ecoflex.terms, ecoflex.density
('Ogden', 3, 1070.0)
"""

from __future__ import annotations

from types import MappingProxyType
from typing import Any, Mapping

from ..errors import ParameterError
from ..material_library import LibraryEntry
from ..material_library import library as _entries
from ._declarations import (
    CLASSES,
    DENSITY,
    IDENTITY,
    LOG,
    Form,
    Material,
    MaterialModel,
    Parameter,
    Range,
    Transform,
    keywords,
    logit,
)
from .decoupled import MOONEY_RIVLIN, OGDEN, OGDEN_TERMS, YEOH, MooneyRivlin, Ogden, Yeoh
from .neo_hookean import NEO_HOOKEAN, NeoHookean, lame_from_young, young_from_lame

__all__ = [
    "Range",
    "Transform",
    "LOG",
    "IDENTITY",
    "logit",
    "Parameter",
    "Form",
    "MaterialModel",
    "Material",
    "NeoHookean",
    "MooneyRivlin",
    "Yeoh",
    "Ogden",
    "DENSITY",
    "NEO_HOOKEAN",
    "MOONEY_RIVLIN",
    "YEOH",
    "OGDEN",
    "OGDEN_TERMS",
    "MODELS",
    "CLASSES",
    "library",
    "keywords",
    "model",
    "material_class",
    "lame_from_young",
    "young_from_lame",
]

#: Every model, by its scene name (Ogden: the 3-term declaration, which lists every name).
MODELS: dict[str, MaterialModel] = {m.name: m for m in (NEO_HOOKEAN, MOONEY_RIVLIN, YEOH, OGDEN)}


def model(name: str) -> MaterialModel:
    """The declaration of the model called ``name`` (a key of :data:`MODELS`).

    Raises
    ------
    ParameterError
        No such model.
    """
    if not isinstance(name, str) or name not in MODELS:
        raise ParameterError(f"model: expected one of {list(MODELS)}, got {name!r}", "model")
    return MODELS[name]


def material_class(name: str) -> type[Material]:
    """The class of the model called ``name`` (:class:`NeoHookean` for ``"neo-hookean"``).

    Raises
    ------
    ParameterError
        No such model.
    """
    if not isinstance(name, str) or name not in CLASSES:
        raise ParameterError(f"model: expected one of {list(CLASSES)}, got {name!r}", "model")
    return CLASSES[name]


def _library_material(entry: LibraryEntry) -> Material:
    """The material of a :mod:`sorofem.material_library` entry (its ``ready_params``: an
    incompressible source's ``d1`` is assumed), with the entry as its source."""
    spec = next(m for m in MODELS.values() if m.core_name == entry.model)
    values: dict[str, Any] = {}
    for name, value in entry.ready_params.items():
        base, vector, _ = name.partition(":")
        if vector:
            values.setdefault(base, []).append(value)
        else:
            values[name] = value
    return CLASSES[spec.name](**values, density=entry.density).with_source(entry.to_dict())


#: Published silicones, ready to use: name -> material (its ``source`` holds the citation, where
#: in the source the values are, the source's own words, the test mode and strain range when
#: stated, the density's source, and whether ``d1`` was assumed for a source that gives the
#: material as incompressible; ``summary.json`` carries it). The entries are listed in
#: :mod:`sorofem.material_library`.
library: Mapping[str, Material] = MappingProxyType({name: _library_material(e) for name, e in _entries.items()})
