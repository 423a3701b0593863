"""Worker threads for numba kernels that release the GIL: one pool per process.

A kernel compiled with ``nogil=True`` runs on its own core when called from another
thread. Callers cut their work into parts (:func:`balanced_cuts`), run the first part
themselves and the others on the shared pool (:func:`in_parts`), and join the results
in order. On this 2-core machine the gain is less than half (parts are uneven, the
cores share memory bandwidth): the narrow phase of 0.88 M boxes 125 -> 103 ms (least of
20), a 437,000-constraint plan 55 -> 50 ms (medians 87 -> 57). Work run on the pool must
never wait for other work on the pool (with every thread waiting, it would wait for
ever); callers that wait are never pool threads.

Solves count themselves as under way (:func:`solving`) so that a search that can use
more threads takes the cores no other solve of the process holds (:func:`cores_per_solve`):
a lone request gets the whole machine, two at once on two cores one core each.
"""

from __future__ import annotations

import math
import os
import threading
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from pathlib import Path
from typing import TypeVar

import numpy as np

__all__ = [
    "available_cores",
    "balanced_cuts",
    "cores_per_solve",
    "in_parts",
    "parts_for",
    "shared_pool",
    "solving",
]

A = TypeVar("A")
T = TypeVar("T")

# The pool of this process (rebuilt in a forked child, which inherits the pool but not
# its threads), and the lock that guards building it.
_pool: tuple[int, ThreadPoolExecutor] | None = None
_pool_lock = threading.Lock()


# Where a cgroup states this process's CPU quota: v2 ("<quota> <period>" or "max <period>"),
# v1 (quota, -1 for none, and period in two files).
CGROUP_V2_CPU_MAX = Path("/sys/fs/cgroup/cpu.max")
CGROUP_V1_CPU = (
    Path("/sys/fs/cgroup/cpu/cpu.cfs_quota_us"),
    Path("/sys/fs/cgroup/cpu/cpu.cfs_period_us"),
)


def available_cores() -> int:
    """The cores this process may run on: those of its CPU affinity, fewer where a cgroup's
    CPU quota allows less (a container limited to 2 CPUs on a 64-core host: 2, where
    ``os.cpu_count()`` says 64 and threads sized by it would each get a thirty-second)."""
    if hasattr(os, "sched_getaffinity"):
        cores = len(os.sched_getaffinity(0))
    else:
        cores = os.cpu_count() or 1
    quota = _cgroup_quota()
    if quota is not None:
        cores = min(cores, math.ceil(quota))
    return max(1, cores)


def _cgroup_quota() -> float | None:
    """CPUs the cgroup quota allows (quota over period), None where none is set or read."""
    try:
        if CGROUP_V2_CPU_MAX.exists():
            quota, period = CGROUP_V2_CPU_MAX.read_text().split()[:2]
            return None if quota == "max" else int(quota) / int(period)
        quota_file, period_file = CGROUP_V1_CPU
        if quota_file.exists() and period_file.exists():
            quota_us = int(quota_file.read_text())
            return None if quota_us <= 0 else quota_us / int(period_file.read_text())
    except (OSError, ValueError):
        return None
    return None


def shared_pool() -> ThreadPoolExecutor:
    """This process's pool (threads are started on demand, up to the core count)."""
    global _pool
    with _pool_lock:
        if _pool is None or _pool[0] != os.getpid():
            pool = ThreadPoolExecutor(available_cores(), thread_name_prefix="kernel")
            _pool = (os.getpid(), pool)
        return _pool[1]


# Solves under way in this process (:func:`solving`), and the lock that guards the count.
_solves = 0
_solves_lock = threading.Lock()


def _no_solves() -> None:
    """A forked child runs none of its parent's solves."""
    global _solves
    _solves = 0


os.register_at_fork(after_in_child=_no_solves)


@contextmanager
def solving() -> Iterator[None]:
    """Count one solve as under way while the block runs (see :func:`cores_per_solve`)."""
    global _solves
    with _solves_lock:
        _solves += 1
    try:
        yield
    finally:
        with _solves_lock:
            _solves -= 1


def cores_per_solve() -> int:
    """This process's cores shared among its solves under way (:func:`solving`; none
    counts as one), at least one: a search reads it again as it goes, so that a request
    arriving while another searches on every core gets its share from the next turn on."""
    with _solves_lock:
        running = max(_solves, 1)
    return max(1, available_cores() // running)


def parts_for(work: int, least_work: int) -> int:
    """How many parts ``work`` is worth cutting into: one per core at most, and none
    smaller than ``least_work`` (below it, handing a part over costs more than it saves)."""
    return max(1, min(available_cores(), work // max(least_work, 1)))


def balanced_cuts(weight: np.ndarray, parts: int, allowed: np.ndarray | None = None) -> list[int]:
    """Bounds ``[0, c_1, ..., len(weight)]`` of ``parts`` consecutive parts of about equal
    total ``weight`` (W,), each inner cut at the first ``allowed`` position (sorted
    indices in (0, W); default every one) at or after its share. Parts may be empty."""
    size = int(weight.size)
    if parts <= 1 or size == 0:
        return [0, size]
    before = np.concatenate([[0], np.cumsum(weight)])  # (W+1,) weight before each index
    shares = before[-1] * np.arange(1, parts) / parts  # (parts-1,)
    ideal = np.searchsorted(before, shares, side="left")  # first index with that much before
    if allowed is None:
        inner = ideal
    else:  # the first allowed position at or after each, or the end
        ends = np.append(allowed, size)
        inner = ends[np.searchsorted(allowed, ideal, side="left")]
    return [0, *np.clip(inner, 0, size).tolist(), size]


def in_parts(run: Callable[[A], T], args: Sequence[A]) -> list[T]:
    """``run`` of each of ``args`` (at least one), in order: the first here, the others on
    the shared pool at the same time."""
    others = [shared_pool().submit(run, arg) for arg in args[1:]]
    first = run(args[0])
    return [first, *(f.result() for f in others)]
