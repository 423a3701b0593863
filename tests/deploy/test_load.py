"""deploy/load.py: its bounds and figures (the load itself runs against a live service)."""

from __future__ import annotations

import importlib.util
import os
import sys
from pathlib import Path

import pytest

# deploy/ is a folder of scripts, not a package: load the script by its path.
SPEC = importlib.util.spec_from_file_location(
    "deploy_load", Path(__file__).parents[2] / "deploy" / "load.py"
)
assert SPEC is not None and SPEC.loader is not None
load = importlib.util.module_from_spec(SPEC)
sys.modules["deploy_load"] = load  # dataclasses look their module up there
SPEC.loader.exec_module(load)


def test_runs_are_bounded() -> None:
    args = load.parse_args(["--clients", "8", "--seconds", "300", "--pid", "1"])
    assert (args.clients, args.seconds, args.pid) == (8, 300.0, 1)
    for bad in (["--seconds", "0"], ["--seconds", "3601"], ["--clients", "65"]):
        with pytest.raises(SystemExit):
            load.parse_args(bad)


def test_figures() -> None:
    assert load.rss_mib(os.getpid()) > 1
    assert load.percentiles([]) == {"ok": 0, "p50_s": None, "p99_s": None}
    assert load.percentiles([1.0] * 99 + [2.0]) == {"ok": 100, "p50_s": 1.0, "p99_s": 1.01}
    summary = load.rss_summary([(0.0, 600.0), (10.0, 650.0), (20.0, 640.0)])
    assert (summary["first"], summary["max"], summary["last"]) == (600.0, 650.0, 640.0)
    assert summary["samples"] == "0s:600 10s:650 20s:640"
