"""What a test does when something it needs is absent: fail in CI, skip elsewhere."""

from __future__ import annotations

import os

import pytest


def missing_in_ci(reason: str) -> None:
    """Something a test needs is absent: a failure in CI (the environment variable ``CI`` is
    set, and CI provides every test dependency and ``../shared``), a skip elsewhere."""
    if os.environ.get("CI"):
        pytest.fail(f"{reason}; CI must provide it (the CI environment variable is set)", pytrace=False)
    pytest.skip(reason)
