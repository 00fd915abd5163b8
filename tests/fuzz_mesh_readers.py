"""Fuzz target of the mesh and surface readers: ``make fuzz`` (not part of ``make test``).

Runs the checks of tests/test_properties_mesh.py on many random files (Hypothesis's "fuzz"
profile, not derandomised: each run explores new inputs; a failure is shrunk and printed with
the bytes that reproduce it, and kept in Hypothesis's example database, .hypothesis/, so the
next run tries it first). Every file must be read into a valid mesh or refused with a
:class:`sorofem.MeshError` naming it, within the reader's time limit.

Usage::

    python tests/fuzz_mesh_readers.py [--examples N]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
os.environ.setdefault("SOROFEM_HYPOTHESIS_PROFILE", "fuzz")

from hypothesis import given, settings  # noqa: E402

from tests.test_properties_mesh import FILES, read_surface_checked, read_volume_checked  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--examples", type=int, default=20_000, help="files to try (default 20000)")
    args = parser.parse_args()
    folder = Path(tempfile.mkdtemp(prefix="sorofem-fuzz-"))
    count = [0]

    @settings(max_examples=args.examples, derandomize=False, database=settings.default.database)
    @given(file=FILES)
    def fuzz(file: tuple[str, bytes]) -> None:
        suffix, data = file
        count[0] += 1
        path = folder / f"f{count[0] % 1000}{suffix}"
        path.write_bytes(data)
        read_volume_checked(path)
        read_surface_checked(path)

    fuzz()
    print(f"{count[0]} files read or refused cleanly")
    return 0


if __name__ == "__main__":
    sys.exit(main())
