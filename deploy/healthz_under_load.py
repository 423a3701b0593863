"""Measure ``/healthz`` latency while solves saturate a running service (bounded, stops itself).

``python deploy/healthz_under_load.py --url http://127.0.0.1:8000 --seconds 30``

``--clients`` clients post the mid-size example (20 robots, ~60 conflicts) with
``--solver`` back to back, more than the solve slots plus the queue, so the
service is saturated (some posts get 503 with Retry-After: counted, not errors);
meanwhile one client polls ``/healthz`` every ``--interval`` seconds. Prints
the probe latency percentiles and the posts' status counts as JSON.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import time
from collections import Counter
from pathlib import Path
from typing import Any

import httpx
import numpy as np

MID = Path(__file__).resolve().parents[1] / "schemas" / "examples" / "mid.json"


async def post_loop(
    client: httpx.AsyncClient, body: dict[str, Any], until: float, statuses: Counter[int]
) -> None:
    """Post ``body`` back to back until ``until``, counting statuses."""
    while time.monotonic() < until:
        response = await client.post("/v1/schedules", json=body)
        statuses[response.status_code] += 1
        if response.status_code == 503:
            await asyncio.sleep(float(response.headers.get("retry-after", "1")))


async def probe_loop(client: httpx.AsyncClient, until: float, interval: float) -> list[float]:
    """``/healthz`` latencies (s), one probe every ``interval`` seconds until ``until``."""
    latencies = []
    while time.monotonic() < until:
        start = time.perf_counter()
        response = await client.get("/healthz")
        latencies.append(time.perf_counter() - start)
        response.raise_for_status()
        await asyncio.sleep(interval)
    return latencies


async def measure(args: argparse.Namespace) -> dict[str, Any]:
    """Run the load and the probes side by side; their figures."""
    body = json.loads(MID.read_text())
    body["options"] = {"solver": args.solver, "time_limit_s": args.time_limit_s}
    statuses: Counter[int] = Counter()
    until = time.monotonic() + args.seconds
    limits = httpx.Limits(max_connections=args.clients + 2)
    timeout = httpx.Timeout(args.time_limit_s * 10 + 30)
    async with (
        httpx.AsyncClient(base_url=args.url, limits=limits, timeout=timeout) as posts,
        httpx.AsyncClient(base_url=args.url, timeout=timeout) as probes,
    ):
        loops = [post_loop(posts, body, until, statuses) for _ in range(args.clients)]
        latencies, *_ = await asyncio.gather(probe_loop(probes, until, args.interval), *loops)
    ms = np.array(latencies) * 1000
    return {
        "probes": len(ms),
        "healthz_ms": {q: round(float(np.percentile(ms, int(q[1:]))), 2) for q in ("p50", "p99")},
        "healthz_max_ms": round(float(ms.max()), 2),
        "posts": dict(statuses),
    }


def main() -> None:
    """Parse the arguments, measure, print JSON."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--url", default="http://127.0.0.1:8000")
    parser.add_argument("--seconds", type=float, default=30.0)
    parser.add_argument("--clients", type=int, default=8)
    parser.add_argument("--solver", default="auto")
    parser.add_argument("--time-limit-s", type=float, default=2.0)
    parser.add_argument("--interval", type=float, default=0.02)
    print(json.dumps(asyncio.run(measure(parser.parse_args()))))


if __name__ == "__main__":
    main()
