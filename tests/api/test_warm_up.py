"""The warm-up leaves nothing to compile for the requests that follow it."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from service.api import runtime
from service.solvers.dispatch import DispatchPolicy

ROOT = Path(__file__).resolve().parents[2]


def test_requests_after_the_warm_up_compile_no_kernel() -> None:
    """Every solver, every stage of ``auto`` and the paths form on worlds other than the
    warm-up's, in a fresh interpreter: no numba kernel gains a signature (each would be a
    compile of seconds inside a timed request on a cold cache)."""
    run = subprocess.run(
        [sys.executable, "-m", "tests.api.warm_check"],
        cwd=ROOT, capture_output=True, text=True, check=True, timeout=600,
    )  # fmt: skip
    added = json.loads(run.stdout.strip().splitlines()[-1])
    assert added == {}, f"compiled after the warm-up: {added}"


@pytest.mark.parametrize(
    ("compiling_passes", "expected"), [(0, 1), (1, 2), (2, 3), (5, runtime.WARMUP_PASSES)]
)
def test_warm_up_passes_repeat_until_one_compiles_nothing(
    compiling_passes: int, expected: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A pass that compiled (or loaded) a kernel is followed by another, up to
    WARMUP_PASSES: on a cold cache the first pass runs past every solve's limit and
    misses the steps taken only when time is left."""
    passes: list[float] = []
    monkeypatch.setattr(runtime, "solve_every_way", lambda _r, _p, limit: passes.append(limit))
    monkeypatch.setattr(
        runtime,
        "compiled_signatures",
        lambda: {"kernel": {str(min(len(passes), compiling_passes))}},
    )
    runtime.warm_solvers(DispatchPolicy())
    assert passes == [runtime.WARMUP_SOLVER_S] * expected
