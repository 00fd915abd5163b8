"""Published hyperelastic parameters of silicones used in soft robots, each with its source.

Only values found in a source that can be named precisely are listed; every entry carries
the source's own words (``source.quote``), where in the source they are (``source.location``),
the test mode and strain range when the source states them, and the density with its source.
Parameters are converted to SI (Pa for ``c``/``mu``, 1/Pa for ``d``; the sources give MPa, so
the conversion is an exact factor 1e6) under the names of :mod:`sorofem.fitting.models`.

A source that gives the material as incompressible (no ``d1``) is listed so: ``params`` has no
``d1`` and ``bulk_modulus`` is ``None``. The ready material of :data:`sorofem.materials.library`
then needs a compressibility the source does not give; it uses ``ready_params``, which add
``d1`` for Poisson's ratio :data:`ASSUMED_POISSON_RATIO` at the small-strain shear modulus,
and says so (``d1_assumed`` in ``to_dict()``). For closer incompressibility give a smaller
``d1`` with ``formulation="mixed"``.

Entries
-------
``ecoflex-00-30``
    Smooth-On Ecoflex 00-30, 3-term Ogden ``mu = (1887, 22250, 3574) Pa``,
    ``alpha = (-3.848, 0.663, 4.225)``, ``d1 = 2.93e-6 1/Pa`` (K = 0.68 MPa); small-strain shear
    modulus 27.7 kPa. Source: the Soft Robotics Toolkit's *Modeling and Design Tool for Soft
    Pneumatic Actuators*, Demo 1 (the coefficients of its Abaqus material file, in MPa: the
    tool's models are in mm, N and MPa). Density 1070 kg/m^3 (Smooth-On Ecoflex technical
    bulletin: specific gravity 1.07 g/cc).
``elastosil-m4601``
    Wacker Elastosil M4601, 2-term Yeoh ``c10 = 110000 Pa``, ``c20 = 20000 Pa``, incompressible
    in the source (small-strain shear modulus 0.22 MPa). Source: the Soft Robotics Toolkit's
    PneuNets *Modeling* tutorial (Abaqus), "Overview of model components", which gives the
    density too: 1130 kg/m^3.
``elastosil-m4601-neo-hookean``
    Wacker Elastosil M4601, neo-Hookean ``C10 = 0.12 MPa`` (Abaqus's ``C10 (I1b - 3)``: a 1-term
    Yeoh, ``c10 = 120000 Pa``), incompressible in the source (shear modulus 0.24 MPa). Source:
    the Soft Robotics Toolkit's fiber-reinforced actuator *Finite Element Modeling* tutorial,
    "Overview of model components"; density from the PneuNets tutorial (1130 kg/m^3).

What the literature search did not yield (so no entry): coefficients for Ecoflex 00-10, 00-20
and 00-50, Dragon Skin 10/20/30, Sylgard 184 and Smooth-Sil in a text that could be quoted, and
a second Ecoflex 00-30 fit. Found but not readable beyond their first page: Marechal et al.,
*Soft Robotics* 8(3), 2021 (Table III, Yeoh/Ogden/Mooney-Rivlin/Neo-Hookean fits of 17
elastomers; raw data Zenodo 10.5281/zenodo.3611329); Xavier, Fleming and Yong, *Adv. Intell.
Syst.*, 2021 (its table of silicone coefficients); Polygerinos et al., *IEEE T-RO* 31(3), 2015;
Tawk and Alici, *Robotics*, 2020; Steck et al., *J. Appl. Polym. Sci.* 135, 47025, 2018; Di Lecce
et al., *Front. Robot. AI* 8, 2022.
Values met only in secondary text (a project page or note quoting a fit without its source
text) were not used.

Examples
--------
>>> from sorofem.material_library import library
>>> entry = library["ecoflex-00-30"]
>>> entry.model, entry.terms, round(entry.shear_modulus)
('ogden', 3, 27711)
>>> from sorofem.fitting import nominal_stress
>>> round(float(nominal_stress(entry.model, "uniaxial", [2.0], entry.incompressible_params)[0]))
43917
>>> elastosil = library["elastosil-m4601"]
>>> elastosil.bulk_modulus is None, round(2 / elastosil.ready_params["d1"] / elastosil.shear_modulus, 1)
(True, 49.7)
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Mapping

__all__ = ["ASSUMED_POISSON_RATIO", "LibraryEntry", "Source", "StatedValue", "library"]

#: Poisson's ratio at small strain that fixes ``d1`` of the ready material when the source gives the
#: material as incompressible: nearly incompressible like silicone, yet usable with the standard
#: (displacement) formulation on linear tetrahedra.
ASSUMED_POISSON_RATIO = 0.49


@dataclass(frozen=True)
class Source:
    """Where a value comes from.

    ``location`` says where in the source (table, section, line); ``quote`` is the source's
    own text holding the numbers; ``test_mode`` and ``strain_range`` (engineering strain,
    ``(min, max)``) are ``None`` when the source does not state them.
    """

    authors: str | None
    year: int | None
    title: str
    publisher: str
    location: str
    url: str
    quote: str
    test_mode: str | None = None
    strain_range: tuple[float, float] | None = None

    def citation(self) -> str:
        """``Authors (year). Title. Publisher. Location. URL`` (title first when no author is named)."""
        when = str(self.year) if self.year else "undated"
        head = f"{self.authors} ({when}). {self.title}" if self.authors else f"{self.title} ({when})"
        return f"{head}. {self.publisher}. {self.location}. {self.url}"


@dataclass(frozen=True)
class StatedValue:
    """A stress a source states for the material: ``value`` (Pa) at ``stretch`` in ``mode``."""

    what: str
    value: float
    mode: str
    stretch: float
    source: Source


@dataclass(frozen=True)
class LibraryEntry:
    """One material: ``model``/``terms`` and ``params`` as :func:`sorofem.fitting.nominal_stress`
    takes them (SI; no ``d1`` when the source gives the material as incompressible), ``density``
    in kg/m^3, and the sources of both."""

    name: str
    product: str
    model: str
    terms: int | None
    params: Mapping[str, float]
    density: float
    source: Source
    density_source: Source
    stated: tuple[StatedValue, ...] = ()
    notes: str = ""
    checked_stretch: tuple[float, float] = field(default=(0.5, 3.0))

    @property
    def shear_modulus(self) -> float:
        """Small-strain shear modulus (Pa): ``2 (c10 + c01)``, ``2 c10``, ``sum mu_p`` or ``mu``."""
        p = self.params
        if self.model == "ogden":
            return sum(v for k, v in p.items() if k.startswith("mu:"))
        if self.model == "mooney_rivlin":
            return 2.0 * (p["c10"] + p.get("c01", 0.0))
        if self.model == "yeoh":
            return 2.0 * p["c10"]
        return p["mu"]

    @property
    def bulk_modulus(self) -> float | None:
        """``2 / d1`` (Pa), ``None`` when the source gives the material as incompressible."""
        d1 = self.params.get("d1", 0.0)
        return 2.0 / d1 if d1 > 0 else None

    @property
    def incompressible_params(self) -> dict[str, float]:
        """The coefficients without the volumetric compliances (``d_i = 0``)."""
        return {k: v for k, v in self.params.items() if not k.startswith("d")}

    @property
    def d1_assumed(self) -> bool:
        """``True`` when the source gives the material as incompressible, so that ``ready_params``
        carry a ``d1`` of :data:`ASSUMED_POISSON_RATIO` rather than the source's."""
        return self.params.get("d1", 0.0) <= 0

    @property
    def ready_params(self) -> dict[str, float]:
        """``params`` with a ``d1`` for the FE materials: the source's, or, for an incompressible
        source, ``d1 = 2 / K`` with ``K = 2 mu (1 + nu) / (3 (1 - 2 nu))`` (1/Pa) at the small-strain
        shear modulus ``mu`` and ``nu =`` :data:`ASSUMED_POISSON_RATIO`."""
        if not self.d1_assumed:
            return dict(self.params)
        nu = ASSUMED_POISSON_RATIO
        bulk = 2.0 * self.shear_modulus * (1.0 + nu) / (3.0 * (1.0 - 2.0 * nu))
        return {**self.params, "d1": 2.0 / bulk}

    def to_dict(self) -> dict[str, Any]:
        """Plain data for ``summary.json``: model, parameters, density and the full citations."""

        def source(s: Source) -> dict[str, Any]:
            return {"citation": s.citation(), "location": s.location, "url": s.url, "quote": s.quote,
                    "test_mode": s.test_mode, "strain_range": list(s.strain_range) if s.strain_range else None}

        return {"name": self.name, "product": self.product, "model": self.model, "terms": self.terms,
                "params": dict(self.params), "density": self.density, "shear_modulus": self.shear_modulus,
                "bulk_modulus": self.bulk_modulus, "ready_d1": self.ready_params["d1"],
                "d1_assumed": (f"not in the source (incompressible there): Poisson's ratio {ASSUMED_POISSON_RATIO} "
                               "at the small-strain shear modulus") if self.d1_assumed else None,
                "source": source(self.source), "density_source": source(self.density_source), "notes": self.notes}


_SMOOTH_ON_ECOFLEX = Source(
    authors="Smooth-On, Inc.",
    year=None,
    title="Ecoflex Series: Super-Soft, Addition Cure Silicone Rubbers (technical bulletin)",
    publisher="Smooth-On, Macungie PA",
    location="Technical overview table, column Ecoflex 00-30: Specific Gravity (ASTM D-1475) 1.07 g/cc; "
             "100% Modulus (ASTM D-412) 10 psi",
    url="https://www.smooth-on.com/products/ecoflex-00-30/",
    quote="Specific Gravity 1.07 g/cc; 100% Modulus 10 psi",
    test_mode="uniaxial",
)

_TOOLKIT_OGDEN = Source(
    authors=None,
    year=None,
    title="Modeling and Design Tool for Soft Pneumatic Actuators: Demo 1, Multi-Chamber Bending SPA",
    publisher="softroboticstoolkit.com",
    location="section '2. Material constitutive model' (values of the ogden3.mat material file the demo passes "
             "to create_geom.py; Abaqus units mm, N, MPa)",
    url="http://softroboticstoolkit.com/book/modeling-soft-pneumatic-actuators/modeling/demo-1",
    quote="A 3-term Ogden model is used for Ecoflex-30 in this example, with the following coefficients: "
          "mu1 = 0.001887; alpha 1 = -3.848; mu2 = 0.02225; alpha2 = 0.663; mu3= 0.003574; alpha 3 = 4.225; "
          "D1 = 2.93; D2 = 0; D3 = 0",
)

_TOOLKIT_PNEUNETS = Source(
    authors=None,
    year=None,
    title="Modeling (the PneuNet actuator's finite element analysis in Abaqus)",
    publisher="softroboticstoolkit.com",
    location="section 'Overview of model components', first material (the tutorial's Abaqus model of the PneuNet "
             "actuator; coefficients without a unit on the page, read as MPa)",
    url="http://softroboticstoolkit.com/book/export/html/165596",
    quote="Elastosil M4601 silicone rubber: Yeoh strain energy potential defined by the coefficients C10 = 0.11, "
          "C20 = 0.02. Density of 1130 Kg/m³, assumed isotropic",
)

_TOOLKIT_FIBER_REINFORCED = Source(
    authors=None,
    year=None,
    title="Finite Element Modeling (a fiber-reinforced actuator in Abaqus)",
    publisher="softroboticstoolkit.com",
    location="section 'Overview of model components', Materials, first item",
    url="http://softroboticstoolkit.com/book/fr-modeling",
    quote="Elastosil M4601 silicone rubber: neo-Hookean strain energy potential defined by the coefficient "
          "C10 = 0.12MPa.",
)

_INCOMPRESSIBLE_NOTE = (
    "The source gives no D1 (an incompressible material, the Abaqus default without D1); the ready material "
    "of sf.materials.library uses d1 for Poisson's ratio 0.49 (ready_params), which is not from the source. "
    "The source states no test mode or strain range. ")

library: Mapping[str, LibraryEntry] = MappingProxyType({
    "ecoflex-00-30": LibraryEntry(
        name="ecoflex-00-30",
        product="Smooth-On Ecoflex 00-30",
        model="ogden",
        terms=3,
        params={"mu:0": 0.001887e6, "alpha:0": -3.848, "mu:1": 0.02225e6, "alpha:1": 0.663,
                "mu:2": 0.003574e6, "alpha:2": 4.225, "d1": 2.93e-6},
        density=1070.0,
        source=_TOOLKIT_OGDEN,
        density_source=_SMOOTH_ON_ECOFLEX,
        stated=(StatedValue("100% modulus (nominal stress at 100 % strain)", 10 * 6894.757293168361, "uniaxial",
                            2.0, _SMOOTH_ON_ECOFLEX),),
        notes="MPa and 1/MPa on the source page, read as the Abaqus mm-N-MPa system of the tool's models. The "
              "source states no test mode or strain range; the fit's uniaxial nominal stress at 100 % strain "
              "(43.9 kPa incompressible) is 0.64 times the bulletin's 100% modulus (68.9 kPa). Drucker stable "
              "in uniaxial, equibiaxial and planar tests from stretch 0.1 to 10. The bulletin's numbers were checked "
              "against a quotation of it; the bulletin itself could not be opened when this entry was written.",
    ),
    "elastosil-m4601": LibraryEntry(
        name="elastosil-m4601",
        product="Wacker Elastosil M4601",
        model="yeoh",
        terms=2,
        params={"c10": 0.11e6, "c20": 0.02e6},
        density=1130.0,
        source=_TOOLKIT_PNEUNETS,
        density_source=_TOOLKIT_PNEUNETS,
        notes=_INCOMPRESSIBLE_NOTE + "The page gives C10 and C20 without a unit; they are read as MPa, the "
              "stress unit of the toolkit's Abaqus tutorials (the fiber-reinforced tutorial states C10 = 0.12MPa for "
              "the same silicone, see elastosil-m4601-neo-hookean; small-strain shear moduli 0.22 and 0.24 MPa). "
              "Drucker stable in uniaxial, equibiaxial and planar tests at every stretch (c10, c20 > 0).",
    ),
    "elastosil-m4601-neo-hookean": LibraryEntry(
        name="elastosil-m4601-neo-hookean",
        product="Wacker Elastosil M4601",
        model="yeoh",
        terms=1,
        params={"c10": 0.12e6},
        density=1130.0,
        source=_TOOLKIT_FIBER_REINFORCED,
        density_source=_TOOLKIT_PNEUNETS,
        notes=_INCOMPRESSIBLE_NOTE + "Abaqus's neo-Hookean potential C10 (I1b - 3) is the 1-term Yeoh model, so "
              "the entry is given as Yeoh with c10 alone (small-strain shear modulus 2 c10 = 0.24 MPa). The density "
              "is the PneuNets tutorial's, for the same silicone.",
    ),
})
