"""The ``bark`` command (also ``python -m bark_cli``).

Loading the program takes a moment (numpy, scipy, networkx, click).  A signal in that moment ends
it the way a signal before the first step does: one line, exit 128 + signal, nothing run; never a
traceback from the middle of an import.
"""

from __future__ import annotations

import signal
import sys

_REASONS = {signal.SIGINT: "interrupted", signal.SIGTERM: "terminated", signal.SIGHUP: "terminated"}


def main() -> None:
    received: list[int] = []

    def stop(signum, frame):
        received.append(signum)
        raise KeyboardInterrupt

    previous = {sig: signal.signal(sig, stop) for sig in _REASONS}
    try:
        from bark_cli.main import main as command
    except KeyboardInterrupt:
        signum = received[0] if received else signal.SIGINT
        sys.stderr.write(f"bark: {_REASONS[signum]} before the run began: nothing was run\n")
        sys.exit(128 + int(signum))
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    command()


if __name__ == "__main__":
    main()
