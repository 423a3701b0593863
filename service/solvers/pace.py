"""The pace of a search that works in steps: what still fits before its deadline.

Searches whose steps differ in cost check the clock only between steps, so none may
start a step that would end past its deadline (session 30: ``bbts`` answered 0.5-s
requests in 9-11 s inside one step, ``cmaes`` in 0.78-0.92 s). Each times its last
step and asks, before the next, either whether a step as long still ends in time
(:meth:`Pace.fits`: CMA-ES generations, LNS sub-problem builds) or how many units of
work fit at that pace (:meth:`Pace.units`: enumeration moves, decoded rows).
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass

__all__ = ["Pace"]


@dataclass
class Pace:
    """A deadline on ``clock`` and what the last step took."""

    deadline: float
    clock: Callable[[], float] = time.perf_counter
    step_s: float = 0.0  # the last step's seconds (0 before the first)
    per_unit_s: float = 0.0  # ... per unit of work it did

    def record(self, began: float, units: int = 1) -> None:
        """A step that began at ``began`` (on ``clock``) has ended, ``units`` of work done."""
        self.step_s = self.clock() - began
        self.per_unit_s = self.step_s / max(units, 1)

    def left(self) -> float:
        """Seconds to the deadline (negative past it)."""
        return self.deadline - self.clock()

    def fits(self, scale: float = 1.0, margin_s: float = 0.0) -> bool:
        """Whether a step ``scale`` times as long as the last, and ``margin_s`` more, ends
        before the deadline (before any step: whether ``margin_s`` does)."""
        return self.left() > scale * self.step_s + margin_s

    def units(self, within_s: float = math.inf) -> int:
        """Units of work that fit in ``within_s`` or the time left, whichever is less, at
        the last step's pace; 0 past the deadline, unbounded (``sys.maxsize``) while no
        step has taken measurable time."""
        seconds = min(within_s, self.left())
        if seconds <= 0:
            return 0
        if self.per_unit_s <= 0:
            return sys.maxsize
        return int(seconds / self.per_unit_s)
