"""``python -m service``: run the service with uvicorn on CURVATURE_HOST:CURVATURE_PORT."""

from __future__ import annotations

import logging
import sys

import uvicorn

from .app import create_app
from .auth import KeyConfigError, check_exposure, load_keyring
from .settings import Settings

log = logging.getLogger("service")

# Exit status when the configuration forbids starting (EX_CONFIG of sysexits.h).
EXIT_CONFIG = 78


def main() -> None:
    """Start the embedded default: SQLite job store and local pool under CURVATURE_DATA_DIR.

    Refuses to start (exit status 78, with the reason logged) when the API keys cannot be
    read, or when there are none and the host is not a loopback address, unless
    ``CURVATURE_ALLOW_OPEN=true``.
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
    # One server process per data dir: the store's queue is not shared between processes.
    uvicorn.run(create_app(settings), host=settings.host, port=settings.port,
                log_level=settings.log_level, workers=1)


if __name__ == "__main__":
    main()
