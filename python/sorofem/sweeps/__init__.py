"""Sweeps: many variants of a scene solved on a Dask cluster (design sweeps, sensitivity
studies, datasets of actuation -> shape), resumable and fault tolerant.

A sweep is a scene and a table of cases, each overriding scene keys by their dotted names; each
case is what ``sorofem run`` computes for its scene, collected as one row of
``DIR/results.parquet``. Needs the optional packages of the extra ``cluster`` (Dask distributed,
pyarrow, zarr). See ``docs/sweep.md`` for the folder, the columns and running on a cluster.

Examples
--------
>>> import sorofem as sf
>>> run = sf.sweep("cantilever.toml", "results/sweep", workers=2,
...                grid={"material.youngs_modulus": [50e3, 66e3, 80e3]})   # doctest: +SKIP
>>> table = sf.load_sweep("results/sweep")                                 # doctest: +SKIP
"""

from ._cases import Cases, Key, parse_key
from ._run import CONNECT_TIMEOUT, LOCAL_CLUSTER_CONFIG, SweepResult, local_cluster, sweep
from ._solve import FIELDS
from ._store import load_fields, load_sweep

__all__ = ["sweep", "load_sweep", "load_fields", "SweepResult", "Cases", "Key", "parse_key", "local_cluster",
           "FIELDS", "CONNECT_TIMEOUT", "LOCAL_CLUSTER_CONFIG"]

# Documented (and pickled) as members of this package, whichever private module holds them.
for _public in (sweep, load_sweep, load_fields, SweepResult, Cases, Key, parse_key, local_cluster):
    _public.__module__ = __name__
