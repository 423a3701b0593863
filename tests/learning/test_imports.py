"""The learning package reads datasets without the solvers: the arrows point one way."""

from __future__ import annotations

from tests.imports import imported_modules


def test_training_does_not_import_the_solvers() -> None:
    assert imported_modules("service.learning.train", "service.solvers") == []
