"""bark's build backend: setuptools' own (every hook), with the version chosen when it is imported.

The version is the release tag's (``vX.Y.Z``, read by setuptools-scm) when one reaches the
checkout.  Where none does — a clone made without tags, a copy of the tree — it is the version the
project writes down in ``VERSION``: that version exactly at the commit that last changed ``VERSION``
(the release), and its successor's development version, ``X.Y.(Z+1).devN+gHASH``, N commits later
(``.dirty`` with uncommitted changes).  Without git, setuptools-scm reads an sdist's PKG-INFO, and a
bare tree takes ``VERSION`` as it is.  A version the builder sets (``SETUPTOOLS_SCM_PRETEND_VERSION``)
wins over all of these.
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

from setuptools.build_meta import *  # noqa: F401,F403  (the hooks, unchanged)

ROOT = Path(__file__).resolve().parent.parent
PRETEND = "SETUPTOOLS_SCM_PRETEND_VERSION_FOR_BARK_GRASSTREE"


def _git(*args: str) -> str | None:
    try:
        done = subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.SubprocessError):
        return None
    return done.stdout.strip() if done.returncode == 0 else None


def written_version() -> str | None:
    """The version to build as, or ``None`` to leave it to setuptools-scm (a tag, or PKG-INFO)."""
    written = (ROOT / "VERSION").read_text(encoding="utf-8").strip()
    if _git("rev-parse", "--git-dir") is None:
        return None if (ROOT / "PKG-INFO").exists() else written
    if _git("describe", "--tags", "--match", "v[0-9]*") is not None:
        return None  # a release tag reaches this commit: setuptools-scm's version
    release = _git("log", "-1", "--format=%H", "--", "VERSION")
    distance = int(_git("rev-list", "--count", f"{release}..HEAD") or 0) if release else 0
    dirty = bool(_git("status", "--porcelain", "--untracked-files=no"))
    if release and distance == 0 and not dirty:
        return written
    major, minor, patch = (int(part) for part in written.split("."))
    local = f"g{_git('rev-parse', '--short', 'HEAD')}" + (".dirty" if dirty else "")
    return f"{major}.{minor}.{patch + 1}.dev{distance}+{local}"


if not (os.environ.get(PRETEND) or os.environ.get("SETUPTOOLS_SCM_PRETEND_VERSION")):  # else the builder chose
    _version = written_version()
    if _version is not None:
        os.environ[PRETEND] = _version
