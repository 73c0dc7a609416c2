"""Opening a file a user names: only a regular file is read.

A name can be a FIFO (reading it waits for a writer that never comes), a device (``/dev/zero``
streams forever), a socket or a folder.  :func:`open_regular` opens without waiting
(``O_NONBLOCK``) and refuses anything but a regular file, in the words of :func:`what_it_is`; every
reader of user files goes through it, so no input can hang a command.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import BinaryIO

__all__ = ["NotARegularFile", "is_zip", "open_regular", "what_it_is"]

ZIP_MAGIC = (b"PK\x03\x04", b"PK\x05\x06")
"""How a zip archive (an ``.npz``) begins: a member, or the end record of an empty one."""

_KINDS = ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISSOCK, "a socket"),
          (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"))


class NotARegularFile(OSError):
    """The path names something other than a regular file; ``str()`` says what it is."""


def what_it_is(mode: int) -> str:
    """A file type (``os.stat(...).st_mode``) in words: ``"a FIFO (named pipe)"``, ``"a folder"``, ..."""
    return next((name for test, name in _KINDS if test(mode)), "not a regular file")


def open_regular(path: str | Path) -> BinaryIO:
    """``path`` opened for reading in binary, if it is a regular file (links followed); else
    :class:`NotARegularFile` (an ``OSError``) saying what it is, at once — a FIFO is never waited on.
    ``FileNotFoundError`` and ``PermissionError`` as ``open`` raises them."""
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise NotARegularFile(f"it is {what_it_is(mode)}, not a file")
        if hasattr(os, "set_blocking"):
            os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def is_zip(fh: BinaryIO) -> bool:
    """Whether the open file ``fh`` begins as a zip archive (an ``.npz`` does); read from its start,
    left at its start.  A file that does not is refused before numpy would try it as a pickle."""
    fh.seek(0)
    head = fh.read(4)
    fh.seek(0)
    return head in ZIP_MAGIC
