"""Cable commands in the viewer: the slider each cable gets according to what drives it
(:attr:`sorofem.Body.commands`): the actuation alpha of a spring chain, the pull in mm or the
tension in N of a tendon; and the lines of the side panel that report each cable after a solve
(a tendon's solved tension and pull, and whether it is slack).

Plain functions of a body and a result: no viser here, so they are tested without a server.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..body import Body
from ..static import StaticResult
from .style import ALPHA_RANGE, ALPHA_STEP, PULL_RANGE_FRACTION, SLIDER_DIVISIONS, TENSION_RANGE_PER_MU_AREA

__all__ = ["CommandSlider", "command_slider", "tension_scale", "is_slack", "cable_lines", "nice_ceiling"]


@dataclass(frozen=True)
class CommandSlider:
    """What a cable's slider shows: its label, range, step and initial value in display units
    (alpha, mm or N) and the factor that turns a display value into the command's SI value
    (alpha, m or N)."""

    cable: int
    #: ``"actuation"``, ``"pull"`` or ``"tension"`` (:attr:`sorofem.Body.commands`).
    kind: str
    label: str
    min: float
    max: float
    step: float
    initial: float
    hint: str
    #: Command (SI) per display unit: 1 for alpha and N, 1e-3 for a pull shown in mm.
    to_command: float

    def command(self, shown: float) -> float:
        """The command value (alpha, m or N) of the slider position ``shown``."""
        return float(shown) * self.to_command


def nice_ceiling(value: float) -> float:
    """The smallest of 1, 2, 5 times a power of ten that is >= ``value`` (> 0)."""
    power = 10.0 ** math.floor(math.log10(value))
    return next(m * power for m in (1.0, 2.0, 5.0, 10.0) if m * power >= value * (1 - 1e-12))


def _step(span: float) -> float:
    """A power of ten giving about :data:`SLIDER_DIVISIONS` or more positions over ``span``."""
    return 10.0 ** math.floor(math.log10(span / SLIDER_DIVISIONS))


def tension_scale(body: Body) -> float:
    """Top of a tension slider when the command gives no scale, N: ``TENSION_RANGE_PER_MU_AREA``
    times the mean shear modulus times the body's cross-section (the product of the two
    smallest extents of its bounding box), rounded up by :func:`nice_ceiling`. That force
    strains a bar of that section by some 10 %, a curl well past anything small."""
    lo, hi = body.mesh.bounds
    extents = np.sort(hi - lo)
    mu = float(np.mean(body.material.per_element(body.mesh.n_tets)[0]))
    return nice_ceiling(TENSION_RANGE_PER_MU_AREA * mu * float(extents[0] * extents[1]))


def command_slider(body: Body, cable: int, alpha_range: tuple[float, float] = ALPHA_RANGE) -> CommandSlider:
    """The slider of ``body``'s cable ``cable`` for its current command.

    - spring chain: alpha over ``alpha_range`` (widened to the current alpha);
    - tendon pulled by a length: its pull in mm from 0 to ``PULL_RANGE_FRACTION`` of its rest
      length (the default bounds of :func:`sorofem.control`), widened to the current pull;
    - tendon driven by a tension: N from 0 to :func:`tension_scale` or twice the current
      tension, whichever is larger.
    """
    kind, value = body.commands[cable]
    if kind == "actuation":
        return CommandSlider(cable, kind, f"cable {cable} alpha", min(alpha_range[0], value),
                             max(alpha_range[1], value), ALPHA_STEP, float(value), "1 = rest length, < 1 = pulled", 1.0)
    length = body.cables[cable].length
    if kind == "pull":
        top = max(nice_ceiling(PULL_RANGE_FRACTION * length * 1e3), value * 1e3)
        return CommandSlider(cable, kind, f"cable {cable} pull [mm]", min(0.0, value * 1e3), top, _step(top),
                             value * 1e3, f"tendon pulled by this length (rest length {length * 1e3:.4g} mm); slack "
                             "when the body does not hold it taut", 1e-3)
    top = max(tension_scale(body), nice_ceiling(2.0 * value) if value > 0 else 0.0)
    return CommandSlider(cable, kind, f"cable {cable} tension [N]", 0.0, top, _step(top), float(value),
                         "tendon held at this tension by its motor", 1.0)


def is_slack(result: StaticResult, cable: int) -> bool:
    """Whether ``cable`` is a tendon that carries no tension at ``result``."""
    tension = result.cable_tension[cable] if cable < len(result.cable_tension) else None
    return tension is not None and tension <= 0.0


def cable_lines(result: StaticResult) -> list[str]:
    """One line per cable for the side panel: a tendon's command and its solved tension (N)
    and pull (mm), or "slack"; a spring chain's alpha and its range of segment tensions."""
    lines = []
    for c, (kind, value) in enumerate(result.commands):
        tension = result.cable_tension[c] if c < len(result.cable_tension) else None
        if tension is None:
            segments: Any = result.cable_tensions[c]
            lines.append(f"cable {c}: alpha {value:.3f}, tension {segments.min():.3g} .. {segments.max():.3g} N")
            continue
        command = f"pull {value * 1e3:.3g} mm" if kind == "pull" else f"tension {value:.3g} N"
        state = "**slack**" if is_slack(result, c) else "taut"
        lines.append(f"cable {c} (tendon, {command}): {state}, tension {tension:.4g} N, "
                     f"pull {result.cable_pull[c] * 1e3:.4g} mm")
    return lines
