"""``python -m curvature`` runs the CLI."""

from .cli import main

raise SystemExit(main())
