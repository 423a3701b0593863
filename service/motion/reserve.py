"""The time a paths-form answer keeps for its motion, learned from the answers made.

After the solve, a paths-form answer still executes the plan, checks clearance,
builds its trajectories and dependencies and encodes the answer as JSON (the encoding
since session 62: left to the margin before, ~0.08 s at 250 robots, it took a fresh
process's first 1-s request of 250 robots to 1.25 s): no solver can cut that short,
so the solve must stop early enough for it to fit in the request's time limit. A fixed share of the
limit (10 % until session 32) left 1-s requests of 250 robots 1.09-1.47 s end to end
(motion 0.17-0.41 s), and how long motion takes depends on the machine and the hour as
much as on the problem (the same worlds: 0.15-0.21 s on a 2-vCPU EPYC, 0.17-0.49 s on a
2-vCPU Xeon). So the reserve is ``margin`` x (``base_s`` + ``seconds_per_unit`` x
units) for a problem of :func:`work_units` units, and ``seconds_per_unit`` follows what
motion took: up at once to a slower observation, down by ``decay`` of the difference
per faster one. Problems of fewer than ``min_units`` units teach nothing (their fixed
costs would inflate the rate for the large ones).

A unit is a conflict, and an event weighs EVENT_UNITS of them (execution steps through
events, the answer lists conflicts and node times): fitted on the generator's 250-robot
warehouses on the Xeon (session 32), whose motion took 0.15-0.25 s, 4.6-5.8 us per unit
across the four layouts, where per event plus conflict it was 6.6-9.2 us (two-lane
worlds have half the conflicts of two-way ones for as many events).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field

from service.core.problem import Problem

__all__ = ["EVENT_UNITS", "MotionReserve", "work_units"]

EVENT_UNITS = 3


def work_units(problem: Problem) -> int:
    """The size of ``problem``'s motion: its conflicts, and EVENT_UNITS per event."""
    return EVENT_UNITS * int(problem.events.size) + problem.n_conflicts


@dataclass
class MotionReserve:
    """Seconds to keep for motion, per problem size; shared by the solves of a process."""

    seconds_per_unit: float = 6e-6  # the 250-robot worlds on the Xeon, rounded up
    base_s: float = 0.01  # what motion takes however small the problem (~10 ms at 25 robots)
    margin: float = 1.25  # jitter: the same motion varies by ~30 % from one run to the next
    min_units: int = 2_000
    decay: float = 0.2
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False, compare=False)

    def seconds(self, units: int) -> float:
        """The time to keep for the motion of a problem of ``units`` work units."""
        return self.margin * (self.base_s + self.seconds_per_unit * units)

    def observe(self, units: int, seconds: float) -> None:
        """Motion of a problem of ``units`` units took ``seconds``: follow its rate."""
        if units < self.min_units:
            return
        rate = max(seconds - self.base_s, 0.0) / units
        with self._lock:
            old = self.seconds_per_unit
            self.seconds_per_unit = rate if rate > old else old + self.decay * (rate - old)
