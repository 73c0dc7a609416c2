"""The ``bark`` command (also ``python -m bark_cli``).

Loading the program takes a moment (numpy, scipy, networkx, click).  A signal in that moment ends
it the way a signal before the first step does: one line, exit 128 + signal, nothing run; never a
traceback from the middle of an import.
"""

from __future__ import annotations

import signal
import sys

from bark_cli import REASONS, Interrupted


def main() -> None:
    def stop(signum, frame):
        raise Interrupted(signum)

    for sig in REASONS:  # kept until the command's own handlers take over (``bark_cli.main.Signals``)
        signal.signal(sig, stop)
    try:
        from bark_cli.main import main as command
    except KeyboardInterrupt as err:
        signum = getattr(err, "signum", signal.SIGINT)
        sys.stderr.write(f"bark: {REASONS[signum]} before the run began: nothing was run\n")
        sys.exit(128 + int(signum))
    command()


if __name__ == "__main__":
    main()
