"""Published hyperelastic parameters of silicones used in soft robots, each with its source.

Only values found in a source that can be named precisely are listed; every entry carries
the source's own words (``source.quote``), where in the source they are (``source.location``),
the test mode and strain range when the source states them, and the density from the
manufacturer's technical bulletin. Parameters are converted to SI (Pa for ``c``/``mu``, 1/Pa
for ``d``) under the names of :mod:`sorofem.fitting.models`.

Entries
-------
``ecoflex-00-30``
    Smooth-On Ecoflex 00-30, 3-term Ogden ``mu = (1887, 22250, 3574) Pa``,
    ``alpha = (-3.848, 0.663, 4.225)``, ``d1 = 2.93e-6 1/Pa`` (K = 0.68 MPa); small-strain shear
    modulus 27.7 kPa. Source: the Soft Robotics Toolkit's *Modeling and Design Tool for Soft
    Pneumatic Actuators*, Demo 1 (the coefficients of its Abaqus material file, in MPa: the
    tool's models are in mm, N and MPa). Density 1070 kg/m^3 (Smooth-On Ecoflex technical
    bulletin: specific gravity 1.07 g/cc).

What the literature search did not yield (so no entry): coefficients for Ecoflex 00-10 and
00-50, Dragon Skin 10/20/30, Sylgard 184 and Elastosil M4601 in a text that could be quoted
(Marechal et al., *Soft Robotics* 8(3), 2021; Di Lecce et al., *Front. Robot. AI* 8, 2022;
Polygerinos et al., *IEEE T-RO* 31(3), 2015 were found, but not their tables).

Examples
--------
>>> from sorofem.material_library import library
>>> entry = library["ecoflex-00-30"]
>>> entry.model, entry.terms, round(entry.shear_modulus)
('ogden', 3, 27711)
>>> from sorofem.fitting import nominal_stress
>>> round(float(nominal_stress(entry.model, "uniaxial", [2.0], entry.incompressible_params)[0]))
43917
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Mapping

__all__ = ["LibraryEntry", "Source", "StatedValue", "library"]


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
    takes them (SI), ``density`` in kg/m^3, and the sources of both."""

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

    def to_dict(self) -> dict[str, Any]:
        """Plain data for ``summary.json``: model, parameters, density and the full citations."""

        def source(s: Source) -> dict[str, Any]:
            return {"citation": s.citation(), "location": s.location, "url": s.url, "quote": s.quote,
                    "test_mode": s.test_mode, "strain_range": list(s.strain_range) if s.strain_range else None}

        return {"name": self.name, "product": self.product, "model": self.model, "terms": self.terms,
                "params": dict(self.params), "density": self.density, "shear_modulus": self.shear_modulus,
                "bulk_modulus": self.bulk_modulus, "source": source(self.source),
                "density_source": source(self.density_source), "notes": self.notes}


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
})
