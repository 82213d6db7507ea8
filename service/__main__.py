"""``python -m service``: run the service with uvicorn on CURVATURE_HOST:CURVATURE_PORT."""

from __future__ import annotations

import logging

import uvicorn

from .app import create_app
from .settings import Settings


def main() -> None:
    """Start the embedded default: SQLite job store and local pool under CURVATURE_DATA_DIR."""
    settings = Settings()
    logging.basicConfig(level=settings.log_level.upper(),
                        format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    # One server process per data dir: the store's queue is not shared between processes.
    uvicorn.run(create_app(settings), host=settings.host, port=settings.port,
                log_level=settings.log_level, workers=1)


if __name__ == "__main__":
    main()
