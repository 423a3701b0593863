"""Bounded loopback load on a running service: mixed sizes, latencies, rejections, server RSS.

``python deploy/load.py --url http://127.0.0.1:8000 --clients 8 --seconds 300 --pid <server pid>``

``--clients`` clients post back to back, each request drawn (seeded) from three
size classes: ``small`` (schemas/examples/tiny.json), ``mid`` (mid.json) and
``paths`` (schemas/examples/paths/wh_two_lane_12.json), weighted by ``--mix``.
The run stops by itself after ``--seconds`` or ``--max-requests`` posts,
whichever comes first. A 503 (saturated: Retry-After) is counted as a
rejection, and its client waits ``Retry-After``; any other non-200 or a
transport error is an error. Meanwhile the server's resident memory is read
from ``/proc/<pid>/status`` every ``--rss-interval`` seconds. Prints one JSON
object: throughput, p50/p99 per class, errors, rejections and the RSS samples.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import random
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx
import numpy as np

EXAMPLES = Path(__file__).resolve().parents[1] / "schemas" / "examples"
CLASSES = {
    "small": EXAMPLES / "tiny.json",
    "mid": EXAMPLES / "mid.json",
    "paths": EXAMPLES / "paths" / "wh_two_lane_12.json",
}
MIB = 1024 * 1024


@dataclass
class Tally:
    """What the clients observed, per size class."""

    latencies: dict[str, list[float]] = field(default_factory=lambda: {c: [] for c in CLASSES})
    rejected: dict[str, int] = field(default_factory=lambda: dict.fromkeys(CLASSES, 0))
    errors: dict[str, int] = field(default_factory=lambda: dict.fromkeys(CLASSES, 0))
    error_samples: list[str] = field(default_factory=list)
    sent: int = 0


def rss_mib(pid: int) -> float:
    """Resident set size of process ``pid`` in MiB (``VmRSS`` of ``/proc/<pid>/status``)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise ValueError(f"no VmRSS for pid {pid}")


async def sample_rss(pid: int, interval: float, until: float) -> list[tuple[float, float]]:
    """``(elapsed s, RSS MiB)`` of ``pid`` every ``interval`` seconds until ``until``."""
    start = time.monotonic()
    samples = []
    while (now := time.monotonic()) < until:
        samples.append((round(now - start, 1), round(rss_mib(pid), 1)))
        await asyncio.sleep(min(interval, max(0.0, until - now)))
    samples.append((round(time.monotonic() - start, 1), round(rss_mib(pid), 1)))
    return samples


async def client_loop(
    client: httpx.AsyncClient,
    bodies: dict[str, bytes],
    weights: Sequence[float],
    rng: random.Random,
    until: float,
    budget: int,
    tally: Tally,
) -> None:
    """Post requests drawn from ``bodies`` until ``until`` or ``budget`` posts in all."""
    names = list(bodies)
    while time.monotonic() < until and tally.sent < budget:
        tally.sent += 1
        name = rng.choices(names, weights)[0]
        start = time.perf_counter()
        try:
            response = await client.post("/v1/schedules", content=bodies[name])
        except httpx.TransportError as exc:
            tally.errors[name] += 1
            tally.error_samples.append(f"{name}: {type(exc).__name__}")
            continue
        if response.status_code == 200:
            tally.latencies[name].append(time.perf_counter() - start)
        elif response.status_code == 503 and "retry-after" in response.headers:
            tally.rejected[name] += 1
            await asyncio.sleep(float(response.headers["retry-after"]))
        else:
            tally.errors[name] += 1
            tally.error_samples.append(f"{name}: {response.status_code} {response.text[:200]}")


def rss_summary(samples: list[tuple[float, float]]) -> dict[str, Any]:
    """First, lowest, highest and last RSS (MiB) of ``samples``, and the samples themselves."""
    values = [mib for _, mib in samples]
    return {
        "first": values[0],
        "min": min(values),
        "max": max(values),
        "last": values[-1],
        "samples": " ".join(f"{t:g}s:{mib:g}" for t, mib in samples),
    }


def percentiles(latencies: list[float]) -> dict[str, Any]:
    """Count, p50 and p99 (seconds) of ``latencies``."""
    if not latencies:
        return {"ok": 0, "p50_s": None, "p99_s": None}
    p50, p99 = np.percentile(latencies, [50, 99])
    return {"ok": len(latencies), "p50_s": round(float(p50), 3), "p99_s": round(float(p99), 3)}


async def run(args: argparse.Namespace) -> dict[str, Any]:
    """Run the load (and the RSS sampler when ``--pid`` is given); the figures."""
    bodies = {name: path.read_bytes() for name, path in CLASSES.items()}
    tally = Tally()
    headers = {"content-type": "application/json"}
    if args.token:
        headers["authorization"] = f"Bearer {args.token}"
    limits = httpx.Limits(max_connections=args.clients)
    started = time.monotonic()
    until = started + args.seconds
    async with httpx.AsyncClient(
        base_url=args.url, headers=headers, limits=limits, timeout=args.timeout
    ) as client:
        loops = [
            client_loop(
                client,
                bodies,
                args.mix,
                random.Random(args.seed + i),
                until,
                args.max_requests,
                tally,
            )
            for i in range(args.clients)
        ]
        sampler = sample_rss(args.pid, args.rss_interval, until) if args.pid else asyncio.sleep(0)
        *_, rss = await asyncio.gather(*loops, sampler)
    elapsed = time.monotonic() - started
    answered = sum(len(v) for v in tally.latencies.values())
    return {
        "clients": args.clients,
        "seconds": round(elapsed, 1),
        "posts": tally.sent,
        "answered": answered,
        "throughput_per_s": round(answered / elapsed, 2),
        "classes": {
            name: {
                **percentiles(tally.latencies[name]),
                "rejected_503": tally.rejected[name],
                "errors": tally.errors[name],
            }
            for name in CLASSES
        },
        "error_samples": tally.error_samples[:10],
        "rss_mib": rss_summary(rss) if rss else None,
    }


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    """The command line; every count and duration is bounded."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--url", default="http://127.0.0.1:8000")
    parser.add_argument("--clients", type=int, default=8, choices=range(1, 65), metavar="1..64")
    parser.add_argument("--seconds", type=float, default=60.0, help="run length, at most 3600")
    parser.add_argument("--max-requests", type=int, default=100_000, help="posts in all")
    parser.add_argument(
        "--mix", type=float, nargs=3, default=(0.6, 0.3, 0.1), help="weights small mid paths"
    )
    parser.add_argument("--pid", type=int, help="server pid, for RSS sampling")
    parser.add_argument("--rss-interval", type=float, default=10.0)
    parser.add_argument("--timeout", type=float, default=120.0, help="per request, s")
    parser.add_argument("--token", help="bearer token (SCHEDULER_API_TOKEN)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    if not 0 < args.seconds <= 3600 or args.max_requests < 1:
        parser.error("--seconds must be in (0, 3600] and --max-requests positive")
    return args


def main() -> None:
    """Run the load and print its figures as JSON."""
    print(json.dumps(asyncio.run(run(parse_args())), indent=2))


if __name__ == "__main__":
    main()
