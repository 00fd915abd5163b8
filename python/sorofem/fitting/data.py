"""Test curves: stretch against nominal stress in one homogeneous test, from arrays or CSV files.

CSV convention
--------------
::

    # mode: uniaxial
    # stress_unit: kPa
    stretch,nominal_stress
    1.00,0.0
    1.10,8.1

* Lines starting with ``#`` are comments; a comment of the form ``# key: value`` sets the
  test ``mode`` (``uniaxial``, ``equibiaxial`` or ``planar``) or the ``stress_unit``. Other
  comments are ignored.
* The first other line is the header; fields are separated by commas (or semicolons or tabs,
  whichever the header uses). Two columns are read, in any position, other columns ignored:
  ``stretch`` (or ``strain``, engineering strain ``stretch - 1``, optionally ``strain [%]``) and
  ``nominal_stress`` (or ``engineering_stress``): force over *undeformed* area. A unit may
  follow the name in brackets: ``nominal_stress [kPa]``. Units: Pa, kPa, MPa, GPa, psi
  (and N/mm^2 = MPa).
* The stress unit comes from the column, the ``# stress_unit:`` line or the ``stress_unit``
  argument, in that order; two of them that disagree are an error; none means Pa.
* Stretch must be positive and strictly monotone (loading only, no unloading branch);
  every value finite. Tension (stretch > 1) must carry positive stress and compression
  negative stress: a file where most points have the opposite sign is rejected (compression
  data written as positive magnitudes).

What cannot be checked is a unit that is wrong but plausible (MPa values declared as Pa):
:class:`~sorofem.fitting.MaterialFit` warns when the fitted shear modulus lies outside what
any elastomer or gel has (10 Pa .. 1 GPa).
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError, ParameterError, ShapeError
from .curves import MODES

__all__ = ["Curve", "DataFileError", "STRESS_UNITS", "read_curve", "as_curves"]

Array = NDArray[np.float64]

#: Stress units a CSV column, ``# stress_unit:`` line or ``stress_unit`` argument may name, in Pa.
STRESS_UNITS = {"pa": 1.0, "kpa": 1e3, "mpa": 1e6, "gpa": 1e9, "psi": 6894.757293168361,
                "n/mm^2": 1e6, "n/mm2": 1e6}
_MODE_ALIASES = {"biaxial": "equibiaxial", "pure_shear": "planar", "pure-shear": "planar"}
_STRETCH_NAMES = ("stretch",)
_STRAIN_NAMES = ("strain", "engineering_strain", "nominal_strain")
_STRESS_NAMES = ("nominal_stress", "engineering_stress")
_COLUMN = re.compile(r"^\s*([A-Za-z_ \-]+?)\s*(?:[\[(]\s*([^\])]*?)\s*[\])])?\s*$")


class DataFileError(InputError):
    """A test-data file is malformed. ``str()`` reads ``path:line: message``.

    Attributes
    ----------
    path, line
        The file and the 1-based line (``None`` when the problem is the whole file).
    column
        The column concerned, if any.
    """

    def __init__(self, message: str, *, path: str | os.PathLike[str], line: int | None = None,
                 column: str | None = None) -> None:
        super().__init__(message)
        self.message = message
        self.path = path
        self.line = line
        self.column = column

    def __str__(self) -> str:
        where = str(self.path) + (f":{self.line}" if self.line is not None else "")
        col = f" column '{self.column}':" if self.column else ""
        return f"{where}:{col} {self.message}"


@dataclass(frozen=True)
class Curve:
    """One homogeneous test: ``mode``, stretch ``(n,)`` and nominal stress ``(n,)`` in Pa.

    ``source`` names where it came from (a file path or ``data[i]``) and ``lines`` the file
    line of each point (``None`` for arrays), so that a complaint can point at the data.
    """

    mode: str
    stretch: Array
    nominal_stress: Array
    source: str = "data"
    lines: tuple[int, ...] | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        mode = _normalize_mode(self.mode)
        if mode not in MODES:
            raise ParameterError(
                f"{self.source}: unknown test mode {self.mode!r}; expected one of {', '.join(MODES)}", "mode")
        object.__setattr__(self, "mode", mode)
        stretch = _float_vector(self.stretch, f"{self.source}.stretch")
        stress = _float_vector(self.nominal_stress, f"{self.source}.nominal_stress")
        if stretch.shape != stress.shape:
            raise ShapeError(f"{self.source}: stretch has {stretch.size} values but nominal_stress has {stress.size}")
        object.__setattr__(self, "stretch", stretch)
        object.__setattr__(self, "nominal_stress", stress)
        _validate(self)

    def where(self, index: int) -> str:
        """``source:line`` of point ``index`` (``source[index]`` for arrays)."""
        if self.lines is not None:
            return f"{self.source}:{self.lines[index]}"
        return f"{self.source}[{index}]"


def _normalize_mode(mode: Any) -> str:
    text = str(mode).strip().lower()
    return _MODE_ALIASES.get(text, text)


def _float_vector(values: Any, name: str) -> Array:
    try:
        array = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ShapeError(f"{name} must be a 1-D array of numbers: {exc}") from None
    if array.ndim != 1 or array.size < 2:
        raise ShapeError(f"{name} must be a 1-D array of at least 2 values, got shape {array.shape}")
    return array


def _fail(curve: Curve, index: int | None, message: str, column: str | None = None) -> None:
    if curve.lines is not None:
        raise DataFileError(message, path=curve.source, line=None if index is None else curve.lines[index],
                            column=column)
    where = curve.source if index is None else curve.where(index)
    raise ParameterError(f"{where}: {(column + ': ') if column else ''}{message}", column or "data")


def _validate(curve: Curve) -> None:
    for column, values in (("stretch", curve.stretch), ("nominal_stress", curve.nominal_stress)):
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            _fail(curve, int(bad[0]), f"value {values[bad[0]]} is not a finite number", column)
    bad = np.flatnonzero(curve.stretch <= 0)
    if bad.size:
        _fail(curve, int(bad[0]), f"stretch must be > 0, got {curve.stretch[bad[0]]:g}", "stretch")
    step = np.diff(curve.stretch)
    direction = np.sign(step[0])
    bad = np.flatnonzero(~(np.sign(step) == direction) | (step == 0))
    if direction == 0 or bad.size:
        k = 1 if direction == 0 else int(bad[0]) + 1
        _fail(curve, k, f"stretch must be strictly monotone (loading only): {curve.stretch[k - 1]:g} is followed "
                        f"by {curve.stretch[k]:g}", "stretch")
    strained = np.abs(curve.stretch - 1.0) > 1e-2
    wrong = strained & (np.sign(curve.nominal_stress) != np.sign(curve.stretch - 1.0))
    if strained.any() and wrong.sum() > 0.5 * strained.sum():
        k = int(np.flatnonzero(wrong)[0])
        _fail(curve, k, f"{wrong.sum()} of {strained.sum()} strained points have a nominal stress of the wrong "
                        f"sign (here {curve.nominal_stress[k]:g} at stretch {curve.stretch[k]:g}): tension "
                        "(stretch > 1) must be positive and compression negative", "nominal_stress")


def _parse_unit(text: str, where: str, path: Path, line: int) -> float:
    key = text.strip().lower().replace(" ", "")
    if key not in STRESS_UNITS:
        raise DataFileError(f"unknown stress unit {text!r} in {where}; expected one of Pa, kPa, MPa, GPa, psi",
                            path=path, line=line)
    return STRESS_UNITS[key]


def read_curve(path: str | os.PathLike[str], *, mode: str | None = None, stress_unit: str | None = None) -> Curve:
    """Read one test curve from a CSV file (see the module docstring for the format).

    Parameters
    ----------
    path
        The CSV file.
    mode
        The test mode of a file without a ``# mode:`` line (a file's own line wins).
    stress_unit
        The stress unit, for a file that names none (Pa when neither does).

    Raises
    ------
    DataFileError
        Naming the file, the line and the column: no header, a missing column, a field that
        is not a number, NaN, non-monotone stretch, wrong stress sign, no mode, conflicting
        units.

    Examples
    --------
    >>> from pathlib import Path
    >>> _ = Path("/tmp/ut.csv").write_text("# mode: uniaxial\\nstretch,nominal_stress [kPa]\\n1.0,0\\n1.5,20\\n2.0,35\\n")
    >>> curve = read_curve("/tmp/ut.csv")
    >>> curve.mode, curve.nominal_stress.tolist()
    ('uniaxial', [0.0, 20000.0, 35000.0])
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise DataFileError(f"not a UTF-8 text file ({exc.reason})", path=path) from None
    meta: dict[str, tuple[str, int]] = {}
    header: tuple[list[str], int, str] | None = None
    rows: list[tuple[list[str], int]] = []
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        if not line:
            continue
        if line.startswith("#"):
            match = re.match(r"#\s*([A-Za-z_]+)\s*:\s*(.*?)\s*$", line)
            if match and match.group(1).lower() in ("mode", "stress_unit"):
                meta[match.group(1).lower()] = (match.group(2), number)
            continue
        if header is None:
            sep = next((s for s in (",", ";", "\t") if s in line), None)
            header = (_split(line, sep), number, sep or "")
        else:
            rows.append((_split(line, header[2] or None), number))
    if header is None:
        raise DataFileError("no header line; expected columns 'stretch' and 'nominal_stress'", path=path)
    names, header_line, _ = header
    stretch_col, strain_scale, stress_col, column_unit = _columns(names, path, header_line)

    unit_scale = None
    if column_unit is not None:
        unit_scale = column_unit
    if "stress_unit" in meta:
        value, number = meta["stress_unit"]
        declared = _parse_unit(value, "'# stress_unit:'", path, number)
        if unit_scale is not None and declared != unit_scale:
            raise DataFileError(f"'# stress_unit: {value}' disagrees with the unit of column '{names[stress_col]}'",
                                path=path, line=number)
        unit_scale = declared
    if stress_unit is not None:
        given = _parse_unit(stress_unit, "the stress_unit argument", path, header_line)
        if unit_scale is not None and given != unit_scale:
            raise DataFileError(f"stress_unit={stress_unit!r} disagrees with the unit the file declares",
                                path=path, line=header_line)
        unit_scale = given
    unit_scale = 1.0 if unit_scale is None else unit_scale

    file_mode = None
    if "mode" in meta:
        value, number = meta["mode"]
        file_mode = _normalize_mode(value)
        if file_mode not in MODES:
            raise DataFileError(f"unknown test mode {value!r}; expected one of {', '.join(MODES)}",
                                path=path, line=number)
    chosen = file_mode or mode
    if chosen is None:
        raise DataFileError("test mode unknown: add a line '# mode: uniaxial' (or equibiaxial, planar) "
                            "or pass the mode (--mode)", path=path)

    if len(rows) < 2:
        raise DataFileError(f"needs at least 2 data lines, found {len(rows)}", path=path)
    values = np.empty((len(rows), 2))
    for k, (fields, number) in enumerate(rows):
        if len(fields) != len(names):
            raise DataFileError(f"{len(fields)} fields, but the header (line {header_line}) has {len(names)}",
                                path=path, line=number)
        for j, col in enumerate((stretch_col, stress_col)):
            try:
                values[k, j] = float(fields[col])
            except ValueError:
                raise DataFileError(f"{fields[col]!r} is not a number", path=path, line=number,
                                    column=names[col]) from None
    stretch = values[:, 0] if strain_scale is None else 1.0 + strain_scale * values[:, 0]
    return Curve(chosen, stretch, values[:, 1] * unit_scale, source=str(path), lines=tuple(n for _, n in rows))


def _split(line: str, sep: str | None) -> list[str]:
    return [f.strip() for f in (line.split(sep) if sep else line.split())]


def _columns(names: list[str], path: Path, line: int) -> tuple[int, float | None, int, float | None]:
    """Indices of the stretch (or strain) and stress columns, the strain scale (None for
    stretch) and the stress unit in Pa (None when the column names none)."""
    stretch_col = stress_col = None
    strain_scale: float | None = None
    unit: float | None = None
    for k, name in enumerate(names):
        match = _COLUMN.match(name)
        if not match:
            continue
        key = match.group(1).strip().lower().replace(" ", "_").replace("-", "_")
        bracket = match.group(2)
        if key in _STRETCH_NAMES or key in _STRAIN_NAMES:
            if stretch_col is not None:
                raise DataFileError(f"two stretch/strain columns ('{names[stretch_col]}' and '{name}')",
                                    path=path, line=line)
            stretch_col = k
            if key in _STRAIN_NAMES:
                if bracket in (None, "", "-", "1"):
                    strain_scale = 1.0
                elif bracket == "%":
                    strain_scale = 0.01
                else:
                    raise DataFileError(f"strain unit {bracket!r} unknown; use no unit or [%]", path=path, line=line,
                                        column=name)
            elif bracket not in (None, "", "-", "1"):
                raise DataFileError(f"stretch is dimensionless, got unit {bracket!r}", path=path, line=line,
                                    column=name)
        elif key in _STRESS_NAMES:
            if stress_col is not None:
                raise DataFileError(f"two stress columns ('{names[stress_col]}' and '{name}')", path=path, line=line)
            stress_col = k
            if bracket:
                unit = _parse_unit(bracket, f"column '{name}'", path, line)
    missing = [what for what, col in (("'stretch' (or 'strain')", stretch_col),
                                      ("'nominal_stress'", stress_col)) if col is None]
    if missing:
        try:
            [float(n) for n in names]
            hint = " (the first line holds numbers: the header line is missing)"
        except ValueError:
            hint = f"; found {', '.join(repr(n) for n in names)}"
        raise DataFileError(f"missing column {' and '.join(missing)}{hint}", path=path, line=line)
    assert stretch_col is not None and stress_col is not None
    return stretch_col, strain_scale, stress_col, unit


def as_curves(data: Any, *, mode: str | None = None, stress_unit: str | None = None) -> list[Curve]:
    """``data`` as a list of :class:`Curve`: a Curve, a CSV path, a mapping with ``mode``,
    ``stretch`` and ``nominal_stress`` (Pa), or a list/tuple of these. ``mode`` and
    ``stress_unit`` apply to CSV files that do not name theirs."""
    if isinstance(data, (Curve, str, os.PathLike, dict)):
        data = [data]
    if not isinstance(data, (list, tuple)) or not data:
        raise ParameterError("data must be a curve, a CSV path, a dict with 'mode', 'stretch' and "
                             f"'nominal_stress', or a non-empty list of these; got {type(data).__name__}", "data")
    curves = []
    for i, item in enumerate(data):
        if isinstance(item, Curve):
            curves.append(item)
        elif isinstance(item, (str, os.PathLike)):
            curves.append(read_curve(item, mode=mode, stress_unit=stress_unit))
        elif isinstance(item, dict):
            missing = [k for k in ("mode", "stretch", "nominal_stress") if k not in item]
            if missing:
                raise ParameterError(f"data[{i}] lacks {', '.join(missing)}", "data")
            unknown = sorted(set(item) - {"mode", "stretch", "nominal_stress"})
            if unknown:
                raise ParameterError(f"data[{i}] has unknown keys {unknown}; expected mode, stretch, nominal_stress "
                                     "(Pa)", "data")
            curves.append(Curve(item["mode"], item["stretch"], item["nominal_stress"], source=f"data[{i}]"))
        else:
            raise ParameterError(f"data[{i}] is a {type(item).__name__}; expected a Curve, a CSV path or a dict",
                                 "data")
    return curves
