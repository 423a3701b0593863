"""A cached property computed without a lock shared between instances.

:class:`functools.cached_property` of Python 3.11 computes under one lock per
property shared by every instance of the class (removed in 3.12 for that reason):
two requests building their solve contexts at once wait for each other. Measured
(session 31): a 16-robot context that takes 0.07 s alone took 1.04 s beside a
250-robot one (its cliques, orientation graph and decoder, ~1 s) built in another
thread. Here, as in Python 3.12, nothing is locked: different instances compute in
parallel (the numba kernels release the GIL). Two threads asking one instance for a
value it has not stored yet may both compute it; the first value stored is kept and
returned to both, so every reader sees one object.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Generic, TypeVar, overload

__all__ = ["cached_property"]

T = TypeVar("T")


class cached_property(Generic[T]):  # noqa: N801 (named after the functools descriptor it replaces)
    """Like :class:`functools.cached_property` (the value is stored in the instance's
    ``__dict__``, so frozen dataclasses work), without its class-wide lock."""

    def __init__(self, func: Callable[[Any], T]) -> None:
        self.func = func
        self.name = func.__name__
        self.__doc__ = func.__doc__

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    @overload
    def __get__(self, instance: None, owner: type | None = None) -> cached_property[T]: ...

    @overload
    def __get__(self, instance: object, owner: type | None = None) -> T: ...

    def __get__(self, instance: object | None, owner: type | None = None) -> Any:
        if instance is None:
            return self
        stored = instance.__dict__
        if self.name in stored:
            return stored[self.name]
        return stored.setdefault(self.name, self.func(instance))
