"""The service's settings: one typed object, read from ``SCHEDULER_*`` environment variables.

Example::

    SCHEDULER_PORT=9000 SCHEDULER_SOLVE_CONCURRENCY=4 python -m service

Routes read them through :func:`get_settings` (cached, so the environment is
read once); tests replace them with ``app.dependency_overrides[get_settings]``.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import Literal

from pydantic import Field, SecretStr, field_validator
from pydantic_settings import BaseSettings, SettingsConfigDict

from service.core.schemas import MAX_TIME_LIMIT_S

__all__ = ["MAX_CLIQUES", "MAX_CLIQUE_INCIDENCES", "MIB", "Settings", "get_settings"]

MIB = 1024 * 1024

# The model store shipped in the repository (the Dockerfile copies it to the same place).
# The defaults of ``max_cliques`` and ``max_clique_incidences`` (see Settings), also what
# tools that ask whether a default service would serve a request (413) read.
MAX_CLIQUES, MAX_CLIQUE_INCIDENCES = 20_000, 2_000_000
DEFAULT_MODEL_STORE = Path(__file__).resolve().parents[1] / "model_store"

LogLevel = Literal["critical", "error", "warning", "info", "debug"]


class Settings(BaseSettings):
    """Everything an operator may tune, with the defaults the service ships with."""

    model_config = SettingsConfigDict(env_prefix="SCHEDULER_")

    host: str = "127.0.0.1"
    port: int = Field(default=8000, ge=1, le=65535)
    log_level: LogLevel = "info"
    # Solving: a request without options.time_limit_s gets this many seconds.
    default_time_limit_s: float = Field(default=5.0, gt=0.0, le=MAX_TIME_LIMIT_S)
    # Caps on what one request may ask (413 above them); they bound memory and solve time.
    max_robots: int = Field(default=5000, ge=1)
    max_nodes: int = Field(default=100_000, ge=1)
    max_conflicts: int = Field(default=200_000, ge=0)
    max_body_bytes: int = Field(default=50 * MIB, ge=1)
    # Routing of solver "auto": exact up to this many conflicts, large_solver above.
    # Conflict density, not robot count, makes CP-SAT slow: measured (docs/benchmarks.md)
    # it proves 25 robots x 2 conflicts (50) in < 0.5 s but not 25 x 4 (100) in 10 s.
    exact_max_conflicts: int = Field(default=60, ge=0)
    # ``auto`` skips its CP-SAT stage (and LNS) above this many conflicts and gives the first
    # stage (then re-insertion search in turns, or tabu search) the whole budget: measured
    # (docs/benchmarks.md, "Anytime auto"), CP-SAT improved no 250-robot warehouse
    # (12,000-23,000 conflicts) in 10 s, and the 70 % it took there made auto worse with
    # 10 s than with 5 s. (LNS followed the first stage there from session 24 to 57; since
    # session 58 the turns alone are better at 5, 10 and 30 s: see portfolio._staged.)
    exact_stage_max_conflicts: int = Field(default=10_000, ge=0)
    # ``auto`` runs large-neighbourhood search (CP-SAT re-planning a few robots at a time,
    # service/solvers/lns.py) instead of its whole-model CP-SAT stage from this many
    # conflicts up to exact_stage_max_conflicts, for the objectives that are sums. Measured
    # (session 18, 5 s, against the better answer): generated 50-robot worlds of 806-901
    # conflicts 0.81-0.98 -> 1.00, of 515-575 conflicts mixed (two worse by 1-5 %, one
    # better); 100-robot warehouses 0.76-0.79 -> 0.85-0.89 at 5 s (avg_delay: LNS better on
    # all six), docs/benchmarks.md "Large-neighbourhood search". Below it (and above
    # exact_max_conflicts) LNS runs until it converges and the CP-SAT stage follows
    # (session 19, portfolio.MID_LNS_SHARE).
    lns_min_conflicts: int = Field(default=700, ge=0)
    # ``auto``'s first stage above exact_max_conflicts. Measured (2026-11-24, bench.anytime,
    # auto with tabu from the blended start vs with gnn_vae_refined, cost ratio against
    # the best found): generated warehouses and floors of 515-3,900 conflicts 0.88-0.97 vs
    # 0.82-0.94 at 1 s and 0.98-1.00 vs 0.93-1.00 at 5 s; 250 robots 0.83-0.87 vs
    # 0.69-0.73 at 1 s, 0.94 / 1.00 vs 1.00 / 0.98 at 5 s; the conformance sets (83-262
    # conflicts) identical. The GNN-VAE solvers stay available by name. Since
    # 2026-11-24 (session 12) robot-priority search first (priority_tabu): measured
    # against tabu in docs/benchmarks.md, "Anytime auto".
    large_solver: str = "priority_tabu"
    # Where the learned models live (manifest.json + <objective>/<version>/); a missing
    # or corrupt model degrades its objective to the exact solver, then FCFS.
    model_store: Path = DEFAULT_MODEL_STORE
    # Cores per solve (CP-SAT's workers, threads evaluating the local searches' batches,
    # LNS sub-problems solved at once, re-insertion searches a turn runs at once), and how
    # many solves run at once in worker threads; their product should not exceed the
    # machine's cores. One fleet per service on 2 cores: concurrency 1 and 2 workers
    # (measured in docs/benchmarks.md, "Anytime auto", auto_2cores). Re-insertion's
    # searches also take the cores no other solve holds (a lone request every core:
    # ``service.core.threads.cores_per_solve``), whatever this says.
    exact_workers: int = Field(default=1, ge=1)
    # The ``exact`` solver's answer the same on every run with the same seed, even when the
    # time limit cuts its search: CP-SAT stops on a deterministic-time budget (about half
    # the time limit on the benchmark machine; docs/contract.md, Exact solver).
    exact_deterministic: bool = False
    solve_concurrency: int = Field(default=2, ge=1)
    # Solves waiting for a slot beyond the running ones; when full, 503 with Retry-After
    # (retry_after_s, also sent while the service is not ready).
    queue_size: int = Field(default=8, ge=0)
    retry_after_s: int = Field(default=1, ge=1)
    # Intra-op threads of torch per process (None: cores / solve_concurrency, at least 1),
    # so concurrent solves do not oversubscribe the cores.
    torch_threads: int | None = Field(default=None, ge=1)
    # Work bounds of the clique enumeration (413 above either): maximal cliques of the
    # conflict graph, and conflicts summed over them. Complete multipartite conflict graphs
    # have exponentially many; what a solve costs beyond its time limit follows both
    # (each clique is a density constraint, each conflict in it a term). Measured
    # (2026-11-24, auto, no bound; complete multipartite k robots x n nodes): 4 x 10
    # (10,000 cliques, 60,000 conflicts in them) kept 0.5-5 s limits within 0.12 s;
    # 5 x 7 (16,807; 168,070) and 7 x 4 (16,384; 344,064) overran 0.5 s limits by 0.3-0.5 s
    # before the enumeration's output and CP-SAT's density constraints were sped up;
    # 9 x 3 (19,683; 708,588) by 0.9 s. Realistic graphs have few, large cliques: 250-robot
    # warehouses hold up to 936,000 conflicts in 209 cliques and keep their limits, and a
    # sparse graph has about one conflict per clique (5,000 robots, 100,000 conflicts:
    # 102,512 in as many cliques).
    max_cliques: int = Field(default=MAX_CLIQUES, ge=1)
    max_clique_incidences: int = Field(default=MAX_CLIQUE_INCIDENCES, ge=1)
    # Paths form (docs/paths.md): pieces of at most this many metres (sections and following
    # gaps are conservative by up to this much) and this much clearance kept between
    # footprints beyond their radii; caps on path points (413 above them) and on the
    # interference work (segment pairs within reach, boxes) of one request.
    geometry_resolution_m: float = Field(default=0.25, ge=0.01, le=100.0)
    geometry_margin_m: float = Field(default=0.05, gt=0.0, le=10.0)
    max_path_points: int = Field(default=10_000, ge=2)
    max_total_path_points: int = Field(default=500_000, ge=2)
    max_interference_pairs: int = Field(default=5_000_000, ge=1)
    # Bearer token the POST endpoints require (``Authorization: Bearer <token>``); unset or
    # empty: no authentication. Probes and metrics stay open.
    api_token: SecretStr | None = None

    @field_validator("log_level", mode="before")
    @classmethod
    def _lower_log_level(cls, value: object) -> object:
        """Accept ``INFO`` as well as ``info``."""
        return value.lower() if isinstance(value, str) else value

    @field_validator("api_token", mode="before")
    @classmethod
    def _empty_token_is_none(cls, value: object) -> object:
        """``SCHEDULER_API_TOKEN=`` (empty) means no authentication, not an empty token."""
        return None if value in ("", None) else value

    @field_validator("large_solver")
    @classmethod
    def _concrete_solver(cls, value: str) -> str:
        """``auto`` would route to itself; the solver must be a concrete one."""
        if value == "auto":
            raise ValueError("large_solver must name a concrete solver, not 'auto'")
        return value


@lru_cache
def get_settings() -> Settings:
    """The process's settings, read from the environment once."""
    return Settings()
