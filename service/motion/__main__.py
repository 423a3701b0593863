"""``python -m service.motion``: answer a saved paths-form request offline, as the service would.

Example::

    python -m service.scenarios --kind wh_two_lane --robots 12 --seed 0 \\
        --out world.json --request req.json
    python -m service.motion --request req.json --out resp.json --solver exact --time-limit 5
    python -m service.pictures --request req.json --response resp.json --world world.json \\
        --out pictures/

The learned models are read from ``--model-store`` (default: the shipped store);
without them the GNN-VAE solvers fall back to the exact solver, as in the service.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from service.core.path_schemas import PathsRequest
from service.core.schemas import OBJECTIVES, SOLVER_NAMES
from service.geometry.graph import GeometrySettings
from service.motion.plan import plan_paths
from service.settings import DEFAULT_MODEL_STORE
from service.solvers.dispatch import DispatchPolicy

__all__ = ["main"]


def main(argv: list[str] | None = None) -> int:
    """Plan the request, print a summary line, write the answer."""
    parser = argparse.ArgumentParser(
        prog="python -m service.motion",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--request", type=Path, required=True, help="paths-form request body")
    parser.add_argument("--out", type=Path, required=True, help="where the answer goes (JSON)")
    parser.add_argument("--solver", choices=SOLVER_NAMES, help="overrides the request's")
    parser.add_argument("--time-limit", type=float, help="seconds; overrides the request's")
    parser.add_argument("--model-store", type=Path, default=DEFAULT_MODEL_STORE)
    args = parser.parse_args(argv)
    body = json.loads(args.request.read_text())
    options = body.setdefault("options", {})
    if args.solver:
        options["solver"] = args.solver
    if args.time_limit:
        options["time_limit_s"] = args.time_limit
    from service.learning.store import load_all  # torch is imported only when planning

    models, _ = load_all(args.model_store, OBJECTIVES)
    planned = plan_paths(
        PathsRequest.model_validate(body), DispatchPolicy(models=models), GeometrySettings()
    )
    args.out.write_bytes(planned.content)
    answer = planned.response
    print(
        f"{answer.solver.name}: cost {answer.cost:.3f} ({answer.objective}), "
        f"collision free {answer.checks.collision_free}, "
        f"min clearance {answer.checks.min_clearance_m} m, {answer.timings}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
