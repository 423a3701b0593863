"""The cached property: once per instance, no lock shared between instances, one value
kept when two threads compute it at once."""

from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import pytest

from service.core.lazy import cached_property


@dataclass(frozen=True, eq=False)
class _Held:
    """A frozen instance whose property meets ``barrier`` (if any) while computing."""

    barrier: threading.Barrier | None = None
    calls: list[int] = field(default_factory=list)

    @cached_property
    def value(self) -> list[int]:
        """A new list each computation (so identity tells computations apart)."""
        self.calls.append(1)
        if self.barrier is not None:
            self.barrier.wait(timeout=5.0)
        return [len(self.calls)]


def test_computed_once_and_stored_on_a_frozen_instance() -> None:
    held = _Held()
    first = held.value
    assert held.value is first and held.__dict__["value"] is first and len(held.calls) == 1
    assert (
        _Held.value.__doc__ == "A new list each computation (so identity tells computations apart)."
    )


def test_two_instances_compute_at_once() -> None:
    """Both computations must be inside the property together to pass the barrier: a lock
    shared by the class (functools' in Python 3.11) breaks it."""
    barrier = threading.Barrier(2)
    pair = [_Held(barrier), _Held(barrier)]
    with ThreadPoolExecutor(2) as pool:
        values = list(pool.map(lambda held: held.value, pair))
    assert values == [[1], [1]]


def test_one_instance_asked_by_two_threads_keeps_the_first_value() -> None:
    held = _Held(threading.Barrier(2))
    with ThreadPoolExecutor(2) as pool:
        first, second = pool.map(lambda _: held.value, range(2))
    assert len(held.calls) == 2  # both computed (no lock) ...
    assert first is second is held.value  # ... and both got the one value stored


def test_functools_property_of_this_python_serializes_instances() -> None:
    """Why the module exists: on Python 3.11 the functools descriptor's lock is shared."""
    import functools
    import sys

    if sys.version_info >= (3, 12):
        pytest.skip("functools.cached_property has no lock from Python 3.12 on")

    class Locked:
        def __init__(self, barrier: threading.Barrier) -> None:
            self.barrier = barrier

        @functools.cached_property
        def value(self) -> int:
            self.barrier.wait(timeout=0.5)
            return 1

    barrier = threading.Barrier(2)
    with ThreadPoolExecutor(2) as pool, pytest.raises(threading.BrokenBarrierError):
        list(pool.map(lambda held: held.value, [Locked(barrier), Locked(barrier)]))
