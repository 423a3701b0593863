"""A small typed client of the scheduler's HTTP API (httpx), for fleet back ends and scripts.

Example::

    from service.client import ScheduleClient

    with ScheduleClient("http://127.0.0.1:8000", token=None) as client:
        answer = client.schedule(request)  # a dict: the JSON answer of POST /v1/schedules

A 503 (saturated, or warming up) is retried after its ``Retry-After`` (seconds),
at most ``max_attempts`` attempts in all and never waiting past ``retry_budget_s``
from the first attempt; then :class:`ServiceUnavailable`. A 4xx raises
:class:`RequestRejected` with the status and the API's ``detail`` (a message, or
for 422 the list of ``{"loc", "msg", "type"}``).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from types import TracebackType
from typing import Any

import httpx

__all__ = ["RequestRejected", "ScheduleClient", "SchedulerError", "ServiceUnavailable"]

JsonObject = dict[str, Any]
# Wait for a 503 without Retry-After (the service always sends one; a proxy may not).
DEFAULT_RETRY_AFTER_S = 1.0


class SchedulerError(Exception):
    """A non-2xx answer: its HTTP status and the API's ``detail``."""

    def __init__(self, status: int, detail: Any) -> None:
        super().__init__(f"{status}: {detail}")
        self.status = status
        self.detail = detail


class RequestRejected(SchedulerError):
    """A 4xx: the request is at fault (401 token, 413 too large, 422 invalid); do not retry."""


class ServiceUnavailable(SchedulerError):
    """A 5xx, or a 503 still answered after the retry budget was spent."""


class ScheduleClient:
    """Client of one scheduler; a context manager (closes its connections)."""

    def __init__(
        self,
        base_url: str,
        token: str | None = None,
        timeout: float = 60.0,
        max_attempts: int = 5,
        retry_budget_s: float = 30.0,
        transport: httpx.BaseTransport | None = None,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        """Args:
        base_url: e.g. ``http://127.0.0.1:8000``.
        token: the service's ``SCHEDULER_API_TOKEN``, sent as a bearer token.
        timeout: per request, in seconds (a solve may take its time limit and more).
        max_attempts: attempts in all when answered 503.
        retry_budget_s: no retry would start later than this after the first attempt.
        transport: an httpx transport (tests; default: the network).
        sleep: how to wait ``Retry-After`` seconds (tests).
        """
        headers = {"authorization": f"Bearer {token}"} if token else {}
        self._http = httpx.Client(
            base_url=base_url, headers=headers, timeout=timeout, transport=transport
        )
        self._max_attempts = max(1, max_attempts)
        self._retry_budget_s = retry_budget_s
        self._sleep = sleep

    def schedule(self, body: JsonObject) -> JsonObject:
        """``POST /v1/schedules``: the schedule of a graph- or paths-form request."""
        return self._post("/v1/schedules", body)

    def coordination_graph(self, body: JsonObject) -> JsonObject:
        """``POST /v1/coordination-graphs``: the coordination graph robot paths make."""
        return self._post("/v1/coordination-graphs", body)

    def simulate(self, body: JsonObject) -> JsonObject:
        """``POST /v1/simulations``: play back trajectories or execute a dependency plan."""
        return self._post("/v1/simulations", body)

    def health(self) -> JsonObject:
        """``GET /healthz``: ``{"status": "ok"}`` while the process runs."""
        return _json_or_raise(self._http.get("/healthz"))

    def ready(self) -> JsonObject:
        """``GET /readyz``: the readiness report (``ready`` false while warming up, no error)."""
        response = self._http.get("/readyz")
        return response.json() if response.status_code == 503 else _json_or_raise(response)

    def _post(self, path: str, body: JsonObject) -> JsonObject:
        """POST ``body``, retrying 503s after ``Retry-After`` within the attempts and budget."""
        deadline = time.monotonic() + self._retry_budget_s
        for attempt in range(1, self._max_attempts + 1):
            response = self._http.post(path, json=body)
            if response.status_code != 503 or attempt == self._max_attempts:
                break
            wait = retry_after_s(response)
            if time.monotonic() + wait > deadline:
                break
            self._sleep(wait)
        return _json_or_raise(response)

    def close(self) -> None:
        """Close the connections."""
        self._http.close()

    def __enter__(self) -> ScheduleClient:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()


def retry_after_s(response: httpx.Response) -> float:
    """The response's ``Retry-After`` in seconds (a number; else the default)."""
    try:
        return max(0.0, float(response.headers["retry-after"]))
    except (KeyError, ValueError):
        return DEFAULT_RETRY_AFTER_S


def _json_or_raise(response: httpx.Response) -> JsonObject:
    """The JSON body of a 2xx; else the typed error with the status and ``detail``."""
    if response.is_success:
        return response.json()
    try:
        content = response.json()
    except ValueError:
        content = None
    detail = (
        content["detail"] if isinstance(content, dict) and "detail" in content else response.text
    )
    error = RequestRejected if response.is_client_error else ServiceUnavailable
    raise error(response.status_code, detail)
