"""The cases of a sweep: overrides of a scene by dotted key (``material.youngs_modulus``,
``cable[0].actuation``, ``loads.gravity``, ``mesh.file``), checked against the scene spec
(:data:`sorofem.scene.SCENE`) before anything is solved, from a grid (Cartesian product),
Latin-hypercube samples within bounds or a table of cases.

Examples
--------
>>> from sorofem.sweeps import Cases
>>> cases = Cases.build("scene.toml", grid={"material.youngs_modulus": [50e3, 66e3]},
...                     sample={"cable[0].actuation": (0.7, 1.0)}, samples=3)  # doctest: +SKIP
>>> cases.n, cases.keys                                                             # doctest: +SKIP
(6, ('material.youngs_modulus', 'cable[0].actuation'))
"""

from __future__ import annotations

import copy
import csv
import hashlib
import inspect
import itertools
import json
import math
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from .._validate import count
from ..errors import InputError, SceneError
from ..scene import PER_SOLVE_CABLE_KEYS, SCENE, Checker, Field, Number, Table, Tables

__all__ = ["Key", "Cases", "parse_key", "parse_values", "read_scene", "missing_extra"]

#: One level of a dotted key: a name (an Ogden coefficient's with its term, ``mu:0``), optionally
#: indexed (``cable[0]``).
_PART = re.compile(r"^([A-Za-z_][A-Za-z0-9_\-]*(?::\d+)?)(?:\[(\d+)\])?$")
#: Scene tables a sweep may not override: ``sorofem run`` does not read them.
NOT_SWEPT = ("output", "target", "estimate", "control")
#: Tables whose values a built model takes at every solve: cases differing only there share a model.
_PER_SOLVE_TABLES = ("material", "solver", "dynamics")


@dataclass(frozen=True)
class Key:
    """A dotted scene key and the spec of its value."""

    #: As written: ``cable[0].actuation``.
    text: str
    #: ``(name, index or None)`` per level.
    parts: tuple[tuple[str, int | None], ...]
    field: Field

    @property
    def per_solve(self) -> bool:
        """Whether a built model takes this value at each solve (else the key shapes the model:
        the mesh, the supports, the cables' geometry)."""
        top = self.parts[0][0]
        if top in _PER_SOLVE_TABLES:
            return self.text != "material.model"
        if self.text == "loads.gravity":
            return True
        return top == "cable" and len(self.parts) == 2 and self.parts[1][0] in PER_SOLVE_CABLE_KEYS

    def check(self, value: Any, scene: Path, where: str) -> Any:
        """The value checked and normalised by the spec (numbers as float), or an
        :class:`InputError` naming the key and ``where`` it came from."""
        try:
            return self.field.spec.check(Checker(scene, ""), value, self.text)
        except SceneError as exc:
            raise InputError(f"{self.text} ({where}): {exc.message}") from None

    def check_column(self, values: Sequence[Any], scene: Path, where: Callable[[int], str]) -> list[Any]:
        """Every value checked as :meth:`check` does (``where(i)`` names value ``i``). A column of
        plain numbers for a number key is checked at once; a column with a bad value, or of
        another kind, value by value, so that the error names the first bad one."""
        spec = self.field.spec
        if isinstance(spec, Number) and all(type(v) is float or type(v) is int for v in values):
            try:
                x = np.array(values, dtype=np.float64)
            except OverflowError:  # an integer beyond float64: checked alone below
                x = np.array([np.nan])
            if np.all(np.isfinite(x)) and np.all(spec.range.contains(x)):
                return x.tolist()
        return [self.check(v, scene, where(i)) for i, v in enumerate(values)]

    def apply(self, data: dict[str, Any], value: Any, where: str) -> dict[str, Any]:
        """A scene's tables (as :func:`tomllib.loads` returns them) with the value set: the
        tables and arrays on the key's path are copies, the rest is shared with ``data``."""
        out = dict(data)
        node: Any = out
        for depth, (name, index) in enumerate(self.parts):
            last = depth == len(self.parts) - 1
            if index is None:
                if last:
                    node[name] = copy.deepcopy(value)
                    break
                child = node.get(name, {})
                if not isinstance(child, dict):
                    raise InputError(f"{where}: {self.text}: '{self._header(depth)}' in the scene is not a table")
                node[name] = node = dict(child)
                continue
            entries = node.get(name, [])
            count = len(entries) if isinstance(entries, list) else 0
            if index >= count:
                raise InputError(
                    f"{where}: {self.text}: the scene has {count} [[{self._header(depth)}]] entr"
                    f"{'y' if count == 1 else 'ies'} (indices 0..{count - 1}), not {index}"
                    if count else f"{where}: {self.text}: the scene has no [[{self._header(depth)}]] entry"
                )
            node[name] = entries = list(entries)
            entries[index] = node = dict(entries[index])
        return out

    def _header(self, depth: int) -> str:
        return ".".join(name for name, _ in self.parts[: depth + 1])

    def column_type(self) -> str:
        """How the values are stored in the tables: ``float``, ``int``, ``bool``, ``str``,
        ``list`` (of floats) or ``json`` (anything else, as JSON text)."""
        schema = self.field.spec.schema()
        kind = schema.get("type")
        simple = {"number": "float", "boolean": "bool", "integer": "int", "string": "str"}
        if kind in simple:
            return simple[kind]
        if kind == "array" and schema.get("items", {}).get("type") == "number" and "prefixItems" not in schema:
            return "list"
        return "json"


def parse_key(text: str, where: str = "key") -> Key:
    """The :class:`Key` of a dotted scene key, or an :class:`InputError` saying what is wrong."""
    if not isinstance(text, str):
        raise InputError(f"{where}: expected a dotted scene key such as material.youngs_modulus (a string), "
                         f"got {type(text).__name__} {text!r}")
    text = text.strip()
    parts: list[tuple[str, int | None]] = []
    spec: Any = SCENE
    field: Field | None = None
    done = ""
    for token in text.split("."):
        match = _PART.match(token)
        if not match:
            raise InputError(
                f"{where}: {text!r} is not a dotted scene key such as material.youngs_modulus or cable[0].actuation"
            )
        name, index = match.group(1), None if match.group(2) is None else int(match.group(2))
        if not _is_table(spec):
            raise InputError(f"{where}: {text}: '{done}' is {spec.what()}, it has no key '{name}'")
        if name not in spec.fields:
            where_in = f"under '{done}'" if done else "at the top of a scene"
            raise InputError(f"{where}: {text}: unknown key '{name}' {where_in} (allowed: {', '.join(spec.fields)})")
        field = spec.fields[name]
        spec = field.spec
        done = f"{done}.{name}" if done else name
        if index is not None:
            if not _is_tables(spec):
                raise InputError(f"{where}: {text}: '{done}' is not an array of tables, so [{index}] selects nothing")
            spec = spec.table
            done += f"[{index}]"
        elif _is_tables(spec):
            raise InputError(f"{where}: {text}: '{done}' is an array of [[{done}]] entries: name one, e.g. {done}[0]")
        parts.append((name, index))
    assert field is not None
    if parts[0][0] in NOT_SWEPT:
        raise InputError(
            f"{where}: {text}: [{parts[0][0]}] is not swept: a case is what `sorofem run` computes, "
            f"which does not read it (sweep keys of {', '.join(k for k in SCENE.fields if k not in NOT_SWEPT)})"
        )
    if index is not None:
        raise InputError(f"{where}: {text}: a whole [[{parts[-1][0]}]] entry is not an override; name one of its keys")
    return Key(text, tuple(parts), Field(spec, field.doc, field.units) if index is not None else field)


def missing_extra(what: str, exc: ImportError) -> InputError:
    """The error for a missing optional package of the ``cluster`` extra."""
    return InputError(f"{what} needs the optional packages of the extra 'cluster' ({exc.name} is not installed): "
                      "pip install \".[cluster]\" in a sorofem checkout, or pip install \"dask[distributed]\" pyarrow zarr")


def _is_table(spec: Any) -> bool:
    return isinstance(spec, Table)


def _is_tables(spec: Any) -> bool:
    return isinstance(spec, Tables)


def parse_values(key: Key, text: str, where: str) -> list[Any]:
    """The values of ``--grid key=v1,v2,...``: numbers, ``true``/``false``, bare strings (for a
    string key) or TOML values such as ``[0, 0, -9.81]``."""
    text = text.strip()
    if not text:
        raise InputError(f"{where}: {key.text}: no values after '='")
    kind = key.column_type()
    if kind == "str":
        return [v.strip() for v in text.split(",")]
    if kind in ("float", "int", "bool"):
        return [_scalar(key, v.strip(), where) for v in text.split(",")]
    try:
        return list(tomllib.loads(f"v = [{text}]")["v"])
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{where}: {key.text}: could not read {text!r} as TOML values ({exc})") from None


def _scalar(key: Key, text: str, where: str) -> Any:
    kind = key.column_type()
    if kind == "bool":
        if text.lower() in ("true", "false"):
            return text.lower() == "true"
        raise InputError(f"{where}: {key.text}: expected true or false, got {text!r}")
    try:
        return int(text) if kind == "int" else float(text)
    except ValueError:
        noun = "an integer" if kind == "int" else "a number"
        raise InputError(f"{where}: {key.text}: expected {noun}, got {text!r}") from None


def read_scene(path: str | Path) -> tuple[Path, str, dict[str, Any]]:
    """``(path, text, tables)`` of a scene file."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"scene file not found: {path}")
    try:
        text = path.read_text(encoding="utf-8")
        return path, text, tomllib.loads(text)
    except UnicodeDecodeError as exc:
        raise SceneError(f"not a UTF-8 text file ({exc})", path=path) from None
    except tomllib.TOMLDecodeError as exc:
        match = re.search(r"line (\d+)", str(exc))
        raise SceneError(f"invalid TOML: {exc}", path=path, line=int(match.group(1)) if match else None) from None


def _latin_hypercube(d: int, n: int, seed: int) -> np.ndarray:
    """``(n, d)`` Latin-hypercube samples in [0, 1) (scipy.stats.qmc)."""
    from scipy.stats import qmc

    # SciPy 1.15 renamed the generator argument `seed` to `rng`.
    name = "rng" if "rng" in inspect.signature(qmc.LatinHypercube).parameters else "seed"
    return qmc.LatinHypercube(d, **{name: np.random.default_rng(seed)}).random(n)


@dataclass
class Cases:
    """The case table of a sweep: one column of checked values per key, case ``i`` being row ``i``."""

    scene: Path
    keys: tuple[Key, ...]
    #: ``values[j][i]``: the value of ``keys[j]`` in case ``i``.
    values: tuple[list[Any], ...]
    #: How the table was made (``grid``, ``sample``, ``samples``, ``seed``, ``table``), for the record.
    origin: dict[str, Any]

    @property
    def n(self) -> int:
        return len(self.values[0]) if self.values else 0

    def row(self, i: int) -> tuple[Any, ...]:
        return tuple(column[i] for column in self.values)

    def columns(self) -> dict[str, list[Any]]:
        return {k.text: list(v) for k, v in zip(self.keys, self.values)}

    def group(self, i: int) -> tuple[Any, ...]:
        """What case ``i`` shares a compiled model with other cases by: its values of the keys
        that shape the model (cases with equal groups differ only in per-solve values)."""
        return tuple(json.dumps(col[i], sort_keys=True) for k, col in zip(self.keys, self.values) if not k.per_solve)

    def digest(self) -> str:
        """SHA-256 of the keys and every value (what makes two case tables the same)."""
        text = json.dumps([[k.text for k in self.keys], [list(v) for v in self.values]], sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()

    @classmethod
    def build(
        cls,
        scene: str | Path,
        *,
        grid: Mapping[str, Sequence[Any]] | None = None,
        sample: Mapping[str, Sequence[float]] | None = None,
        samples: int | None = None,
        seed: int = 0,
        table: str | Path | Mapping[str, Sequence[Any]] | None = None,
    ) -> "Cases":
        """The case table: the Cartesian product of ``grid`` with ``samples`` Latin-hypercube
        samples of ``sample`` (``key: (lo, hi)``), or the rows of ``table`` (a CSV or Parquet
        file, or a mapping key -> column). Every key and value is checked against the scene spec.

        Raises
        ------
        InputError
            An unknown key, a value of the wrong type or out of range, a key given twice, a
            sample without bounds or count, or no case at all.
        """
        scene = Path(scene)
        grid, sample = dict(grid or {}), dict(sample or {})
        if table is not None and (grid or sample):
            raise InputError("cases: a table of cases cannot be combined with grid or sample")
        if table is not None:
            return cls._from_table(scene, table)
        if sample and samples is None:
            raise InputError("samples: the number of samples is needed with sample (--samples N)")
        if samples is not None and (isinstance(samples, bool) or not isinstance(samples, (int, np.integer))
                                    or samples < 1):
            raise InputError(f"samples: expected an integer >= 1, got {samples!r}")
        if samples is not None:
            samples = int(samples)  # a NumPy integer would not go into the sweep's JSON record
        if samples is not None and not sample:
            raise InputError("samples: given without any sample key=lo:hi to draw")
        # NumPy's generators take any non-negative integer; the bound is that of sf.estimate's seed.
        seed = count(seed, "seed", 0, 2**63 - 1)
        keys: list[Key] = []
        for name in list(grid) + list(sample):
            key = parse_key(name, "grid" if name in grid else "sample")
            if any(k.text == key.text for k in keys):
                raise InputError(f"{key.text}: given twice (in grid and sample)")
            for other in keys:
                if key.text.startswith(other.text + ".") or other.text.startswith(key.text + "."):
                    raise InputError(f"{key.text}: overlaps {other.text}; give one of them")
            keys.append(key)
        grid_columns: list[list[Any]] = []
        for key in keys[: len(grid)]:
            values = grid[key.text] if key.text in grid else grid[next(n for n in grid if n.strip() == key.text)]
            if isinstance(values, (str, bytes)) or not isinstance(values, Sequence | np.ndarray):
                values = [values]
            values = key.check_column([_plain(v) for v in values], scene, lambda i: f"grid value {i}")
            grid_columns.append(values)
        bounds = []
        for key in keys[len(grid):]:
            lo_hi = sample[key.text] if key.text in sample else sample[next(n for n in sample if n.strip() == key.text)]
            if key.column_type() != "float":
                raise InputError(f"sample: {key.text}: only number keys can be sampled, this one takes "
                                 f"{key.field.spec.what()}")
            try:
                lo, hi = (float(v) for v in lo_hi)
            except (TypeError, ValueError):
                raise InputError(f"sample: {key.text}: expected bounds (lo, hi), got {lo_hi!r}") from None
            if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
                raise InputError(f"sample: {key.text}: expected finite bounds lo < hi, got {lo:g}:{hi:g}")
            for bound in (lo, hi):
                key.check(bound, scene, "sample bound")
            bounds.append((lo, hi))
        rows = list(itertools.product(*grid_columns))
        if bounds:
            unit = _latin_hypercube(len(bounds), int(samples), seed)
            lo, hi = np.array(bounds).T
            drawn = [tuple(float(v) for v in row) for row in lo + unit * (hi - lo)]
            # The samples' bounds are checked; interior values lie between them.
            rows = [g + s for g in rows for s in drawn]
        if not rows or not keys:
            empty = [k.text for k, col in zip(keys, grid_columns) if not col]
            why = f" ({', '.join(empty)} has no values)" if empty else " (give --grid, --sample or --cases)"
            raise InputError(f"the sweep has no case{why}")
        values = tuple([row[j] for row in rows] for j in range(len(keys)))
        origin = {"grid": {k: list(v) for k, v in zip([k.text for k in keys], grid_columns)},
                  "sample": {k.text: list(b) for k, b in zip(keys[len(grid):], bounds)},
                  "samples": samples, "seed": seed if bounds else None}
        return cls(scene, tuple(keys), values, origin)

    @classmethod
    def _from_table(cls, scene: Path, table: str | Path | Mapping[str, Sequence[Any]]) -> "Cases":
        if isinstance(table, Mapping):
            columns, source = {str(k): list(v) for k, v in table.items()}, "table"
        else:
            path = Path(table)
            if not path.is_file():
                raise FileNotFoundError(f"cases: file not found: {path}")
            columns, source = _read_table(path), str(path)
        if not columns:
            raise InputError(f"cases: {source} has no column")
        keys = [parse_key(name, f"cases: {source}: column") for name in columns]
        lengths = {len(v) for v in columns.values()}
        if len(lengths) != 1:
            raise InputError(f"cases: {source}: columns of different lengths {sorted(lengths)}")
        if lengths == {0}:
            raise InputError(f"the sweep has no case ({source} has no row)")
        values = []
        for key, raw in zip(keys, columns.values()):
            cells = [_cell(key, v, f"cases: {source} row {i}") for i, v in enumerate(raw)]
            values.append(key.check_column(cells, scene, lambda i: f"{source} row {i}"))
        return cls(scene, tuple(keys), tuple(values), {"table": source})


def _plain(value: Any) -> Any:
    """NumPy scalars and arrays as the Python values a TOML file gives."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


def _cell(key: Key, value: Any, where: str) -> Any:
    """A table cell as the scene value: CSV cells are text, read by the key's type."""
    value = _plain(value)
    if not isinstance(value, str):
        return value
    kind = key.column_type()
    if kind == "str":
        return value
    if kind in ("float", "int", "bool"):
        return _scalar(key, value.strip(), where)
    try:
        return tomllib.loads(f"v = {value}")["v"]
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{where}: {key.text}: could not read {value!r} as a TOML value ({exc})") from None


def _read_table(path: Path) -> dict[str, list[Any]]:
    suffix = path.suffix.lower()
    if suffix == ".csv":
        with path.open(newline="", encoding="utf-8") as stream:
            reader = csv.reader(stream)
            header = next(reader, None)
            if header is None:
                raise InputError(f"cases: {path} is empty")
            rows = list(reader)
        bad = next((i for i, row in enumerate(rows) if len(row) != len(header)), None)
        if bad is not None:
            raise InputError(f"cases: {path} row {bad}: {len(rows[bad])} cells, the header has {len(header)}")
        return {name: [row[j] for row in rows] for j, name in enumerate(header)}
    if suffix in (".parquet", ".pq"):
        try:
            import pyarrow.parquet as pq
        except ImportError as exc:
            raise missing_extra(f"cases: reading {path}", exc) from None
        return pq.read_table(path).to_pydict()
    raise InputError(f"cases: expected a .csv or .parquet file, got {path}")
