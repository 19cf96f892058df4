"""Import pybullet without its build-time banner.

pybullet's C module prints "pybullet build time: ..." when it is first imported (to file
descriptor 1 or 2, depending on the build), which corrupts machine-readable output
(``--json``) and clutters every command. Importing it once through :func:`load` silences
that: during the import fd 1 goes to /dev/null and fd 2 to a temporary file, whose lines
other than the banner are written back to fd 2 (a real warning is never lost). Later imports
reuse the module.
"""

from __future__ import annotations

import ctypes
import os
import sys
import tempfile
from types import ModuleType

#: How the banner line starts.
BANNER = b"pybullet build time"


def load() -> ModuleType:
    """Import and return pybullet, its banner dropped (see the module doc)."""
    if "pybullet" in sys.modules:
        return sys.modules["pybullet"]
    for stream in (sys.stdout, sys.stderr):
        if stream is not None:
            stream.flush()
    saved = os.dup(1), os.dup(2)
    with tempfile.TemporaryFile() as caught, open(os.devnull, "wb") as null:
        try:
            os.dup2(null.fileno(), 1)
            os.dup2(caught.fileno(), 2)
            import pybullet

            ctypes.CDLL(None).fflush(None)  # C stdio buffers the banner
        finally:
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            for fd in saved:
                os.close(fd)
            caught.seek(0)
            rest = [
                ln for ln in caught.read().splitlines(keepends=True) if not ln.startswith(BANNER)
            ]
            if rest:
                os.write(2, b"".join(rest))
    return pybullet
