"""The learning package reads datasets without the solvers: the arrows point one way."""

from __future__ import annotations

import subprocess
import sys


def test_training_does_not_import_the_solvers() -> None:
    code = (
        "import sys, service.learning.train; "
        "print(sorted(m for m in sys.modules if m.startswith('service.solvers')))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout
    assert out.strip() == "[]"
