"""The garbage-collection policies: deferred collection and the settled process."""

from __future__ import annotations

import gc
import threading
import weakref

import pytest

from service.memory import FULL_AFTER, collection_deferred, settle


@pytest.mark.parametrize("enabled", [True, False])
def test_collection_deferred_restores_the_collector(enabled: bool) -> None:
    """Paused inside (nested too), restored after, also when the block raises."""
    was = gc.isenabled()
    (gc.enable if enabled else gc.disable)()
    try:
        with pytest.raises(KeyError), collection_deferred():
            assert not gc.isenabled()
            with collection_deferred():
                assert not gc.isenabled()
            assert not gc.isenabled()
            raise KeyError("boom")
        assert gc.isenabled() == enabled
    finally:
        (gc.enable if was else gc.disable)()


def test_collection_resumes_when_the_last_concurrent_call_leaves() -> None:
    """Two threads overlap: the first to leave must not resume collection under the other."""
    assert gc.isenabled()
    inside, leave_first, first_left = threading.Event(), threading.Event(), threading.Event()
    seen: list[bool] = []

    def first() -> None:
        with collection_deferred():
            inside.set()
            leave_first.wait(5)
        first_left.set()

    def second() -> None:
        inside.wait(5)
        with collection_deferred():
            leave_first.set()
            first_left.wait(5)
            seen.append(gc.isenabled())

    threads = [threading.Thread(target=first), threading.Thread(target=second)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(10)
    assert seen == [False] and gc.isenabled()


def test_settle_freezes_what_lives_and_makes_full_collections_rarer() -> None:
    before, frozen = gc.get_threshold(), gc.get_freeze_count()
    alive = [[k] for k in range(1000)]  # tracked containers alive at settle time
    try:
        settle()
        assert gc.get_freeze_count() >= frozen + len(alive)
        assert gc.get_threshold() == (before[0], before[1], FULL_AFTER)
    finally:
        gc.unfreeze()
        gc.set_threshold(*before)


def test_settle_collects_garbage_before_freezing() -> None:
    class Node:
        pass

    before = gc.get_threshold()
    cycle = Node()
    cycle.me = cycle  # unreachable once deleted: only the cyclic collector frees it
    ref = weakref.ref(cycle)
    del cycle
    gc.disable()
    try:
        settle()
        assert ref() is None
    finally:
        gc.enable()
        gc.unfreeze()
        gc.set_threshold(*before)
