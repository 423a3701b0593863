"""Prometheus metrics of one app, in a registry of its own (so apps and tests never collide).

Names follow the Prometheus conventions: counters end in ``_total`` (added by
the client library), durations are histograms in ``*_seconds``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram, generate_latest

from service.core.schemas import ScheduleResponse

if TYPE_CHECKING:  # runtime imports the errors, which import these metrics
    from service.api.runtime import SolvePool

__all__ = ["REJECT_REASONS", "Metrics"]

# Why a request was refused: no valid bearer token, schema validation, a size cap, a
# cross-field rule, our fault, a full queue, or not ready yet.
REJECT_REASONS = (
    "unauthorized",
    "validation",
    "too_large",
    "problem_rule",
    "internal",
    "saturated",
    "not_ready",
)
# Solve times from a tiny problem (~5 ms) to the largest allowed time limit (300 s).
SOLVE_BUCKETS = (0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1, 2.5, 5, 10, 30, 60, 120, 300)
# Robots and conflicts per problem, up to the default caps (5000 robots, 200000 conflicts).
SIZE_BUCKETS = (2, 5, 10, 30, 100, 300, 1000, 3000, 10_000, 30_000, 100_000, 200_000)


class Metrics:
    """Every metric the service exports, registered in a fresh :class:`CollectorRegistry`."""

    def __init__(self) -> None:
        self.registry = CollectorRegistry()
        labels = ("route", "method", "status")
        self.requests = Counter(
            "scheduler_http_requests",
            "HTTP requests (probes excluded).",
            labels,
            registry=self.registry,
        )
        self.request_seconds = Histogram(
            "scheduler_http_request_duration_seconds",
            "HTTP request latency (probes excluded).",
            labels,
            registry=self.registry,
        )
        self.solves = Counter(
            "scheduler_solves",
            "Answered solves by solver and outcome.",
            ("solver", "outcome"),
            registry=self.registry,
        )
        self.solve_seconds = Histogram(
            "scheduler_solve_duration_seconds",
            "Solve time reported by the dispatcher.",
            ("solver",),
            buckets=SOLVE_BUCKETS,
            registry=self.registry,
        )
        self.problem_size = Histogram(
            "scheduler_problem_size",
            "Robots and conflicts of problems within the caps.",
            ("dimension",),
            buckets=SIZE_BUCKETS,
            registry=self.registry,
        )
        self.rejected = Counter(
            "scheduler_rejected_requests",
            "Refused requests by reason.",
            ("reason",),
            registry=self.registry,
        )
        for reason in REJECT_REASONS:
            self.rejected.labels(reason)
        self.queued = Gauge(
            "scheduler_queued_solves",
            "Solves waiting for a slot.",
            registry=self.registry,
        )
        self.running = Gauge(
            "scheduler_running_solves",
            "Solves holding a slot.",
            registry=self.registry,
        )

    def watch_pool(self, pool: SolvePool) -> None:
        """Read the queue length and running solves from ``pool`` at every scrape."""
        self.queued.set_function(lambda: pool.waiting)
        self.running.set_function(lambda: pool.running)

    def observe_request(self, route: str, method: str, status: int, seconds: float) -> None:
        """Count one HTTP request and its latency."""
        self.requests.labels(route, method, str(status)).inc()
        self.request_seconds.labels(route, method, str(status)).observe(seconds)

    def observe_problem(self, n_robots: int, n_conflicts: int) -> None:
        """Record the size of a problem about to be solved."""
        self.problem_size.labels("robots").observe(n_robots)
        self.problem_size.labels("conflicts").observe(n_conflicts)

    def observe_solve(self, response: ScheduleResponse) -> None:
        """Count one answered solve under the solver that was asked (after ``auto`` routing).

        Outcome ``fallback`` means that solver had no valid answer and a fallback answered.
        """
        info = response.solver
        if info.fallback_from is not None:
            solver, outcome = info.fallback_from, "fallback"
        else:
            solver, outcome = info.name, "optimal" if info.optimal else "feasible"
        self.solves.labels(solver, outcome).inc()
        self.solve_seconds.labels(solver).observe(info.runtime_s)

    def render(self) -> bytes:
        """The Prometheus text exposition of every metric."""
        return generate_latest(self.registry)
