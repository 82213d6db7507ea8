"""Write the service's OpenAPI document to openapi/openapi.json (or stdout).

Usage::

    python scripts/export_openapi.py            # writes openapi/openapi.json
    python scripts/export_openapi.py --stdout   # prints it

The formatting is deterministic (sorted keys, two-space indent, final newline) so the file
diffs cleanly; tests/service/test_openapi.py keeps it equal to the app's spec.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DEFAULT_OUTPUT = REPO / "openapi" / "openapi.json"


def render_openapi() -> str:
    """The app's OpenAPI document as deterministic JSON text."""
    if str(REPO) not in sys.path:  # allow running the script from anywhere
        sys.path.insert(0, str(REPO))
    from service.app import create_app

    spec = create_app().openapi()
    return json.dumps(spec, indent=2, sort_keys=True) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--stdout", action="store_true", help="print instead of writing")
    parser.add_argument("--output", type=Path, default=DEFAULT_OUTPUT,
                        help=f"file to write (default: {DEFAULT_OUTPUT.relative_to(REPO)})")
    args = parser.parse_args(argv)
    text = render_openapi()
    if args.stdout:
        sys.stdout.write(text)
    else:
        args.output.parent.mkdir(parents=True, exist_ok=True)
        args.output.write_text(text, encoding="utf-8")
        print(f"wrote {args.output}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
