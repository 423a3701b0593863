# CPU-only image of the coordination scheduler (shipped models included).
#
# deploy/build-image.sh builds it with podman where no image registry is reachable: it
# makes BASE from Debian packages (debootstrap) and downloads every wheel into
# deploy/wheels first, so this build needs neither a registry nor a package index.
# BASE needs python3 (3.11) with venv; python:3.11-slim-bookworm works too.
ARG BASE=python:3.11-slim-bookworm
FROM ${BASE}

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    PATH=/opt/venv/bin:$PATH \
    SCHEDULER_HOST=0.0.0.0 \
    SCHEDULER_PORT=8000 \
    SCHEDULER_MODEL_STORE=/app/model_store \
    NUMBA_CACHE_DIR=/tmp/numba-cache

WORKDIR /app
# The project and every dependency as wheels (CPU torch among them), installed offline:
# no CUDA build of torch can sneak in, and the wheels stay out of the image's layers.
RUN --mount=type=bind,source=deploy/wheels,target=/wheels \
    python3 -m venv /opt/venv \
    && pip install --no-index --find-links /wheels coordination-scheduler \
    && useradd --create-home --uid 10001 scheduler
COPY model_store ./model_store
COPY schemas ./schemas

USER scheduler
EXPOSE 8000
HEALTHCHECK --interval=15s --timeout=3s --start-period=60s --retries=3 \
    CMD python -c "import os, urllib.request; urllib.request.urlopen(f\"http://127.0.0.1:{os.environ['SCHEDULER_PORT']}/healthz\", timeout=2)"
# python -m service reads SCHEDULER_HOST, SCHEDULER_PORT, SCHEDULER_LOG_LEVEL and the rest.
CMD ["python", "-m", "service"]
