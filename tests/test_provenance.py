"""Provenance: every strategy is recorded by its entry-point name or, for one defined elsewhere, its
import path; a resumed run continues with that very class, or refuses in one line — never another
in its place."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from bark.contract import registry
from bark.errors import BarkError

LAW = '''
import attrs
import numpy as np
from bark_plugins.growth import SqrtGrowth


@attrs.frozen(kw_only=True)
class Law(SqrtGrowth):
    """A law in Python only: r0 + G t^0.45 (not the square root it subclasses)."""

    def radius(self, t, z):
        return self.r0 + self.G * np.power(t, 0.45)
'''

SCRIPT = '''
import sys
import attrs
import bark.studies.runner
from bark.engine.scene import Scene
{law_import}

scene = Scene.from_dict({{"lattice": {{"n_bases": 300}}, "run": {{"until_time": 30.0, "backend": "numpy"}},
                          "effects": {{"want": ["fracture", "break-log", "state-snapshot", "checkpoints"]}}}})
scene = attrs.evolve(scene, strategies={{**scene.strategies, "growth": Law(G=0.03)}})
steps = iter(range(10**9))
stop_after = int(sys.argv[2])
outcome = bark.studies.runner.run(scene, sys.argv[1], checkpoint_every=0,
                          interrupted=lambda: "interrupted" if stop_after and next(steps) >= stop_after else None)
print(outcome.stop_reason)
'''


def _python(tmp_path, script: str, *args, path=()):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([*map(str, path), os.environ.get("PYTHONPATH", "")])}
    return subprocess.run([sys.executable, "-c", script, *args], capture_output=True, text=True, env=env, cwd=tmp_path)


def _bark(*args, path=()):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([*map(str, path), os.environ.get("PYTHONPATH", "")])}
    return subprocess.run([sys.executable, "-m", "bark_cli", *args], capture_output=True, text=True, env=env)


@pytest.fixture
def law_module(tmp_path):
    folder = tmp_path / "laws"
    folder.mkdir()
    (folder / "mylaw.py").write_text(LAW)
    return folder


def _state(out):
    with np.load(out / "state.npz") as data:
        return {k: data[k] for k in data.files}


def test_a_law_from_a_module_is_recorded_by_its_path_and_resumed_to_the_bit(tmp_path, law_module):
    script = SCRIPT.format(law_import="from mylaw import Law")
    whole, part = tmp_path / "whole", tmp_path / "part"
    done = _python(tmp_path, script, str(whole), "0", path=[law_module])
    assert done.returncode == 0 and done.stdout.split() == ["time"], done.stderr
    summary = json.loads((whole / "summary.json").read_text())
    assert summary["settings"]["growth"] == {"name": "mylaw:Law", "r0": 0.2, "G": 0.03}
    stopped = _python(tmp_path, script, str(part), "40", path=[law_module])
    assert stopped.returncode == 0 and stopped.stdout.split() == ["interrupted"], stopped.stderr

    before = {p.name: p.read_bytes() for p in part.iterdir() if p.is_file()}
    refused = _bark("simulate", "--resume", str(part))  # its module is not on the path here
    assert refused.returncode != 0 and "Traceback" not in refused.stderr
    assert {p.name: p.read_bytes() for p in part.iterdir() if p.is_file()} == before  # nothing written, nothing lost
    lines = refused.stderr.strip().splitlines()
    assert len(lines) == 1 and "mylaw:Law" in lines[0] and "cannot be imported" in lines[0] and "PYTHONPATH" in lines[0]

    resumed = _bark("simulate", "--resume", str(part), "--quiet", path=[law_module])
    assert resumed.returncode == 0, resumed.stderr
    a, b = _state(whole), _state(part)
    assert all(np.array_equal(a[k], b[k]) for k in a)
    expected = 0.2 + 0.03 * 30.0**0.45  # the law's, not the square root's 0.2 + 0.03 * 30 ** 0.5
    assert json.loads((part / "summary.json").read_text())["radius"] == pytest.approx(expected, rel=1e-12)
    assert (whole / "breaks.csv").read_bytes() == (part / "breaks.csv").read_bytes()


def test_a_law_of_the_script_itself_is_recorded_as_such_and_resumed_only_from_there(tmp_path):
    script = SCRIPT.format(law_import=textwrap.dedent(LAW))
    part = tmp_path / "part"
    stopped = _python(tmp_path, script, str(part), "40")
    assert stopped.returncode == 0 and stopped.stdout.split() == ["interrupted"], stopped.stderr
    refused = _bark("simulate", "--resume", str(part))
    lines = refused.stderr.strip().splitlines()
    assert refused.returncode != 0 and len(lines) == 1 and "__main__:Law" in lines[0]
    assert "resume it from there" in lines[0]
    again = _python(tmp_path, textwrap.dedent(LAW) + f"\nimport bark.studies.runner\nprint(bark.studies.runner.resume({str(part)!r}).stop_reason)")
    assert again.returncode == 0 and again.stdout.split() == ["time"], again.stderr


def test_a_scene_names_a_strategy_by_its_import_path(law_module, monkeypatch):
    from bark.engine.scene import Scene

    monkeypatch.syspath_prepend(str(law_module))
    scene = Scene.from_dict({"growth": {"name": "mylaw:Law", "G": 0.02}})
    assert type(scene.strategies["growth"]).__name__ == "Law" and scene.names["growth"] == "mylaw:Law"
    assert scene.to_dict()["growth"] == {"name": "mylaw:Law", "r0": 0.2, "G": 0.02}
    assert registry.name_of(scene.strategies["breaker"]) == "threshold"
    for bad, why in (("mylaw:Nothing", "cannot be imported"), ("no_such_module:Law", "cannot be imported"),
                     ("bark.engine.scene:Scene", "is not a bark growth strategy")):
        with pytest.raises(BarkError, match=why) as err:
            Scene.from_dict({"growth": {"name": bad}})
        assert "\n" not in str(err.value)
