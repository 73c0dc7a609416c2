"""The accuracy study's pattern errors: unsigned against the seeds' spread, and signed, with the
seeds counted on each side, so that a bias within the spread is seen."""

from __future__ import annotations

import numpy as np
import pytest

from bark.studies import accuracy as A
from bark.studies.accuracy import METRICS, SIGNED, Method, pattern_study


def _run(n_broken: int, n_patches: int) -> dict:
    return {"n_broken": n_broken, "n_patches": n_patches, "orientations": np.array([80.0, 90.0, 100.0])}


@pytest.mark.parametrize("run,ref,broken,patches", [
    ((110, 12), (100, 10), 0.1, 2),
    ((90, 8), (100, 10), -0.1, -2),
    ((100, 10), (100, 10), 0.0, 0),
    ((5, 1), (0, 0), 5.0, 1),  # a reference without breaks: relative to one spring, not a division by 0
])
def test_signed_errors_are_run_minus_reference_and_the_unsigned_their_size(run, ref, broken, patches):
    d = A._distance(_run(*run), _run(*ref))
    assert d["broken_rel_bias"] == pytest.approx(broken) and d["patch_count_bias"] == patches
    assert d["broken_rel_diff"] == pytest.approx(abs(broken)) and d["patch_count_diff"] == abs(patches)


@pytest.mark.slow  # a dozen small runs: seconds
def test_the_pattern_study_reports_each_seeds_side_of_the_reference():
    scene = {"lattice": {"n_bases": 400}}
    rows, spread = pattern_study({Method("euler-cromer"): [0.3]}, scene=scene, seeds=(0, 1, 2), until_time=60.0,
                                 reference_dt=0.05)
    (row,) = rows
    assert set(METRICS) <= set(spread)
    for m, unsigned in zip(SIGNED, METRICS):
        per_seed = row[m + "_per_seed"]
        assert len(per_seed) == 3
        assert row[m + "_above"] == sum(v > 0 for v in per_seed) and row[m + "_below"] == sum(v < 0 for v in per_seed)
        assert row[m] == pytest.approx(np.mean(per_seed))
        np.testing.assert_allclose(np.abs(per_seed), row[unsigned + "_per_seed"])
