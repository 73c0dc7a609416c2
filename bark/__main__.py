"""``python -m bark``: the ``bark`` command, as the distribution installs it (its console script,
found by entry point: the core imports no command line, as it imports no plotting)."""

from __future__ import annotations

import sys
from importlib.metadata import entry_points


def main() -> None:
    """``python -m bark``: the ``bark`` command, when bark's command line is installed (one line saying how to
    install it when not)."""
    scripts = [ep for ep in entry_points(group="console_scripts", name="bark") if ep.value.startswith("bark_cli")]
    if not scripts:
        sys.exit("bark: the command line is not installed (pip install bark-grasstree installs it)")
    scripts[0].load()()


if __name__ == "__main__":
    main()
