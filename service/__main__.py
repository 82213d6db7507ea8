"""``python -m service``: run the service with uvicorn on CURVATURE_HOST:CURVATURE_PORT."""

from __future__ import annotations

import logging
import socket
import sys

# Only light imports up here: the refusals below must come before numpy, numba and FastAPI
# are loaded (seconds on a small machine).
from .auth import KeyConfigError, check_exposure, load_keyring
from .datalock import DataDirBusy, DataDirLock
from .settings import Settings

log = logging.getLogger("service")

# Exit statuses (sysexits.h): the configuration forbids starting (EX_CONFIG), the port cannot
# be bound (EX_OSERR), another server holds the data folder (EX_TEMPFAIL: retry once it is
# gone), uvicorn's own start-up failed.
EXIT_CONFIG = 78
EXIT_BIND = 71
EXIT_DATA_BUSY = 75
EXIT_STARTUP = 3


def bind(host: str, port: int) -> socket.socket:
    """A listening TCP socket on ``host:port`` (IPv6 when ``host`` is an IPv6 address)."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind((host, port))
        sock.listen(2048)
    except BaseException:
        sock.close()
        raise
    return sock  # not inheritable: no child may keep the port after the server is gone


def main() -> None:
    """Start the embedded default: SQLite job store and local pool under CURVATURE_DATA_DIR.

    In this order, so that a refusal leaves everything untouched: check the API keys (exit
    status 78 when they cannot be read, or when there are none and the host is not a loopback
    address, unless ``CURVATURE_ALLOW_OPEN=true``), bind the port (71 when it cannot be
    bound), lock the data folder (75 when another server holds it, naming its pid); only
    then load the numeric code, open the store and start the workers.
    """
    settings = Settings()
    logging.basicConfig(level=settings.log_level.upper(),
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    try:
        refusal = check_exposure(settings, load_keyring(settings))
    except KeyConfigError as exc:
        refusal = f"cannot load the API keys: {exc}"
    if refusal is not None:
        log.critical(refusal)
        sys.exit(EXIT_CONFIG)
    try:
        sock = bind(settings.host, settings.port)
    except OSError as exc:
        log.critical("cannot listen on %s port %d: %s", settings.host, settings.port,
                     exc.strerror or exc)
        sys.exit(EXIT_BIND)
    try:
        lock = DataDirLock.acquire(settings.data_dir)
    except DataDirBusy as exc:
        log.critical("refusing to start: %s", exc)
        sys.exit(EXIT_DATA_BUSY)
    except OSError as exc:
        log.critical("cannot lock the data folder %s: %s", settings.data_dir, exc)
        sys.exit(EXIT_CONFIG)
    import uvicorn

    from .app import create_app
    from .http_guard import guarded_protocol
    from .upload_gate import FD_HEADROOM, raise_fd_limit

    app = create_app(settings)
    app.state.data_lock = lock
    # One server process per data dir (the lock above): the store's queue is not shared.
    # Not limit_concurrency: it counts stalled connections too, and would refuse everyone.
    # Stalled connections hold a descriptor each: keep them to a quarter of what is left
    # after the headroom the upload gate keeps for the store and the pool.
    fd_share = max(16, (raise_fd_limit() - FD_HEADROOM) // 4)
    protocol = guarded_protocol(settings.header_timeout_seconds, settings.max_header_bytes,
                                min(settings.max_pending_connections, fd_share))
    server = uvicorn.Server(uvicorn.Config(
        app, log_level=settings.log_level, workers=1, http=protocol,
        timeout_keep_alive=settings.keep_alive_timeout_seconds))
    server.run(sockets=[sock])
    if not server.started:
        sys.exit(EXIT_STARTUP)


if __name__ == "__main__":
    main()
