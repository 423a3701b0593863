"""``python -m service`` (or ``coordination-scheduler``): serve the API with uvicorn."""

from __future__ import annotations

import logging

import uvicorn

from service.settings import get_settings


def main() -> None:
    """Serve ``service.main:app`` on the configured host and port."""
    settings = get_settings()
    logging.basicConfig(
        level=settings.log_level.upper(), format="%(asctime)s %(levelname)s %(name)s: %(message)s"
    )
    uvicorn.run(
        "service.main:app", host=settings.host, port=settings.port, log_level=settings.log_level
    )


if __name__ == "__main__":
    main()
