"""The folder of a sweep: what it holds, written so that an interruption never leaves a half
file behind and a rerun knows which cases are done.

::

    DIR/sweep.json            the record: scene (path and text), keys, sampling, columns, runs
    DIR/cases.parquet         the case table: case, one column per key
    DIR/results.parquet/      one row per finished case, one part file per batch
        part-RRR-BBBBB.parquet      (run RRR, batch BBBBB), appended as batches finish
        _common_metadata            the schema (read when no part exists yet)
    DIR/fields.zarr           with save=("displacement",): (n_cases, n_nodes, 3), one chunk per case

Every file is written under a temporary name (starting with ``.``, which readers of the
dataset skip) and renamed, so a file is either whole or absent. A batch writes its fields
first and its part file last: the part file is what marks its cases done, and a rerun solves
(and writes again) every case that has no row.
"""

from __future__ import annotations

import importlib.util
import json
import os
import shutil
import uuid
from pathlib import Path
from typing import Any, Iterable, Sequence

import numpy as np

from ..errors import InputError
from ._cases import missing_extra

__all__ = ["Store", "load_sweep", "load_fields", "MANIFEST", "RESULTS", "CASES", "FIELDS_STORE",
           "missing_extra"]

MANIFEST, CASES, RESULTS, FIELDS_STORE = "sweep.json", "cases.parquet", "results.parquet", "fields.zarr"
_OWNED = (MANIFEST, CASES, RESULTS, FIELDS_STORE)


def _arrow() -> tuple[Any, Any]:
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError as exc:
        raise missing_extra("a sweep", exc) from None
    return pa, pq


def _temporary(path: Path) -> Path:
    return path.with_name(f".{path.name}.{uuid.uuid4().hex[:8]}.tmp")


def write_atomic(path: Path, data: bytes) -> None:
    """Write ``data`` to a temporary file beside ``path`` and rename it into place: a process
    killed at any moment leaves the whole file or none (no fsync: a power cut may still cost the
    last files, which :meth:`Store.done` then finds unreadable and drops)."""
    tmp = _temporary(path)
    try:
        tmp.write_bytes(data)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def _arrow_type(pa: Any, kind: str) -> Any:
    return {"float": pa.float64(), "int": pa.int64(), "bool": pa.bool_(), "str": pa.string(),
            "list": pa.list_(pa.float64()), "json": pa.string()}[kind]


def _stored(kind: str, value: Any) -> Any:
    return json.dumps(value, sort_keys=True) if kind == "json" and value is not None else value


def result_columns(key_columns: Sequence[tuple[str, str]], *, dynamic: bool, n_cables: int,
                   n_markers: int) -> list[tuple[str, str]]:
    """``(name, kind)`` of every column of the results table, in order."""
    columns = [("case", "int"), *key_columns, ("converged", "bool"), ("newton_iterations", "int"),
               ("residual_norm", "float"), ("time", "float"), ("max_displacement", "float")]
    if dynamic:
        columns += [("steps", "int"), ("cutbacks", "int"), ("final_time", "float"), ("final_kinetic_energy", "float")]
    columns += [("tip.node", "int"), *((f"tip.{a}", "float") for a in "xyz")]
    columns += [(f"marker[{i}].{a}", "float") for i in range(n_markers) for a in "xyz"]
    for c in range(n_cables):
        columns += [(f"cable[{c}].max_tension", "float"), (f"cable[{c}].tensions", "list")]
    return columns + [("error", "str")]


class Store:
    """The folder of one sweep (see the module docstring)."""

    def __init__(self, root: str | os.PathLike[str]) -> None:
        self.root = Path(root)
        self.pa, self.pq = _arrow()

    # -- the record -----------------------------------------------------------------------

    @property
    def results(self) -> Path:
        return self.root / RESULTS

    def manifest(self) -> dict[str, Any] | None:
        """The record of the sweep held here, or None (no sweep here yet)."""
        path = self.root / MANIFEST
        if not path.is_file():
            return None
        try:
            return json.loads(path.read_text(encoding="utf-8"))
        except (json.JSONDecodeError, UnicodeDecodeError):
            return {"fingerprint": None}

    def holds_sweep_files(self) -> bool:
        return any((self.root / name).exists() for name in _OWNED)

    def clear(self) -> None:
        """Remove what a sweep writes here (and nothing else)."""
        for name in _OWNED:
            path = self.root / name
            if path.is_dir():
                shutil.rmtree(path)
            elif path.exists():
                path.unlink()

    def create(self, manifest: dict[str, Any], key_columns: Sequence[tuple[str, str]],
               case_columns: dict[str, list[Any]], columns: Sequence[tuple[str, str]]) -> None:
        """Start a new sweep here: the case table, the results' schema, then the record (last:
        a folder with a record is a complete start)."""
        pa, pq = self.pa, self.pq
        self.root.mkdir(parents=True, exist_ok=True)
        self.results.mkdir(exist_ok=True)
        n = len(next(iter(case_columns.values())))
        table = pa.table(
            {"case": pa.array(np.arange(n), pa.int64()),
             **{name: pa.array([_stored(kind, v) for v in case_columns[name]], _arrow_type(pa, kind))
                for name, kind in key_columns}}
        )
        self._write_table(table, self.root / CASES)
        schema = self.schema(columns)
        sink = pa.BufferOutputStream()
        pq.write_metadata(schema, sink)
        write_atomic(self.results / "_common_metadata", sink.getvalue().to_pybytes())
        self.write_manifest(manifest)

    def write_manifest(self, manifest: dict[str, Any]) -> None:
        write_atomic(self.root / MANIFEST, (json.dumps(manifest, indent=2) + "\n").encode())

    def schema(self, columns: Sequence[tuple[str, str]]) -> Any:
        return self.pa.schema([(name, _arrow_type(self.pa, kind)) for name, kind in columns])

    # -- results --------------------------------------------------------------------------

    def clean_temporaries(self) -> None:
        """Remove temporary files an interrupted run left behind (never whole files)."""
        for folder in (self.root, self.results):
            if folder.is_dir():
                for tmp in folder.glob(".*.tmp"):
                    tmp.unlink(missing_ok=True)

    def parts(self) -> list[Path]:
        return sorted(self.results.glob("part-*.parquet")) if self.results.is_dir() else []

    def done(self) -> set[int]:
        """The cases that have a row. A part file that cannot be read (cut short by a power
        cut) is removed: its cases are solved again."""
        out: set[int] = set()
        for part in self.parts():
            try:
                out.update(self.pq.read_table(part, columns=["case"]).column("case").to_pylist())
            except (OSError, self.pa.ArrowInvalid):
                part.unlink()
        return out

    def failed(self) -> int:
        """How many rows are failures (``converged`` false)."""
        count = 0
        for part in self.parts():
            count += self.pq.read_table(part, columns=["converged"]).column("converged").to_pylist().count(False)
        return count

    def append(self, run: int, batch: int, rows: Iterable[dict[str, Any]], columns: Sequence[tuple[str, str]]) -> Path:
        """Write the rows of one batch as a new part file (renamed into place when whole)."""
        rows = list(rows)
        data = {name: [_stored(kind, row.get(name)) for row in rows] for name, kind in columns}
        table = self.pa.table(data, schema=self.schema(columns))
        path = self.results / f"part-{run:03d}-{batch:05d}.parquet"
        self._write_table(table, path)
        return path

    def _write_table(self, table: Any, path: Path) -> None:
        sink = self.pa.BufferOutputStream()
        self.pq.write_table(table, sink)
        write_atomic(path, sink.getvalue().to_pybytes())

    # -- fields ---------------------------------------------------------------------------

    def create_fields(self, names: Sequence[str], n_cases: int, n_nodes: int) -> None:
        """The Zarr store of the saved fields: per name ``(n_cases, n_nodes, 3)`` float64, NaN
        until written, one chunk per case."""
        zarr = _zarr()
        root = zarr.open_group(str(self.root / FIELDS_STORE), mode="a")
        for name in names:
            if name not in root:
                root.create_array(name, shape=(n_cases, n_nodes, 3), chunks=(1, n_nodes, 3), dtype="f8",
                                  fill_value=np.nan)

    def write_fields(self, cases: Sequence[int], fields: Sequence[dict[str, np.ndarray]]) -> None:
        """Write the fields of some cases (each case its own chunk, so batches never share one)."""
        if not any(fields):
            return
        root = _zarr().open_group(str(self.root / FIELDS_STORE), mode="r+")
        for case, values in zip(cases, fields):
            for name, value in values.items():
                root[name][case] = value


def _zarr() -> Any:
    try:
        import zarr
    except ImportError as exc:
        raise missing_extra("saving fields", exc) from None
    return zarr


def _folder(path: str | os.PathLike[str]) -> Path:
    root = Path(path)
    if not (root / MANIFEST).is_file():
        raise InputError(f"{root}: not the folder of a sweep (no {MANIFEST}); expected the --out of sorofem sweep")
    return root


def load_sweep(path: str | os.PathLike[str], *, pandas: bool | None = None) -> Any:
    """The results of a sweep, one row per finished case, sorted by case.

    Parameters
    ----------
    path
        The sweep's folder (``--out`` of ``sorofem sweep``, ``out`` of :func:`sorofem.sweep`).
    pandas
        ``True``: a :class:`pandas.DataFrame` (its ``attrs["sweep"]`` is the record of
        ``sweep.json``); ``False``: a :class:`pyarrow.Table`; ``None`` (default): pandas if it
        is installed.

    Returns
    -------
    pandas.DataFrame or pyarrow.Table
        Columns: ``case``; one per override key, named by the key; ``converged``,
        ``newton_iterations``, ``residual_norm``, ``time`` (s, the solve), ``max_displacement``
        (m); with ``[dynamics]`` ``steps``, ``cutbacks``, ``final_time``,
        ``final_kinetic_energy``; ``tip.node``, ``tip.x``..``tip.z`` and ``marker[i].x``..
        (deformed positions, m, at the end for a dynamic case); per cable
        ``cable[c].max_tension`` and ``cable[c].tensions`` (N); ``error`` (text of a failed case).
        Override values that are tables are JSON text.

    Examples
    --------
    >>> table = sf.load_sweep("results/sweep")                    # doctest: +SKIP
    >>> table[table.converged]["max_displacement"].describe()     # doctest: +SKIP
    """
    root = _folder(path)
    pa, pq = _arrow()
    parts = Store(root).parts()
    if parts:
        table = pa.concat_tables([pq.read_table(p) for p in parts]).sort_by("case")
    else:
        table = pq.read_schema(root / RESULTS / "_common_metadata").empty_table()
    if pandas is False or (pandas is None and importlib.util.find_spec("pandas") is None):
        return table
    try:
        frame = table.to_pandas()  # pyarrow imports pandas (not a dependency: installed or not)
    except ImportError as exc:
        raise InputError(f"load_sweep(pandas=True): pandas is not installed ({exc}); pip install pandas") from None
    frame.attrs["sweep"] = json.loads((root / MANIFEST).read_text(encoding="utf-8"))
    return frame


def load_fields(path: str | os.PathLike[str], name: str = "displacement") -> np.ndarray:
    """A saved field of every case, ``(n_cases, n_nodes, 3)`` float64 (NaN for cases without
    a row yet or whose solve failed), from ``DIR/fields.zarr``."""
    root = _folder(path)
    zarr = _zarr()
    store = root / FIELDS_STORE
    if not store.is_dir():
        raise InputError(f"{root}: no saved fields (run the sweep with --save {name})")
    group = zarr.open_group(str(store), mode="r")
    if name not in group:
        raise InputError(f"{root}: no saved field {name!r} (saved: {', '.join(group.array_keys())})")
    return np.asarray(group[name][...])
