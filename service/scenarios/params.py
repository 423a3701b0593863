"""Keyword parameters of a generator, split among the parameter dataclasses that own them."""

from __future__ import annotations

import dataclasses
from typing import Any

__all__ = ["split_params"]


def split_params(params: dict[str, Any], *classes: type[Any]) -> tuple[Any, ...]:
    """One instance of each dataclass in ``classes``, built from the keys it declares.

    Why: generators take flat ``**params`` (handy on a command line and in a kind
    registry) but validate them in typed dataclasses; an unknown key is a typo,
    so it raises ``TypeError`` rather than being ignored.
    """
    known: set[str] = set()
    built = []
    for cls in classes:
        names = {f.name for f in dataclasses.fields(cls)}
        known |= names
        built.append(cls(**{k: v for k, v in params.items() if k in names}))
    unknown = sorted(set(params) - known)
    if unknown:
        raise TypeError(f"unknown parameter(s): {', '.join(unknown)}")
    return tuple(built)
