# CPU-only image of the coordination scheduler (shipped models included).
FROM python:3.11-slim

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    SCHEDULER_HOST=0.0.0.0 \
    SCHEDULER_PORT=8000 \
    SCHEDULER_MODEL_STORE=/app/model_store \
    NUMBA_CACHE_DIR=/tmp/numba-cache

WORKDIR /app
# CPU build of torch first, so the project's torch==2.13.0 pin never pulls a CUDA build.
RUN pip install --index-url https://download.pytorch.org/whl/cpu torch==2.13.0

COPY pyproject.toml README.md ./
COPY service ./service
COPY bench ./bench
RUN pip install . && useradd --create-home --uid 10001 scheduler
COPY model_store ./model_store
COPY schemas ./schemas

USER scheduler
EXPOSE 8000
HEALTHCHECK --interval=15s --timeout=3s --start-period=60s --retries=3 \
    CMD python -c "import urllib.request; urllib.request.urlopen('http://127.0.0.1:8000/healthz', timeout=2)"
CMD ["uvicorn", "service.main:app", "--host", "0.0.0.0", "--port", "8000"]
