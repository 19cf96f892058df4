"""Import pybullet without its build-time banner on standard output.

pybullet's C module prints "pybullet build time: ..." to file descriptor 1 when it
is first imported, which would corrupt machine-readable output (``--json``).
Importing it once through :func:`load` silences that; later imports reuse the module.
"""
from __future__ import annotations

import ctypes
import os
import sys
from types import ModuleType


def load() -> ModuleType:
    """Import and return pybullet, with fd 1 pointed at /dev/null during the import."""
    if "pybullet" in sys.modules:
        return sys.modules["pybullet"]
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 1)
            import pybullet

            ctypes.CDLL(None).fflush(None)  # C stdio buffers the banner
    finally:
        os.dup2(saved, 1)
        os.close(saved)
    return pybullet
