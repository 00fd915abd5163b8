"""The pieces of a simulation run in chunks (see :func:`sorofem.dynamics.simulate`): their
outputs joined as one call would return them, and their error messages counted from the run's
start."""

from __future__ import annotations

import re
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .errors import ConvergenceError

__all__ = ["Joined", "shift_step_in_message"]

STEP_IN_MESSAGE = re.compile(r"time step (\d+) \(t = ([0-9.eE+-]+) s\)")


class Joined:
    """The outputs of the chunks integrated so far, joined as one call would return them."""

    def __init__(self) -> None:
        self.times: list[NDArray[np.float64]] = []
        self.positions: list[NDArray[np.float64]] = []
        self.kinetic_energy: list[NDArray[np.float64]] = []
        self.cable_points: list[Any] = []
        self.tendon_tensions: list[list[float | None]] = []
        self.tendon_pulls: list[list[float | None]] = []
        self.iterations: list[NDArray[np.int64]] = []
        self.factorizations: list[NDArray[np.int64]] = []
        self.residuals: list[NDArray[np.float64]] = []
        self.contact: list[dict[str, Any]] = []
        self.cutbacks = 0
        self.single_precision_factorizations = 0
        #: The core's seconds per phase, summed over the chunks.
        self.timings: dict[str, float] = {}
        self.velocities: Any = None
        #: Steps integrated.
        self.done = 0

    def output(self) -> dict[str, Any]:
        return {
            "times": np.concatenate(self.times),
            "positions": np.concatenate(self.positions),
            "velocities": self.velocities,
            "kinetic_energy": np.concatenate(self.kinetic_energy),
            "cable_points": self.cable_points,
            "tendon_tensions": self.tendon_tensions,
            "tendon_pulls": self.tendon_pulls,
            "iterations": np.concatenate(self.iterations),
            "factorizations": np.concatenate(self.factorizations),
            "residuals": np.concatenate(self.residuals),
            "cutbacks": self.cutbacks,
            "single_precision_factorizations": self.single_precision_factorizations,
            "timings": self.timings,
            "contact": None if not self.contact else {
                key: (np.concatenate([c[key] for c in self.contact]) if key != "iterate_min_distances"
                      else [d for c in self.contact for d in c[key]])
                for key in self.contact[0]
            },
        }


def shift_step_in_message(err: ConvergenceError, first_step: int, t_offset: float) -> None:
    """A chunk's error counts steps and time from the chunk's start: make them global."""

    def shift(match: re.Match[str]) -> str:
        return f"time step {int(match[1]) + first_step} (t = {float(match[2]) + t_offset:.4f} s)"

    if err.args and isinstance(err.args[0], str):
        err.args = (STEP_IN_MESSAGE.sub(shift, err.args[0]), *err.args[1:])
    if isinstance(err.report, dict) and isinstance(err.report.get("message"), str):
        err.report["message"] = STEP_IN_MESSAGE.sub(shift, err.report["message"])
