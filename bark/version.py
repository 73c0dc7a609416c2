"""bark's version and the provenance of a run: the installed distribution's version (the release
tag's, else the one written in VERSION: ``tools/bark_build.py``), the git commit of the source that
ran and whether it had uncommitted changes."""

from __future__ import annotations

import functools
import subprocess
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

DISTRIBUTION = "bark-grasstree"
"""The distribution's name in the Python Package Index (the import package is ``bark``)."""

try:
    __version__ = version(DISTRIBUTION)
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0+unknown"

__all__ = ["__version__", "DISTRIBUTION", "source_commit", "session", "provenance"]


@functools.lru_cache(maxsize=1)
def source_commit() -> tuple[str | None, bool | None]:
    """``(commit, dirty)`` of the source bark runs from: read from git when the package sits in a
    git checkout (an editable install), else the commit the build put in the version (a wheel
    built between tags: ``...+gCOMMIT``), else ``(None, None)``.  Asked once a process."""
    here = Path(__file__).resolve().parent
    try:
        head = subprocess.run(["git", "-C", str(here), "rev-parse", "HEAD"], capture_output=True, text=True, timeout=10)
        if head.returncode == 0:
            status = subprocess.run(["git", "-C", str(here), "status", "--porcelain", "--untracked-files=no", "--",
                                     ":/bark", ":/plugins", ":/cli"],
                                    capture_output=True, text=True, timeout=10)
            return head.stdout.strip(), (bool(status.stdout.strip()) if status.returncode == 0 else None)
    except (OSError, subprocess.SubprocessError):  # no git here, or it hung
        pass
    local = __version__.partition("+")[2]
    commit = next((part[1:] for part in local.split(".") if part.startswith("g") and len(part) > 7), None)
    return commit, (local.endswith(".dirty") or ".d" in local) if commit else None


def session(command: str | None = None) -> dict:
    """This process's part of a run: its ``command`` line (default: the process's, a script as run)
    and when it started, UTC."""
    import shlex
    import sys
    from datetime import datetime, timezone

    return {"command": shlex.join(sys.argv) if command is None else command,
            "started": datetime.now(timezone.utc).isoformat(timespec="seconds")}


def provenance(sessions: list[dict]) -> dict:
    """What summary.json says made a run: bark's version, the git commit of its source (and whether
    that had uncommitted changes), and each process that ran part of it (``session``: the first
    started it, each later one resumed it)."""
    commit, dirty = source_commit()
    return {"bark_version": __version__, "commit": commit, "dirty": dirty, "sessions": list(sessions)}
