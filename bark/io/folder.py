"""The output folder of a run: checked before anything runs, held by one run at a time, never mixed.

Opening a folder for a run, before the simulation takes its first step:

1. **Checked**: a name the file system can hold (no NUL, no part over ``NAME_MAX`` bytes), created
   with its parents if missing, a folder (not a file), and writable (a probe file is written, synced
   and removed) — so a run can never end in a folder it cannot write.
2. **Locked**: an exclusive ``flock`` on the folder itself, held until the run's last file is
   written.  A second run into the same folder is refused in one line.  The lock is the kernel's, so
   a run killed by SIGKILL leaves no stale lock behind, and no lock file in the folder.
3. **Cleaned of stale temporary files**: every file is written to a temporary name and moved into
   place; a run killed in the middle of a write leaves its temporary behind, and the next run into
   the folder removes it (safe: the lock says no other run is writing).
4. **Never mixed**: a fresh run into a folder holding another run's files replaces them, all at
   once, before it starts — unless that run is *unfinished* (its checkpoint was written along the
   way or on a signal), which is refused: go on with it (``--resume``) or discard it
   (``--overwrite``).  Only bark's own file names are removed; anything else in the folder stays.
"""

from __future__ import annotations

import errno
import os
import tempfile
from pathlib import Path
from typing import Callable

from bark.io.checkpoint import CHECKPOINT_NAME, PREVIOUS_NAME, Damaged, read_meta
from bark.errors import BarkError, Ref
from bark.io.files import TMP_SUFFIX, temp_name_prefix
from bark.model.effects import EFFECTS, PICTURE_FORMATS, in_format

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX: no locking
    fcntl = None

__all__ = ["RUN_FILES", "OutputFolder", "held_folder", "holds_a_run", "writable_folder"]

RUN_FILES = ("summary.json", "scene.toml", "report.html", "analysis-*.csv",
             *dict.fromkeys(in_format(f, fmt) for effect in EFFECTS.values() for f in effect.files
                            for fmt in PICTURE_FORMATS))
"""Every file a run may write: summary.json, scene.toml, the report ``bark report`` writes about it, its
analyzers' tables (``analysis-<analyzer>-<table>.csv``) and
each effect's files in every picture format (``Effect.files``; a
name may be a pattern in a folder of the run's, such as the history's ``history/tree-*.vtu``).  A fresh
run removes these (and only these) from its folder."""


def holds_a_run(path: Path) -> bool:
    """Whether the folder ``path`` holds a run of ``bark simulate`` (begun, ended or stopped)."""
    return any((path / name).is_file() for name in ("summary.json", "scene.toml", CHECKPOINT_NAME, "state.npz",
                                                    "breaks.csv"))


def run_files(path: Path) -> list[Path]:
    """The files of ``RUN_FILES`` in the folder ``path``."""
    return [f for name in RUN_FILES for f in (path.glob(name) if "*" in name else [path / name]) if f.is_file()]
PROBE = "bark-probe"


def _short(text: str, limit: int = 60) -> str:
    return text if len(text) <= limit else text[: limit - 1] + "…"


class OutputFolder:
    """A folder opened for one run: checked, created, locked and cleaned (see the module's docstring).
    Use as a context manager; closing releases the lock."""

    def __init__(self, path: Path, fd: int | None) -> None:
        self.path = path
        self._fd = fd

    @classmethod
    def open(cls, path: str | Path, *, fresh: bool, overwrite: bool = False, key: str = "out",
             notice: Callable[[str], None] | None = None) -> "OutputFolder":
        """Open ``path`` for a fresh run (``fresh=True``: created if missing, other runs' files
        replaced) or for resuming the run in it.  ``key`` names the setting in messages (``out``,
        ``resume``).  Raises a one-line :class:`BarkError`."""
        path = Path(path)
        ref = Ref(None, key, str(path))

        def fail(problem: str, *more: Ref) -> BarkError:
            return BarkError("{0}: " + problem, ref, *more)

        _check_name(path, fail)
        created = []
        if fresh:
            missing = [p for p in (path, *path.parents) if not p.exists()]
            _make_folder(path, fail)
            created = missing
        if not path.exists():
            raise fail("no such folder")
        if not path.is_dir():
            raise fail("exists and is not a folder")
        fd = None
        try:
            fd = _lock(path, fail)
            _probe(path, fail)
            _remove_stale_temporaries(path)
            if fresh:
                _clear_for_fresh_run(path, overwrite, fail, notice)
        except BaseException:
            if fd is not None:
                os.close(fd)
            for p in created:  # leave nothing behind for a run that never started
                try:
                    p.rmdir()
                except OSError:
                    break
            raise
        return cls(path, fd)

    def close(self) -> None:
        """Release the folder's lock (another command may then write into it)."""
        if self._fd is not None:
            os.close(self._fd)  # releases the flock
            self._fd = None

    def __enter__(self) -> "OutputFolder":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _make_folder(path: Path, fail) -> None:
    """``path`` made a folder (with its parents), or ``fail`` saying in the user's terms why it
    cannot be one: a file, a symbolic link that loops, leads nowhere or to a file."""
    if path.is_symlink():
        try:
            os.stat(path)
        except OSError as err:
            target = os.readlink(path)
            if err.errno == errno.ELOOP:
                raise fail(f"is a symbolic link that loops ({target!r})") from None
            raise fail(f"is a symbolic link to {target!r}, which does not exist") from None
    if path.exists() and not path.is_dir():
        raise fail(("is a symbolic link to a file" if path.is_symlink() else "is a file") + ", not a folder")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise fail("is not a folder") from None
    except OSError as err:
        raise fail(f"cannot create it ({err.strerror or err})") from None


def writable_folder(path: str | Path, key: str = "out") -> Path:
    """``path`` checked, created if missing and probed for writing, for outputs that are not a run's
    (benchmarks): no lock, nothing removed.  One-line :class:`BarkError` naming ``key`` if unusable."""
    path = Path(path)
    ref = Ref(None, key, str(path))

    def fail(problem: str) -> BarkError:
        return BarkError("{0}: " + problem, ref)

    _check_name(path, fail)
    _make_folder(path, fail)
    if not path.is_dir():
        raise fail("exists and is not a folder")
    _probe(path, fail)
    return path


def held_folder(path: str | Path, key: str = "out") -> OutputFolder:
    """:func:`writable_folder`, locked as a run's folder is (an exclusive ``flock`` on the folder,
    released when the returned :class:`OutputFolder` closes): one bark command at a time writes
    there — a second sweep into a sweep's folder, or two analyses into one, is refused in one line
    that names the command holding it, instead of both writing."""
    folder = writable_folder(path, key)
    return OutputFolder(folder, _lock(folder, lambda problem: BarkError("{0}: " + problem, Ref(None, key, str(path)))))


def _check_name(path: Path, fail) -> None:
    text = str(path)
    if "\0" in text:
        raise fail("a folder name cannot contain a NUL character")
    try:
        raw = os.fsencode(text)
    except UnicodeError:
        raise fail("the name cannot be encoded for this file system") from None
    name_max = 255
    try:
        anchor = next(p for p in (path, *path.parents) if p.exists())
        name_max = os.pathconf(anchor, "PC_NAME_MAX")
    except (StopIteration, OSError, ValueError):
        pass
    for part in path.parts:
        if len(os.fsencode(part)) > name_max:
            raise fail(f"the name {_short(part)!r} is longer than the {name_max} bytes a folder name may have here")
    if len(raw) > 4000:
        raise fail(f"the path is {len(raw)} bytes long; this file system takes at most 4096")


def _lock(path: Path, fail) -> int | None:
    if fcntl is None:  # pragma: no cover
        return None
    fd = os.open(path, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        holder = _holder(path)
        raise fail(f"{holder or 'another bark command'} is writing there; wait for it to end, or choose another "
                   f"folder") from None
    except OSError:  # a file system without flock: go on unlocked
        pass
    return fd


def _holder(path: Path) -> str | None:
    """The command holding the lock on the folder ``path``, as its user typed it (``bark sweep ...``,
    process N), read from Linux's ``/proc/locks`` and the holder's command line; ``None`` where
    that cannot be known (another system, a process of another user)."""
    try:
        st = os.stat(path)
        key = f"{os.major(st.st_dev):02x}:{os.minor(st.st_dev):02x}:{st.st_ino}"
        with open("/proc/locks") as fh:
            pids = [int(f[4]) for f in (line.split() for line in fh) if len(f) > 5 and f[1] == "FLOCK" and f[5] == key]
        if not pids:
            return None
        argv = Path(f"/proc/{pids[0]}/cmdline").read_bytes().decode(errors="replace").split("\0")[:-1]
    except (OSError, ValueError, IndexError):
        return None
    words = [os.path.basename(argv[0]) if argv else "?"] + argv[1:]
    if "bark_cli" in words:  # python -m bark_cli simulate ...: the command as typed, bark simulate ...
        words = ["bark", *words[words.index("bark_cli") + 1:]]
    elif len(words) > 1 and os.path.basename(words[1]) == "bark":  # python .../bin/bark simulate ...
        words = words[1:]
    words[0] = os.path.basename(words[0])
    command = " ".join(" ".join(words).split())  # one line, whatever the arguments held
    return f"{command if len(command) <= 80 else command[:79] + '…'} (process {pids[0]})"


def _probe(path: Path, fail) -> None:
    try:
        fd, name = tempfile.mkstemp(prefix=temp_name_prefix(PROBE), suffix=TMP_SUFFIX, dir=path)
        try:
            os.write(fd, b"bark")
            os.fsync(fd)
        finally:
            os.close(fd)
            os.unlink(name)
    except OSError as err:
        raise fail(f"cannot write there ({err.strerror or err})") from None


def _remove_stale_temporaries(path: Path) -> None:
    """Temporary files of earlier runs killed in the middle of a write (we hold the lock: none is ours),
    in the folder and in its folders a run writes into."""
    names = [Path(name) for name in (*RUN_FILES, PROBE)]
    for folder in {n.parent for n in names}:
        # a name's temporaries start with its prefix; a pattern's, with the prefix of the part before its *
        prefixes = tuple(temp_name_prefix(n.name)[: temp_name_prefix(n.name).index("*")] if "*" in n.name
                         else temp_name_prefix(n.name) for n in names if n.parent == folder)
        if not (path / folder).is_dir():
            continue
        for entry in (path / folder).iterdir():
            if entry.name.startswith(prefixes) and entry.name.endswith(TMP_SUFFIX) and entry.is_file():
                entry.unlink(missing_ok=True)


def _clear_for_fresh_run(path: Path, overwrite: bool, fail, notice) -> None:
    present = run_files(path)
    if not present:
        return
    if not overwrite:
        for name in (CHECKPOINT_NAME, PREVIOUS_NAME):
            if not (path / name).is_file():
                continue
            try:
                meta = read_meta(path / name)
            except Damaged as err:
                raise fail(f"holds a checkpoint that cannot be read ({err}); discard it with {{1}}",
                           Ref(None, "overwrite", True)) from None
            if meta.get("reason") != "end":
                t = meta.get("t")
                when = "its start: no checkpoint of its state yet" if meta.get("reason") == "start" else \
                    f"t = {t:.6g}" if isinstance(t, (int, float)) else "a run"
                raise fail(f"holds an unfinished run (stopped at {when}): go on with it ({{1}}), or discard it with {{2}}",
                           Ref(None, "resume", str(path)), Ref(None, "overwrite", True))
            break
    for file in present:
        file.unlink(missing_ok=True)
    if notice is not None:
        notice(f"replaced the earlier run's files in {str(path)!r}")
