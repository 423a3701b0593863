"""Work cut into parts for the shared pool: balanced cuts and results in order."""

from __future__ import annotations

import os
import threading

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from service.core import threads
from service.core.threads import (
    available_cores,
    balanced_cuts,
    cores_per_solve,
    in_parts,
    parts_for,
    solving,
)


@settings(max_examples=200, deadline=None, derandomize=True)
@given(
    weight=st.lists(st.integers(0, 50), max_size=40),
    parts=st.integers(1, 6),
    allowed_every=st.integers(1, 5),
)
def test_cuts_are_the_first_allowed_positions_past_each_share(
    weight: list[int], parts: int, allowed_every: int
) -> None:
    """Each inner cut is the first allowed index at or after the least index with at
    least its share of the weight before it (or the end): brute force."""
    w = np.array(weight, dtype=np.int64)
    allowed = np.arange(allowed_every, w.size, allowed_every)
    bounds = balanced_cuts(w, parts, allowed)
    assert bounds[0] == 0 and bounds[-1] == w.size
    assert all(lo <= hi for lo, hi in zip(bounds[:-1], bounds[1:], strict=True))
    if parts <= 1 or w.size == 0:
        assert bounds == [0, w.size]
        return
    assert len(bounds) == parts + 1
    total = int(w.sum())
    for k, cut in enumerate(bounds[1:-1], start=1):
        share = total * k / parts
        least = next(i for i in range(w.size + 1) if w[:i].sum() >= share)
        expected = next((a for a in allowed.tolist() if a >= least), w.size)
        assert cut == expected


def test_results_come_in_order_and_the_others_run_elsewhere() -> None:
    """The first part runs in the caller's thread, the rest on the pool."""
    caller = threading.get_ident()

    def run(k: int) -> tuple[int, bool]:
        return k * k, threading.get_ident() == caller

    out = in_parts(run, [3, 1, 4, 1, 5])
    assert [v for v, _ in out] == [9, 1, 16, 1, 25]
    assert [here for _, here in out] == [True, False, False, False, False]


def test_parts_are_never_smaller_than_the_least_work(monkeypatch: pytest.MonkeyPatch) -> None:
    """No part below ``least_work``, one part at least, never more than the cores."""
    monkeypatch.setattr(threads, "available_cores", lambda: 4)
    assert [parts_for(w, 100) for w in (0, 99, 100, 250, 399, 400, 10**9)] == [1, 1, 1, 2, 3, 4, 4]
    monkeypatch.setattr(threads, "available_cores", lambda: 1)
    assert parts_for(10**9, 100) == 1


def test_a_solve_counts_while_under_way_and_shares_the_cores() -> None:
    """Every core with no solve or one under way, the cores split among more (at least
    one each), the count released when a solve ends, also by an exception."""
    cores = available_cores()
    assert cores_per_solve() == cores
    with solving():
        assert cores_per_solve() == cores
        with solving():
            assert cores_per_solve() == max(1, cores // 2)
            with pytest.raises(RuntimeError), solving():
                assert cores_per_solve() == max(1, cores // 3)
                raise RuntimeError
            assert cores_per_solve() == max(1, cores // 2)
    assert cores_per_solve() == cores


def test_a_forked_child_runs_none_of_its_parents_solves() -> None:
    """A child forked while solves are under way counts none of them: its own solves
    may take every core (the count would otherwise never fall there)."""
    cores = available_cores()
    with solving(), solving():
        child = os.fork()
        if child == 0:  # the child: exit with what it reads
            os._exit(cores_per_solve())
        _, status = os.waitpid(child, 0)
    assert os.waitstatus_to_exitcode(status) == cores


@pytest.mark.parametrize(
    ("v2", "v1", "cores"),
    [
        ("100000 100000", None, 1),  # one CPU of quota
        ("150000 100000", None, 2),  # 1.5 CPUs: two threads may share them
        ("max 100000", None, None),  # no quota: the affinity
        (None, ("50000", "100000"), 1),  # cgroup v1
        (None, ("-1", "100000"), None),  # v1, no quota
        ("garbled", None, None),  # unreadable: the affinity
        (None, None, None),  # no cgroup files
    ],
)
def test_the_cores_available_are_the_affinity_capped_by_the_cgroup_quota(
    v2: str | None,
    v1: tuple[str, str] | None,
    cores: int | None,
    tmp_path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The affinity's cores, capped by a cgroup v2 or v1 CPU quota rounded up where one is
    set and readable (``cores`` None: the affinity alone)."""
    affinity = len(os.sched_getaffinity(0))
    v2_file = tmp_path / "cpu.max"
    quota_file, period_file = tmp_path / "cfs_quota_us", tmp_path / "cfs_period_us"
    if v2 is not None:
        v2_file.write_text(v2 + "\n")
    if v1 is not None:
        quota_file.write_text(v1[0] + "\n")
        period_file.write_text(v1[1] + "\n")
    monkeypatch.setattr(threads, "CGROUP_V2_CPU_MAX", v2_file)
    monkeypatch.setattr(threads, "CGROUP_V1_CPU", (quota_file, period_file))
    assert available_cores() == min(affinity, cores if cores is not None else affinity)
