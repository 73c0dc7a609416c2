"""Files written atomically: CSV, JSON, npz, anything through ``atomic_write``.

Every file is written to a temporary name in the same folder and moved into place with
``os.replace``, so a reader (or a crash) never sees half a file.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import math
import os
import tempfile
import zipfile
from pathlib import Path
from typing import Any, Callable

import numpy as np

__all__ = ["atomic_write", "attempt", "write_csv", "write_columns", "write_json", "write_npz"]



def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


_UMASK = _umask()


TMP_SUFFIX = ".tmp"


def temp_name_prefix(name: str) -> str:
    """The prefix of the temporary files :func:`atomic_write` makes for a file called ``name``."""
    return f".{name}."


def atomic_write(path: str | Path, write: Callable[[io.BufferedWriter], None], *,
                 verify: Callable[[Path], None] | None = None, keep: str | Path | None = None,
                 by_name: bool = False) -> Path:
    """Call ``write(fh)`` on a temporary file beside ``path``, then move it onto ``path``.

    ``by_name``: ``write`` is given the temporary file's path instead (for writers that open files
    themselves, like meshio's VTU writer).  ``verify(tmp)``, if given, is called on the written
    temporary file before it replaces anything (it raises to refuse it).  ``keep``, if given, is where
    the file being replaced goes (moved, not copied), so that the previous version survives until the
    new one is whole and verified."""
    path = Path(path)
    try:
        fd, tmp = tempfile.mkstemp(prefix=temp_name_prefix(path.name), suffix=TMP_SUFFIX, dir=path.parent)
    except OSError as err:
        err.filename = str(path)  # the file the user knows, not the hidden temporary
        raise
    try:
        os.chmod(tmp, 0o666 & ~_UMASK)  # mkstemp makes 0600; give the file the usual permissions
        if by_name:
            os.close(fd)
            write(Path(tmp))
            fd = os.open(tmp, os.O_RDONLY)
        with os.fdopen(fd, "rb" if by_name else "wb") as fh:
            if not by_name:
                write(fh)
                fh.flush()
            os.fsync(fh.fileno())
        if verify is not None:
            verify(Path(tmp))
        if keep is not None and path.exists():
            os.replace(path, keep)
        os.replace(tmp, path)
    except BaseException as err:
        Path(tmp).unlink(missing_ok=True)
        if isinstance(err, OSError) and err.filename in (None, tmp, Path(tmp)):
            err.filename = str(path)  # the file the user knows, not the hidden temporary
        raise
    _sync_folder(path.parent)
    return path


def attempt(name: str, write: Callable[[], Any], failed: list[str] | None, stale: tuple[Path, ...] = ()) -> bool:
    """Write one output with ``write()``.  With ``failed`` given, a file system that refuses it (a
    full disk or quota, a file-size limit, a read-only folder) is said as ``"name: could not be
    written (why)"`` in ``failed`` and the caller goes on with its other outputs; nothing of the
    refused file is written (``atomic_write``), and its earlier versions ``stale`` are removed, so a
    folder never holds an output of another state beside this one's.  Returns whether it was written."""
    if failed is None:
        write()
        return True
    try:
        write()
        return True
    except OSError as err:
        failed.append(f"{name}: could not be written ({err.strerror or err})")
        for path in stale:
            try:
                Path(path).unlink(missing_ok=True)
            except OSError:
                pass
        return False


def _sync_folder(folder: Path) -> None:
    """Make the renames in ``folder`` durable (a crash after this keeps them)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def write_csv(path: str | Path, rows: list[dict[str, Any]], columns: list[str], header: list[str] | None = None) -> Path:
    """A CSV of ``rows`` (dicts; keys not in ``columns`` left out, missing ones empty), headed
    ``header`` (default: ``columns``; ``bark.units.headed`` adds their units)."""
    return _write_rows(path, header or columns, ([row.get(c, "") for c in columns] for row in rows))


def write_columns(path: str | Path, columns: dict[str, list], header: list[str] | None = None) -> Path:
    """A CSV of equal-length ``columns`` (name: values), as :func:`write_csv` writes the same rows,
    with no dict made per row (a break log has tens of thousands)."""
    return _write_rows(path, header or list(columns), zip(*columns.values()))


def _write_rows(path: str | Path, header: list[str], rows) -> Path:
    def write(fh):
        text = io.TextIOWrapper(fh, encoding="utf-8", newline="")
        w = csv.writer(text)
        w.writerow(header)
        w.writerows(rows)
        text.flush()
        text.detach()

    return atomic_write(path, write)


def _jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def json_text(obj: Any, indent: int | None = None) -> str:
    """``obj`` as strict JSON (what SQLite's ``json_extract`` and other readers accept): numpy
    scalars as numbers, NaN and infinities as ``null``."""
    return json.dumps(_jsonable(obj), indent=indent, allow_nan=False)


def write_json(path: str | Path, obj: Any) -> Path:
    """Write ``obj`` to ``path`` as indented JSON (NaN and infinities as null), atomically: a reader sees the old
    file or the whole new one; returns the path."""
    data = json_text(obj, indent=2).encode() + b"\n"
    return atomic_write(path, lambda fh: fh.write(data))


def _fast_deflate(info: zipfile.ZipInfo) -> None:
    """Deflate level 1: on float arrays about as small as the default level 6 and faster (measured
    at 2 million bases), which is what a large run's final write waits on."""
    if hasattr(info, "compress_level"):  # Python >= 3.13
        info.compress_level = 1
    else:
        info._compresslevel = 1


def write_npz(path: str | Path, *, compress: bool = True, verify=None, keep=None, **arrays: np.ndarray) -> Path:
    """``np.savez_compressed`` layout (``compress=False``: ``np.savez``'s), but byte-for-byte
    reproducible: every member carries the same fixed timestamp, so two identical states give
    identical files (``cmp`` can compare runs).  ``verify`` and ``keep`` as in :func:`atomic_write`."""
    method = zipfile.ZIP_DEFLATED if compress else zipfile.ZIP_STORED

    def write(fh):
        with zipfile.ZipFile(fh, "w", compression=method) as zf:
            for name, value in arrays.items():
                value = np.asanyarray(value)
                if not value.flags.c_contiguous:  # files are row-major whatever the layout in memory
                    value = np.ascontiguousarray(value)
                info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
                info.compress_type = method
                _fast_deflate(info)
                with zf.open(info, "w", force_zip64=True) as member:
                    np.lib.format.write_array(member, value, allow_pickle=False)

    return atomic_write(path, write, verify=verify, keep=keep)


@contextlib.contextmanager
def sqlite_reader(path: str | Path):
    """A read-only connection to the SQLite file ``path`` that leaves the folder as it found it:
    reading a database in WAL mode makes SQLite create ``-wal`` and ``-shm`` files beside it, which
    a read-only connection cannot remove; those this one made (the ``-wal`` empty: nothing was
    written) are removed once it is closed."""
    import sqlite3

    path = Path(path)
    sidecars = [path.with_name(path.name + suffix) for suffix in ("-wal", "-shm")]
    there = {p for p in sidecars if p.exists()}
    con = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
    try:
        yield con
    finally:
        con.close()
        wal = sidecars[0]
        if wal not in there and (not wal.exists() or wal.stat().st_size == 0):
            for p in sidecars:
                if p not in there:
                    p.unlink(missing_ok=True)
