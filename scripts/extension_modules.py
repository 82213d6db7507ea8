"""Load every shared library of an environment and import every extension module; print
what loads and what imports.

The Docker build strips the wheels' shared libraries of their symbol tables (about 70 MB).
Run before and after, this proves the stripping broke nothing: the two lists must be equal
(``diff`` fails the build otherwise). What fails even before (an optional backend whose
system library is missing, a library that needs another loaded first) is on neither list,
so it does not count.

Usage::

    python scripts/extension_modules.py >before.txt
    find "$VENV" -name "*.so*" -type f -exec strip --strip-unneeded {} +
    python scripts/extension_modules.py | diff before.txt -
"""

from __future__ import annotations

import ctypes
import importlib
import os
import subprocess
import sys
import sysconfig
from pathlib import Path


def extension_modules(root: Path) -> list[str]:
    """Dotted names of the extension modules under ``root`` (site-packages)."""
    names = []
    for path in sorted(root.rglob("*.so")):
        rel = path.relative_to(root)
        if rel.parts[0].endswith((".libs", ".dist-info", ".data")):  # bundled libraries
            continue
        stem = rel.name.split(".", 1)[0]
        names.append(".".join((*rel.parts[:-1], stem)))
    return names


def check(item: str) -> bool:
    """True when ``item`` works: a path loads with dlopen, a dotted name imports."""
    try:
        if item.startswith("/"):
            ctypes.CDLL(item)
        else:
            importlib.import_module(item)
    except BaseException:  # noqa: BLE001 - any failure means "does not work"
        return False
    return True


def main() -> int:
    root = Path(sysconfig.get_paths()["purelib"])
    items = [str(p) for p in sorted(root.rglob("*.so*")) if p.is_file()]
    items += extension_modules(root)
    # Batches of 50 in child interpreters: a crash (a segfault in a broken library) ends only
    # its batch, whose remaining modules then count as not importing, which the diff shows.
    # Each imported module is reported on a line of its own, marked: imports may print too.
    code = ("import sys\nfrom extension_modules import check\n"
            "for n in sys.argv[1:]:\n    if check(n): print('@ok', n, flush=True)\n")
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parent)}
    ok: list[str] = []
    for start in range(0, len(items), 50):
        run = subprocess.run([sys.executable, "-c", code, *items[start:start + 50]],
                             capture_output=True, text=True, env=env)
        ok += [line.split()[1] for line in run.stdout.splitlines() if line.startswith("@ok ")]
    print("\n".join(sorted(ok)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
