# syntax=docker/dockerfile:1
# Curvature REST service: embedded SQLite job store + local process pool, data in /data.
#   docker build -t curvature-service .
#   docker run -p 8000:8000 -v curvature-data:/data -e CURVATURE_API_KEYS=<key1>,<key2> \
#       curvature-service
# The image listens on 0.0.0.0, so it refuses to start without API keys (exit status 78):
# give CURVATURE_API_KEYS, or CURVATURE_API_KEYS_FILE pointing at a mounted secret (one key a
# line), or set CURVATURE_ALLOW_OPEN=true to run it open on purpose.

# --- build: install the package, its service and dask extras into a virtualenv ------------
FROM python:3.11-slim AS build
ENV PIP_NO_CACHE_DIR=1 PIP_DISABLE_PIP_VERSION_CHECK=1
RUN python -m venv /opt/venv
ENV PATH=/opt/venv/bin:$PATH
WORKDIR /src
COPY pyproject.toml README.md ./
COPY curvature ./curvature
COPY service ./service
COPY curvature_client ./curvature_client
# dask: the same image runs the Dask scheduler and workers of docker-compose's "dask" profile
RUN pip install --upgrade pip && pip install ".[service,dask]"

# --- runtime: the virtualenv only, run as an unprivileged user -----------------------------
FROM python:3.11-slim AS runtime
RUN groupadd --system --gid 10001 curvature \
    && useradd --system --uid 10001 --gid curvature --home-dir /home/curvature \
       --create-home --shell /usr/sbin/nologin curvature \
    && mkdir -p /data && chown curvature:curvature /data
COPY --from=build /opt/venv /opt/venv
# The site-packages are read-only for the service user, so numba keeps its compiled-kernel
# cache on the data volume (compiled once per volume, not once per container start).
ENV PATH=/opt/venv/bin:$PATH \
    PYTHONUNBUFFERED=1 \
    PYTHONDONTWRITEBYTECODE=1 \
    NUMBA_CACHE_DIR=/data/numba-cache \
    CURVATURE_HOST=0.0.0.0 \
    CURVATURE_PORT=8000 \
    CURVATURE_DATA_DIR=/data
USER curvature
WORKDIR /home/curvature
VOLUME ["/data"]
EXPOSE 8000
HEALTHCHECK --interval=30s --timeout=5s --start-period=60s --retries=3 \
    CMD ["python", "-c", "import os, urllib.request; urllib.request.urlopen('http://127.0.0.1:' + os.environ.get('CURVATURE_PORT', '8000') + '/healthz', timeout=4)"]
CMD ["python", "-m", "service"]
