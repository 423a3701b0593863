"""The warm-up leaves nothing to compile for the requests that follow it."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

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
