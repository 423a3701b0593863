"""Work cut into parts for the shared pool: balanced cuts and results in order."""

from __future__ import annotations

import os
import threading

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from service.core.threads import balanced_cuts, cores_per_solve, in_parts, parts_for, solving


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
    monkeypatch.setattr(os, "cpu_count", lambda: 4)
    assert [parts_for(w, 100) for w in (0, 99, 100, 250, 399, 400, 10**9)] == [1, 1, 1, 2, 3, 4, 4]
    monkeypatch.setattr(os, "cpu_count", lambda: None)
    assert parts_for(10**9, 100) == 1


def test_a_solve_counts_while_under_way_and_shares_the_cores() -> None:
    """Every core with no solve or one under way, the cores split among more (at least
    one each), the count released when a solve ends, also by an exception."""
    cores = os.cpu_count() or 1
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
    cores = os.cpu_count() or 1
    with solving(), solving():
        child = os.fork()
        if child == 0:  # the child: exit with what it reads
            os._exit(cores_per_solve())
        _, status = os.waitpid(child, 0)
    assert os.waitstatus_to_exitcode(status) == cores
