"""What a first run costs on empty caches (every kernel compiled), against another checkout.

    python benchmarks/first_run.py [--scene default] [--scene whole-tree] [--against DIR] [--rounds 1]
                                   [--until-time T] [--backend numba] [--together N]

Runs ``bark simulate`` of each scene (``default``: no ``--scene``) as a whole process whose every
cache is a new, empty folder (``NUMBA_CACHE_DIR``, ``BARK_CACHE_DIR``, ``XDG_CACHE_HOME``), so that
it compiles whatever it uses as on a new machine, then once more on those caches (warm), and prints
wall and CPU seconds of both. With ``--against DIR`` (a checkout of bark, e.g. ``git worktree add
/tmp/base <commit>``) the same runs of that code are interleaved with these, and the ratios this /
that are printed: of the first runs, and of the first runs less the warm ones (the compiling).
``--until-time`` ends every run there (the compiling of a long scene, without its whole run);
``--backend`` is passed on (``numba``: compiled even where ``auto`` would run a short run on numpy).
``--together N``: the first run is N processes started together on the one empty cache (a sweep's
workers, a shell loop), its wall until the last ends and its CPU theirs summed; the warm run is one.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def timed(argvs: list[list[str]], env: dict, cwd: str) -> tuple[float, float]:
    """(wall seconds until the last ends, CPU seconds: user + sys of the processes and their children)
    of processes started together."""
    t0 = time.perf_counter()
    procs = [subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env, cwd=cwd)
             for argv in argvs]
    errs = [[] for _ in procs]  # read while they run: a process that fills its pipe would wait on it
    readers = [threading.Thread(target=lambda p=proc, e=err: e.append(p.stderr.read())) for proc, err in zip(procs, errs)]
    for reader in readers:
        reader.start()
    cpu = 0.0
    for argv, proc, reader, got in zip(argvs, procs, readers, errs):
        _, status, usage = os.wait4(proc.pid, 0)
        cpu += usage.ru_utime + usage.ru_stime
        reader.join()
        err = b"".join(got).decode(errors="replace")
        proc.stderr.close()
        if os.waitstatus_to_exitcode(status) != 0:
            raise SystemExit(f"{' '.join(argv)} failed: {err.strip()[-2000:]}")
    return time.perf_counter() - t0, cpu


def linked(checkout: Path, folder: Path) -> Path:
    """``checkout``'s packages under the names the installed ones have (``bark``, ``bark_plugins``,
    ``bark_cli``), as links in ``folder``: what to put on ``PYTHONPATH`` to run that checkout's code
    with this interpreter and its libraries (every script here that compares two checkouts)."""
    folder.mkdir(exist_ok=True)
    for name, part in (("bark", "bark"), ("bark_plugins", "plugins"), ("bark_cli", "cli")):
        (folder / name).symlink_to(checkout.resolve() / part)
    return folder


def worker_records(code: Path | None, links: Path, source: str, *argv: str) -> list[dict]:
    """The JSON records (the lines that begin with ``{``) printed by the Python ``source``, run as
    ``python -c source argv...`` in a process of its own, from the temporary folder, on ``code``
    (``None``: this checkout as installed; else that checkout's packages, linked in ``links``): the
    warm workers of every script here that times code inside a process."""
    env = dict(os.environ)
    if code is not None:  # the other checkout's packages under the names the installed ones have
        env["PYTHONPATH"] = str(links)
    done = subprocess.run([sys.executable, "-c", source, *argv], capture_output=True, text=True, env=env,
                          cwd=tempfile.gettempdir())
    if done.returncode != 0:
        raise SystemExit(f"worker on {code or 'this checkout'} failed: {done.stderr.strip()[-2000:]}")
    return [json.loads(line) for line in done.stdout.splitlines() if line.startswith("{")]


def first_and_warm(code: Path | None, scene: str, links: Path, tmp: Path, extra: tuple[str, ...] = (),
                   together: int = 1) -> dict:
    """A first run on empty caches (``together`` processes at once) and a warm one after it, of ``code``
    (``None``: as installed)."""
    caches = Path(tempfile.mkdtemp(dir=tmp))
    env = {**os.environ, "NUMBA_CACHE_DIR": str(caches / "numba"), "BARK_CACHE_DIR": str(caches / "bark"),
           "XDG_CACHE_HOME": str(caches / "xdg")}
    if code is not None:
        env["PYTHONPATH"] = str(links)
    argvs = [[sys.executable, "-m", "bark_cli", "simulate", *(() if scene == "default" else ("--scene", scene)),
              *extra, "--out", str(caches / f"out{i}"), "--quiet", "--overwrite"] for i in range(together)]
    first = timed(argvs, env, str(tmp))
    warm = timed(argvs[:1], env, str(tmp))
    return {"first": first, "warm": warm}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", action="append", default=None, help="a shipped scene's name, or default")
    parser.add_argument("--against", type=Path, default=None, help="another checkout of bark to compare with")
    parser.add_argument("--rounds", type=int, default=1)
    parser.add_argument("--until-time", type=float, default=None, help="end every run at this time")
    parser.add_argument("--backend", default=None, help="bark simulate's --backend for every run")
    parser.add_argument("--together", type=int, default=1, help="processes of the first run, started at once")
    args = parser.parse_args()
    extra = (*(("--until-time", repr(args.until_time)) if args.until_time is not None else ()),
             *(("--backend", args.backend) if args.backend else ()))
    scenes = args.scene or ["default"]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        links = linked(args.against, tmp / "links") if args.against is not None else tmp
        sides = {"this": None, **({"that": args.against} if args.against is not None else {})}
        got = {(scene, side): [] for scene in scenes for side in sides}
        for _ in range(args.rounds):
            for scene in scenes:
                for side, code in sides.items():  # interleaved: a change in the machine's load falls on both
                    got[(scene, side)].append(first_and_warm(code, scene, links, tmp, extra, args.together))
    print(f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}; "
          f"{args.rounds} round(s){'; bark simulate ' + ' '.join(extra) if extra else ''}"
          f"{f'; first runs {args.together} processes together' if args.together > 1 else ''}; seconds: wall / CPU")
    for scene in scenes:
        for side, code in sides.items():
            for r in got[(scene, side)]:
                (fw, fc), (ww, wc) = r["first"], r["warm"]
                print(f"{scene:12s} {side} ({code or ROOT}): first {fw:7.1f} / {fc:7.1f}   warm {ww:7.1f} / {wc:7.1f}   "
                      f"compiling {fw - ww:7.1f} / {fc - wc:7.1f}")
        if "that" in sides:
            for a, b in zip(got[(scene, "this")], got[(scene, "that")]):
                (afw, afc), (aww, awc) = a["first"], a["warm"]
                (bfw, bfc), (bww, bwc) = b["first"], b["warm"]
                print(f"{scene:12s} this / that: first run wall {afw / bfw:.3f}, CPU {afc / bfc:.3f}; compiling wall "
                      f"{(afw - aww) / (bfw - bww):.3f}, CPU {(afc - awc) / (bfc - bwc):.3f}")


if __name__ == "__main__":
    main()
