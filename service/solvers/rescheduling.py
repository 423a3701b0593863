"""Re-scheduling a problem many times as the fleet progresses: its fixed work done once.

A fleet (or the disturbance benchmark) re-schedules the same graph every period
with new progress. The graph-form request is stateless and carries the whole
problem each time; :class:`Rescheduler` keeps what does not change between
re-schedules of one graph (the validated problem, its density cliques and the
decoder's and move search's clique tables, which depend only on the conflict
graph), so that a re-schedule costs the residual problem, the solve and the
rendering. :func:`service.solvers.dispatch.dispatch`
does the same work for a single request.
"""

from __future__ import annotations

import time
from collections import deque

import numpy as np

from service.core.assignment import Assignments
from service.core.cliques import Cliques, find_cliques
from service.core.decode import Decoder
from service.core.orientation import OrientationGraph
from service.core.problem import Problem, problem_from_request
from service.core.progress import previous_from_wire, progress_from_wire, residual_problem
from service.core.schemas import (
    PreviousConflictIn,
    ProgressIn,
    ScheduleRequest,
    ScheduleResponse,
    SolverName,
)
from service.memory import collection_deferred
from service.solvers.dispatch import DispatchPolicy, render_reserve, solve_problem

__all__ = ["Rescheduler"]

# The solver of a re-schedule stops early enough for the slowest of the last TAILS
# calls' checking and rendering (more precisely their 90th percentile) to fit the budget:
# that work grows with the machine's load, and a fleet's loop re-schedules one graph
# many times, so it is measured rather than modelled alone (render_reserve is the floor).
TAILS = 20
TAIL_QUANTILE = 0.9


class Rescheduler:
    """Re-schedules of one graph-form request; build once per graph.

    Raises (on construction):
        ProblemError: the request breaks a rule of the contract.
    """

    def __init__(self, request: ScheduleRequest, policy: DispatchPolicy) -> None:
        self.policy = policy
        self.problem: Problem = problem_from_request(request)
        self.cliques: Cliques = find_cliques(self.problem)
        self.decoder = Decoder(self.problem, self.cliques)
        self.orientation = OrientationGraph(self.problem, self.cliques)
        # Seconds from the solver's planned stop to each recent call's return.
        self.tails: deque[float] = deque(maxlen=TAILS)
        # Only the objective and options are kept of the request: its tens of thousands of
        # models would make every full garbage collection of the process walk them
        # (measured: a 0.5 s pause every ~11 re-schedules at 250 robots).
        self.request = ScheduleRequest.model_construct(
            objective=request.objective, options=request.options
        )

    def solve(
        self,
        previous: list[PreviousConflictIn] | Assignments | None,
        progress: ProgressIn,
        *,
        time_limit_s: float,
        solver: SolverName = "auto",
    ) -> ScheduleResponse:
        """The checked answer from ``progress.time`` on, warm-started from ``previous``
        (the wire list, or the assignment itself: in-process callers skip the mapping).

        The time limit counts from the call (the residual problem's construction
        included), like a request's from its arrival.

        Raises:
            ProblemError: the progress or previous assignment is invalid for this graph.
        """
        deadline = time.monotonic() + time_limit_s
        with collection_deferred():
            return self._solve(previous, progress, deadline, time_limit_s, solver)

    def _solve(
        self,
        previous: list[PreviousConflictIn] | Assignments | None,
        progress: ProgressIn,
        deadline: float,
        time_limit_s: float,
        solver: SolverName,
    ) -> ScheduleResponse:
        """:meth:`solve` inside its deadline, garbage collection deferred."""
        warm = previous
        if isinstance(previous, list):
            warm = previous_from_wire(self.problem, previous)
        residual = residual_problem(self.problem, progress_from_wire(self.problem, progress), warm)
        options = self.request.options.model_copy(
            update={"solver": solver, "time_limit_s": time_limit_s}
        )
        request = self.request.model_copy(update={"options": options})
        reserve = self.reserve(residual)
        answer = solve_problem(
            residual,
            request,
            self.policy,
            deadline=deadline,
            warm=warm,
            cliques=self.cliques,
            decoder=self.decoder.for_problem(residual),
            orientation=self.orientation.for_problem(residual),
            reserve_s=reserve,
        ).response()
        self.tails.append(time.monotonic() - (deadline - reserve))
        return answer

    def reserve(self, residual: Problem) -> float:
        """Seconds the solver leaves before the deadline: the recent calls' measured tails
        (their TAIL_QUANTILE), never less than the model of the work (render_reserve)."""
        floor = render_reserve(residual)
        if not self.tails:
            return floor
        return max(floor, float(np.quantile(np.fromiter(self.tails, float), TAIL_QUANTILE)))
