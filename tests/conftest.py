"""Shared fixtures of the Python tests."""

from __future__ import annotations

from pathlib import Path

import pytest
from ci import missing_in_ci

REPO_ROOT = Path(__file__).resolve().parent.parent

BOX_SCENE = """\
# A tiny cantilever: 4x1x1 cells, clamped at x = 0, sagging under gravity.
[mesh]
box = { size = [0.1, 0.02, 0.02], cells = [4, 1, 1] }

[material]
youngs_modulus = 66e3
poisson_ratio = 0.45
density = 1080

[formulation]
kind = "standard"

[[fixed]]
box = { min = [-1e-9, -1, -1], max = [1e-9, 1, 1] }

[loads]
gravity = [0, 0, -9.81]

[solver]
tolerance = 1e-8
max_iterations = 50
load_steps = 1
"""


@pytest.fixture
def shared_data() -> Path:
    """Path to the shared SolidFEM sample data (../shared/data/solidfem next to the repo)."""
    path = REPO_ROOT.parent / "shared" / "data" / "solidfem"
    if not path.is_dir():
        missing_in_ci(f"shared sample data not found at {path} (expected ../shared/data/solidfem beside the repo)")
    return path


@pytest.fixture
def box_scene_text() -> str:
    """TOML text of a small, valid box scene."""
    return BOX_SCENE


@pytest.fixture
def box_scene(tmp_path: Path) -> Path:
    """A valid box scene written to ``tmp_path/scene.toml``."""
    path = tmp_path / "scene.toml"
    path.write_text(BOX_SCENE, encoding="utf-8")
    return path


# The Hypothesis profiles of the property suite ("ci": derandomised; "fuzz" for `make fuzz`),
# loaded once for every test module.
import tests.hostile  # noqa: E402,F401
