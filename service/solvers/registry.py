"""The solver registry: every solver answers the same call on the same context.

A solver receives a :class:`SolveContext` (the validated problem with its
cliques, evaluator and decoder, built once per request) and returns a
:class:`SolverOutput` holding one assignment, or ``None`` when it found no
solution within its time limit. It never renders HTTP and never checks its own
answer: :mod:`service.solvers.dispatch` does that, once, for every solver.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from service.core.assignment import Assignments
from service.core.cliques import Cliques, find_cliques
from service.core.decode import Decoder
from service.core.evaluate import Evaluator
from service.core.lazy import cached_property
from service.core.orientation import OrientationGraph
from service.core.problem import Problem
from service.core.schemas import Objective

if TYPE_CHECKING:  # the learned models need torch; the registry itself does not
    from service.learning.store import StoredModel

__all__ = ["SolveContext", "Solver", "SolverOutput", "get_solver", "register", "solver_names"]


@dataclass(eq=False)
class SolveContext:
    """Everything a solver needs about one request; derived structures built lazily, once."""

    problem: Problem
    objective: Objective
    time_limit_s: float
    seed: int = 0
    samples: int | None = None
    # Cores of this solve: CP-SAT's workers, the evaluator's threads, LNS sub-problems at once,
    # re-insertion searches a turn runs at once.
    workers: int = 1
    models: Mapping[str, StoredModel] = field(default_factory=dict)  # by objective
    # Sees every improving solution of an anytime solver (CP-SAT) as (wall s, assignment):
    # lets a benchmark measure how fast a method reaches a cost. None in the service.
    on_solution: Callable[[float, Assignments], None] | None = None
    # A valid assignment to start local search from: the previous answer of a re-schedule.
    warm: Assignments | None = None
    # The portfolio (``auto``): CP-SAT alone up to this many conflicts; above, this solver
    # first (the policy's large solver), then CP-SAT hinted with its answer.
    exact_max_conflicts: int = 60
    first_stage: str = "priority_tabu"
    # ... and no CP-SAT stage at all above this many (it improves nothing there in seconds).
    exact_stage_max_conflicts: int = 10_000
    # ... and large-neighbourhood search instead of CP-SAT on the whole model from this many
    # (for the objectives that are sums; service/solvers/lns.py).
    lns_min_conflicts: int = 700
    # CP-SAT limited in deterministic time too (exact.solve(deterministic=True)), so that
    # the ``exact`` solver's answer is the same for the same seed even when it is cut.
    exact_deterministic: bool = False

    @cached_property
    def cliques(self) -> Cliques:
        return find_cliques(self.problem)

    @cached_property
    def evaluator(self) -> Evaluator:
        return Evaluator(self.problem, threads=self.workers)

    @cached_property
    def decoder(self) -> Decoder:
        return Decoder(self.problem, self.cliques)

    @cached_property
    def orientation(self) -> OrientationGraph:
        return OrientationGraph(self.problem, self.cliques)

    def cost(self, assignment: Assignments) -> float:
        """The objective's cost of a single ``assignment``, by the one evaluator."""
        return float(self.evaluator.evaluate(assignment).costs[self.objective][0])


@dataclass
class SolverOutput:
    """A solver's answer: one assignment and what the solver knows about it."""

    assignment: Assignments  # a batch of one
    optimal: bool = False
    model: str | None = None
    samples: int | None = None
    detail: str | None = None
    extra: dict[str, float] = field(default_factory=dict)


Solver = Callable[[SolveContext], SolverOutput | None]

_REGISTRY: dict[str, Solver] = {}


def register(name: str) -> Callable[[Solver], Solver]:
    """Decorator adding a solver under ``name`` (the value of ``options.solver``)."""

    def add(fn: Solver) -> Solver:
        if name in _REGISTRY:
            raise ValueError(f"solver {name!r} registered twice")
        _REGISTRY[name] = fn
        return fn

    return add


def get_solver(name: str) -> Solver:
    """The solver registered under ``name`` (KeyError if none)."""
    return _REGISTRY[name]


def solver_names() -> tuple[str, ...]:
    """Names of every registered solver."""
    return tuple(_REGISTRY)
