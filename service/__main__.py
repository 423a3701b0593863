"""``python -m service`` (or ``coordination-scheduler``): serve the API with uvicorn.

Every log line, uvicorn's included, is one JSON object (``service.api.request_log``);
uvicorn's own access log is off: the service writes one richer line per request.
"""

from __future__ import annotations

import logging

import uvicorn

from service.api.request_log import JsonFormatter
from service.settings import get_settings


def configure_logging(level: str) -> None:
    """One JSON object per line on stderr, for every logger, at ``level``."""
    handler = logging.StreamHandler()
    handler.setFormatter(JsonFormatter())
    logging.basicConfig(level=level.upper(), handlers=[handler], force=True)


def main() -> None:
    """Serve ``service.main:app`` on the configured host and port."""
    settings = get_settings()
    configure_logging(settings.log_level)
    uvicorn.run(
        "service.main:app",
        host=settings.host,
        port=settings.port,
        log_level=settings.log_level,
        log_config=None,  # keep the JSON handler above for uvicorn's loggers too
        access_log=False,
    )


if __name__ == "__main__":
    main()
