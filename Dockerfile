# Curvature REST service: embedded SQLite job store + local process pool, data in /data.
#   docker build -t curvature-service .
#   docker run -p 8000:8000 -v curvature-data:/data -e CURVATURE_API_KEYS=<key1>,<key2> \
#       curvature-service
# The image listens on 0.0.0.0, so it refuses to start without API keys (exit status 78):
# give CURVATURE_API_KEYS, or CURVATURE_API_KEYS_FILE pointing at a mounted secret (one key a
# line), or set CURVATURE_ALLOW_OPEN=true to run it open on purpose.
# BASE_IMAGE: any Debian-like image with python3 (3.11+) and its venv module, e.g. one made by
# debootstrap and `docker import` where no registry is reachable (.ci/docker.sh does that).
ARG BASE_IMAGE=python:3.11-slim

# --- build: install the package, its service and dask extras into a virtualenv ------------
FROM ${BASE_IMAGE} AS build
# The numba cache is filled here, at build time, so a container is ready in seconds.
ENV PIP_NO_CACHE_DIR=1 PIP_DISABLE_PIP_VERSION_CHECK=1 NUMBA_CACHE_DIR=/opt/numba-cache
RUN python3 -m venv /opt/venv
ENV PATH=/opt/venv/bin:$PATH
WORKDIR /src
COPY pyproject.toml README.md ./
COPY curvature ./curvature
COPY service ./service
COPY curvature_client ./curvature_client
# dask: the same image runs the Dask scheduler and workers of docker-compose's "dask" profile.
# Test suites of the dependencies and pip itself are not needed to run; the warm-up after
# removing them compiles every kernel and proves the rest still imports.
RUN pip install ".[service,dask]" \
    && find /opt/venv/lib -depth -type d -path "*/site-packages/*" \
       \( -name tests -o -name test \) -exec rm -rf {} + \
    && (pip uninstall -y -q pip setuptools wheel 2>/dev/null || true)
# Out of /src from here on: there `python -m` would import the source copy, not the installed
# package, and numba would file the kernels under the copy's path, which the runtime lacks.
WORKDIR /
# numba's cache and kernels.warm check each source's modification time; copying between stages
# keeps whole seconds only, so the sources get a whole-second time before the warm-up.
RUN find /opt/venv/lib -path "*/site-packages/curvature/*" -name "*.py" \
        -exec touch -m -d @1700000000 {} + \
    && python -m curvature.warmup -q \
    && python -c "import curvature.warmup as w, service.app, distributed; \
assert w.cache_is_warm() and w.PACKAGE.is_relative_to('/opt/venv'), w.PACKAGE"

# --- runtime: the virtualenv and the compiled kernels, run as an unprivileged user ---------
FROM ${BASE_IMAGE} AS runtime
RUN groupadd --system --gid 10001 curvature \
    && useradd --system --uid 10001 --gid curvature --home-dir /home/curvature \
       --create-home --shell /usr/sbin/nologin curvature \
    && mkdir -p /data && chown curvature:curvature /data
COPY --from=build /opt/venv /opt/venv
# numba only uses a cache folder it can write to: owned by the service user.
COPY --from=build --chown=10001:10001 /opt/numba-cache /opt/numba-cache
ENV PATH=/opt/venv/bin:$PATH \
    PYTHONUNBUFFERED=1 \
    PYTHONDONTWRITEBYTECODE=1 \
    NUMBA_CACHE_DIR=/opt/numba-cache \
    CURVATURE_HOST=0.0.0.0 \
    CURVATURE_PORT=8000 \
    CURVATURE_DATA_DIR=/data
USER curvature
WORKDIR /home/curvature
VOLUME ["/data"]
EXPOSE 8000
HEALTHCHECK --interval=30s --timeout=5s --start-period=30s --retries=3 \
    CMD ["python", "-c", "import os, urllib.request; urllib.request.urlopen('http://127.0.0.1:' + os.environ.get('CURVATURE_PORT', '8000') + '/healthz', timeout=4)"]
CMD ["python", "-m", "service"]
