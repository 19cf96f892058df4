"""The bridge that makes a Python robot process a node of the agent platform.

``dfrl.pybridge.errors`` and ``dfrl.pybridge.terms`` are plain Python. :class:`Bridge` (and
everything that needs the embedded SWI-Prolog) is imported on first use, so importing
``pybridge`` alone does not start Prolog.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from dfrl.pybridge.errors import (
    BridgeError,
    CodecError,
    NodeStateError,
    PrologError,
    PrologFailure,
    TermConversionError,
)
from dfrl.pybridge.terms import Atom, Blob, Term, Var

if TYPE_CHECKING:
    from dfrl.pybridge.codec import Codec
    from dfrl.pybridge.node import Bridge
    from dfrl.pybridge.providers import ParamsProvider, StaticParams, StaticTable, TableProvider

__all__ = [
    "BridgeError",
    "CodecError",
    "NodeStateError",
    "PrologError",
    "PrologFailure",
    "TermConversionError",
    "Atom",
    "Blob",
    "Term",
    "Var",
    "Codec",
    "Bridge",
    "TableProvider",
    "StaticTable",
    "ParamsProvider",
    "StaticParams",
]

_LAZY = {
    "Bridge": "dfrl.pybridge.node",
    "TableProvider": "dfrl.pybridge.providers",
    "StaticTable": "dfrl.pybridge.providers",
    "ParamsProvider": "dfrl.pybridge.providers",
    "StaticParams": "dfrl.pybridge.providers",
    "Codec": "dfrl.pybridge.codec",
}


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'pybridge' has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value
