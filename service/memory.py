"""How the service uses CPython's cyclic garbage collector.

Requests allocate ~10^5-10^6 container objects at 250 robots (wire bodies, graph
requests, answers). With CPython's default thresholds every 25 % of growth of the
long-lived objects starts a full collection that walks all of them: 7-8 full
collections, 0.2-0.3 s, inside one 250-robot paths request (measured through the
app, warehouses of 250 robots). Two policies keep that off the latency path:

* :func:`settle`, once the process has warmed up: what lives now (models, compiled
  kernels, the app) is frozen out of the collector's reach, and full collections wait
  for FULL_AFTER young-generation collections instead of 10 (same request: 1-2 full
  collections, 0.04-0.12 s of collection in all);
* :func:`collection_deferred` around a latency-critical call (a re-schedule within a
  100 ms budget): no automatic collection inside it at all.
"""

from __future__ import annotations

import gc
import threading
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["FULL_AFTER", "collection_deferred", "settle"]

# Collections of the middle generation before a full one may run (CPython: 10).
FULL_AFTER = 100

_gc_lock = threading.Lock()
_gc_depth = 0  # calls inside collection_deferred, all threads
_gc_was_enabled = False


@contextmanager
def collection_deferred() -> Iterator[None]:
    """Run the block without automatic garbage collection, then restore it.

    A 250-robot re-schedule allocates ~10^5 container objects (the previous
    assignment's entries, the answer's), which triggered a full collection on nearly
    every call; each walks every live object of the process (in the disturbance
    benchmark, its planned worlds): 20-400 ms pauses inside a 100 ms budget. Deferred,
    the collection runs after the answer, between re-schedules. Nested and concurrent
    calls are counted, so collection resumes when the last one leaves.
    """
    global _gc_depth, _gc_was_enabled
    with _gc_lock:
        if _gc_depth == 0:
            _gc_was_enabled = gc.isenabled()
            gc.disable()
        _gc_depth += 1
    try:
        yield
    finally:
        with _gc_lock:
            _gc_depth -= 1
            if _gc_depth == 0 and _gc_was_enabled:
                gc.enable()


def settle() -> None:
    """Freeze everything alive now and make full collections rarer (see the module).

    Garbage is collected first: a cycle frozen while unreachable would never be freed.
    """
    gc.collect()
    gc.freeze()
    young, middle, _ = gc.get_threshold()
    gc.set_threshold(young, middle, FULL_AFTER)
