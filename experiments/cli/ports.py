"""What the commands say when the port they were told to bind is taken: the port, the address,
what probably holds it and what to do (one wording for ``dfrl robot``, ``view`` and
``run --view-port``; ``dfrl node`` says the same from Prolog,
``platform_errors.pl`` ``address_in_use``)."""

from __future__ import annotations

import errno


def port_in_use_text(host: str, port: int, holder: str, option: str) -> str:
    """``port 7001 on 127.0.0.1 is in use (another dfrl robot?); pick another --port ...``.

    Parameters
    ----------
    host, port : str, int
        The address that could not be bound.
    holder : str
        What probably holds it, e.g. ``"another dfrl robot"``.
    option : str
        The option that chooses the port, e.g. ``"--port"``.
    """
    return (
        f"port {port} on {host} is in use ({holder}?); pick another {option} "
        f"(0: the OS chooses one) or stop what holds it"
    )


def is_address_in_use(exc: BaseException) -> bool:
    """``exc`` is the OS refusing to bind an address another socket holds."""
    return isinstance(exc, OSError) and exc.errno == errno.EADDRINUSE
