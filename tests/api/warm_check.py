"""Run as ``python -m tests.api.warm_check``: the service's warm-up in a fresh interpreter,
then requests it did not see; prints (JSON) every compiled-kernel signature those
requests added, which on a cold numba cache each cost a compile of seconds inside a
timed request. ``test_warm_up.py`` runs it and expects none."""

from __future__ import annotations

import json
from pathlib import Path

from service.api.runtime import build_runtime, compiled_signatures, solve_every_way, warm_up
from service.core.path_schemas import PathsRequest
from service.geometry.graph import GeometrySettings
from service.motion.plan import derived_request, plan_paths
from service.scenarios import generate
from service.settings import Settings

MODEL_STORE = Path(__file__).resolve().parents[2] / "model_store"
# Worlds unlike the warm-up's (kind, robots, seed), solved by every solver (auto under
# policies that reach each of its stages) and in the paths form.
WORLDS = (("wh_two_lane", 40, 1), ("wh_parked", 12, 1), ("floor_dense", 12, 3), ("wh_mixed", 20, 1))


def main() -> int:
    runtime = build_runtime(Settings(model_store=MODEL_STORE))
    warm_up(runtime)
    if not runtime.ready:
        print(json.dumps({"not ready": runtime.detail}))
        return 1
    worlds = [generate(*world) for world in WORLDS]  # the generator's kernels: no request's
    before = compiled_signatures()
    for world in worlds:
        solve_every_way(derived_request(world), runtime.policy, 0.2)
        paths = PathsRequest.model_validate(world.to_request())
        plan_paths(paths, runtime.policy, GeometrySettings())
    after = compiled_signatures()
    added = {k: sorted(v - before.get(k, set())) for k, v in after.items()}
    print(json.dumps({k: v for k, v in added.items() if v}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
