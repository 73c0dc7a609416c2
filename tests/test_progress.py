"""One progress system for the long commands (``bark_cli.progress.Tally``): a bar on a terminal, in
a log a line at once and then every ``--progress-every`` seconds whether or not anything finished,
and a last line at the end; nothing with ``--quiet``."""

from __future__ import annotations

import io
import math
import threading

import pytest
from click.testing import CliRunner

from bark_cli.main import cli
from bark_cli.progress import Tally
from conftest import REPO_ROOT


class Log(io.StringIO):
    """A stderr that is a file (no terminal), whose lines can be waited for."""

    def __init__(self) -> None:
        super().__init__()
        self.grew = threading.Condition()

    def write(self, text: str) -> int:
        with self.grew:
            n = super().write(text)
            self.grew.notify_all()
        return n

    def lines(self) -> list[str]:
        return self.getvalue().splitlines()

    def wait_for(self, n: int, deadline_s: float = 120.0) -> list[str]:
        with self.grew:
            self.grew.wait_for(lambda: len(self.lines()) >= n, timeout=deadline_s)
        return self.lines()


def _log(monkeypatch) -> Log:
    out = Log()  # set in the test itself: pytest sets its own capture as sys.stderr again when a test starts
    monkeypatch.setattr("sys.stderr", out)
    return out


def test_a_log_gets_a_line_at_once_then_lines_while_nothing_finishes_and_a_last_one(monkeypatch):
    log = _log(monkeypatch)
    tally = Tally("sweep", "runs", every_s=0.01)
    try:
        assert log.lines()[0].startswith("bark: sweep: starting; ")  # at once: before any update
        lines = log.wait_for(4)  # no update meanwhile: the lines come from the clock, not from the work
        assert len(lines) >= 4 and all(line.startswith("bark: sweep: ") for line in lines)
        tally.update(2, 5, "last growth.G=0.01, seed 0")
    finally:
        tally.close()
    last = log.lines()[-1]
    assert last.startswith("bark: sweep: 2 of 5 runs; last growth.G=0.01, seed 0; ") and "elapsed" in last
    n = len(log.lines())
    tally.close()  # closing again says nothing more
    assert len(log.lines()) == n


def test_quiet_says_nothing_and_starts_no_clock(monkeypatch):
    log = _log(monkeypatch)
    before = threading.active_count()
    tally = Tally("fit", "accepted", every_s=0.01, quiet=True)
    tally.update(3, 10, "generation 0")
    tally.say("said")  # a command's own line still goes out: quiet hides progress, not what is said
    tally.close()
    assert log.getvalue() == "said\n" and threading.active_count() == before


@pytest.mark.parametrize("every", [0.0, -1.0, math.nan, math.inf])
def test_a_tally_without_a_finite_positive_period_is_refused(every):
    with pytest.raises(ValueError, match="expected a finite number of seconds above 0"):
        Tally("sweep", "runs", every_s=every)


def test_a_sweep_logs_its_progress_from_the_start_to_the_end(tmp_path):
    r = CliRunner().invoke(cli, ["sweep", "--set", "lattice.n_bases=300", "--set", "run.until_time=20",
                                 "--grid", "growth.G=0.01,0.02", "--seeds", "2", "--out", str(tmp_path / "s")])
    assert r.exit_code == 0, r.output
    said = [line for line in r.stderr.splitlines() if line.startswith("bark: sweep: ")]
    assert said[0].startswith("bark: sweep: starting; ") and said[-1].startswith("bark: sweep: 4 of 4 runs; last ")


@pytest.mark.parametrize("command", [["sweep"], ["fit", "examples/paper/observed-reticulate.toml"]])
@pytest.mark.parametrize("every", ["0", "-3", "nan", "inf", "soon"])
def test_a_progress_period_that_is_not_one_is_one_line_and_writes_nothing(tmp_path, command, every):
    args = [*command[:1], *(str(REPO_ROOT / a) for a in command[1:])]
    r = CliRunner().invoke(cli, [*args, "--progress-every", every, "--out", str(tmp_path / "out")])
    assert r.exit_code == 2 and "--progress-every" in r.output and len(r.output.strip().splitlines()) == 1, r.output
    assert not (tmp_path / "out").exists()
