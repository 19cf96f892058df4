"""Following a file that grows: bounded reads from where the last one stopped.

A :class:`FileTail` never re-reads what it has read: each :meth:`FileTail.read_lines` reads at
most ``max_bytes`` from the saved offset and returns the whole lines found (a torn last line
waits for the next read). A file that shrank or was replaced (a new run in the same folder)
is read again from the start, and :attr:`FileTail.restarted` says so.
"""

from __future__ import annotations

import csv
import os
from pathlib import Path

#: Bytes read from one file in one call at most.
MAX_BYTES = 256 * 1024


class FileTail:
    """Incremental reader of a text file of lines.

    Parameters
    ----------
    path : Path
    max_bytes : int
        Upper bound of one read.
    """

    def __init__(self, path: Path, max_bytes: int = MAX_BYTES) -> None:
        self.path = path
        self.max_bytes = max_bytes
        self.offset = 0
        self.restarted = False
        self._ino: int | None = None
        self._rest = b""

    def pending(self) -> bool:
        """True when the file holds bytes not read yet."""
        try:
            st = os.stat(self.path)
        except OSError:
            return False
        return st.st_ino != self._ino or st.st_size != self.offset

    def read_lines(self) -> list[str]:
        """The whole lines added since the last call (at most ``max_bytes`` read).

        A missing file gives no lines. Lines are decoded as UTF-8 (bad bytes replaced) and
        returned without their newline.
        """
        self.restarted = False
        try:
            st = os.stat(self.path)
        except OSError:
            return []
        if self._ino is not None and (st.st_ino != self._ino or st.st_size < self.offset):
            self.offset, self._rest, self.restarted = 0, b"", True
        self._ino = st.st_ino
        if st.st_size <= self.offset:
            return []
        with open(self.path, "rb") as fh:
            fh.seek(self.offset)
            data = fh.read(min(self.max_bytes, st.st_size - self.offset))
        self.offset += len(data)
        data = self._rest + data
        cut = data.rfind(b"\n")
        if cut < 0:
            self._rest = data
            return []
        self._rest = data[cut + 1 :]
        return data[:cut].decode("utf-8", errors="replace").splitlines()


class CsvTail:
    """A :class:`FileTail` over a CSV file with a header line: rows as dicts."""

    def __init__(self, path: Path, max_bytes: int = MAX_BYTES) -> None:
        self.tail = FileTail(path, max_bytes)
        self.header: list[str] | None = None

    @property
    def path(self) -> Path:
        return self.tail.path

    def pending(self) -> bool:
        return self.tail.pending()

    def read_rows(self) -> list[dict[str, str]]:
        """The rows added since the last call (the header is read once, again after a
        restart)."""
        lines = self.tail.read_lines()
        if self.tail.restarted:
            self.header = None
        if not lines:
            return []
        if self.header is None:
            self.header = next(csv.reader([lines[0]]))
            lines = lines[1:]
        return [dict(zip(self.header, row)) for row in csv.reader(lines) if row]


def file_mtime(path: Path) -> float | None:
    """Modification time of ``path``, None when it does not exist."""
    try:
        return os.stat(path).st_mtime
    except OSError:
        return None
