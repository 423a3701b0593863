"""What importing a module pulls in, measured in a fresh interpreter (this one has it all)."""

from __future__ import annotations

import json
import subprocess
import sys


def imported_modules(module: str, prefix: str) -> list[str]:
    """The modules named ``prefix`` or ``prefix.*`` that ``import module`` loads."""
    wanted = f"(m + '.').startswith({prefix + '.'!r})"
    code = f"import json, sys, {module}; print(json.dumps([m for m in sys.modules if {wanted}]))"
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return json.loads(run.stdout)
