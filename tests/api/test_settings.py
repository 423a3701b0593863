"""Settings: environment variables, validation, and the policy and runtime built from them."""

from __future__ import annotations

import subprocess
import sys

import pytest
from pydantic import ValidationError

from service.api.runtime import build_runtime, dispatch_policy
from service.core.cliques import CliqueBound
from service.core.threads import available_cores
from service.settings import MIB, Settings, get_settings
from service.solvers.dispatch import DispatchPolicy


def test_defaults() -> None:
    s = Settings()
    assert (s.host, s.port, s.log_level) == ("127.0.0.1", 8000, "info")
    assert (s.max_robots, s.max_nodes, s.max_conflicts) == (5000, 100_000, 200_000)
    assert s.max_body_bytes == 50 * MIB
    assert (s.exact_workers, s.solve_concurrency) == (1, 2)


def test_environment_overrides(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("SCHEDULER_PORT", "9001")
    monkeypatch.setenv("SCHEDULER_LOG_LEVEL", "DEBUG")
    monkeypatch.setenv("SCHEDULER_EXACT_MAX_CONFLICTS", "12")
    s = Settings()
    assert (s.port, s.log_level, s.exact_max_conflicts) == (9001, "debug", 12)


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("port", 0),
        ("port", 70000),
        ("default_time_limit_s", 0.0),
        ("default_time_limit_s", 301.0),
        ("max_robots", 0),
        ("max_body_bytes", 0),
        ("exact_workers", 0),
        ("solve_concurrency", 0),
        ("queue_size", -1),
        ("retry_after_s", 0),
        ("torch_threads", 0),
        ("max_clique_incidences", 0),
        ("max_cliques", 0),
        ("large_solver", "auto"),
        ("log_level", "loud"),
    ],
)
def test_invalid_values_are_refused(field: str, value: object) -> None:
    with pytest.raises(ValidationError, match=field):
        Settings(**{field: value})


def test_dispatch_policy_follows_settings() -> None:
    s = Settings(
        default_time_limit_s=2.5, exact_max_conflicts=10, large_solver="fcfs", exact_workers=4
    )
    assert dispatch_policy(s) == DispatchPolicy(
        default_time_limit_s=2.5, exact_max_conflicts=10, large_solver="fcfs", exact_workers=4
    )


def test_reading_settings_imports_nothing_heavy() -> None:
    heavy = "{'torch', 'ortools', 'numba', 'networkx'}"
    code = f"import sys, service.settings; print(sorted({heavy} & set(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_runtime_follows_settings() -> None:
    s = Settings(
        solve_concurrency=3, queue_size=5, retry_after_s=7, max_cliques=98, max_clique_incidences=99
    )
    runtime = build_runtime(s)
    pool = runtime.limiter
    assert (pool.queue_size, pool.retry_after_s) == (5, 7)
    assert pool.clique_bound == CliqueBound(cliques=98, incidences=99)
    assert pool.slots.total_tokens == 3
    assert runtime.torch_threads == max(1, available_cores() // 3)
    assert build_runtime(Settings(torch_threads=5)).torch_threads == 5


def test_get_settings_is_cached() -> None:
    assert get_settings() is get_settings()


def test_misspelled_setting_is_refused() -> None:
    with pytest.raises(ValidationError, match="max_robot"):
        Settings(max_robot=2)
