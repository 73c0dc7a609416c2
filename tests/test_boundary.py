"""The boundary law's parts: the strains a growth law imposes on a stretch of trunk, and the
logistic law fitted to runs' kinds, checked against cases whose answers are known."""

from __future__ import annotations

import math

import attrs
import numpy as np
import pytest

from bark.analysis.boundary import fit_boundary, nested_p, stretch_strains
from bark_plugins.growth import Bulge, BulgeGrowth, SqrtGrowth

pytest.importorskip("statsmodels")


def test_a_straight_trunk_only_widens():
    law = SqrtGrowth(r0=0.2, G=0.014)
    hoop, axial = stretch_strains(law.radius, 300.0, 0.45, 1.05)
    assert hoop == pytest.approx(float(law.radius(300.0, np.array(0.75))) / 0.2 - 1, rel=1e-12)
    assert axial == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("bulge,axial_sign", [
    (Bulge(z=0.75, half_width=0.3, G=0.028), 1),                  # grows faster than the trunk: a rising bump
    (Bulge(z=0.75, half_width=0.3, magnitude=0.05, decay=0.01), -1),  # fades: its meridian shortens
])
def test_a_bulge_stretches_or_shortens_the_trunk_along_it(bulge, axial_sign):
    base = SqrtGrowth(r0=0.2, G=0.014)
    law = BulgeGrowth(base=base, bulges=(bulge,))
    hoop, axial = stretch_strains(law.radius, 300.0, 0.45, 1.05)
    assert np.sign(axial) == axial_sign and hoop > 0
    straight, _ = stretch_strains(base.radius, 300.0, 0.45, 1.05)
    assert (hoop > straight) == (bulge.G is not None)  # faster growth: more hoop strain; a fading bump: less


@pytest.mark.parametrize("low,high,t", [(1.0, 1.0, 1.0), (1.0, 0.5, 1.0), (0.0, math.nan, 1.0), (0.0, 1.0, -1.0),
                                        (0.0, 1.0, math.inf)])
def test_a_stretch_or_time_that_is_not_one_is_refused(low, high, t):
    with pytest.raises(ValueError):
        stretch_strains(SqrtGrowth().radius, t, low, high)


def _runs(n, coef, seed):
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(n, len(coef) - 1))
    p = 1 / (1 + np.exp(-(coef[0] + x @ np.asarray(coef[1:]))))
    return x, rng.random(n) < p


def test_the_law_finds_known_coefficients_within_its_intervals_and_misclassifies_as_the_truth_does():
    truth = (-0.5, 2.0, -1.5)
    x, y = _runs(4000, truth, seed=1)
    law = fit_boundary(x, y, ("a", "b"))
    assert all(lo < c < hi for c, lo, hi in zip(truth, law.low, law.high))
    assert law.llr_p < 1e-100 and 0 < law.pseudo_r2 < 1 and law.n == 4000
    x_new, y_new = _runs(4000, truth, seed=2)
    p_true = 1 / (1 + np.exp(-(truth[0] + x_new @ np.asarray(truth[1:]))))
    bayes = np.mean((p_true >= 0.5) != y_new)  # the least any law can misclassify these runs
    assert law.misclassified(x_new, y_new) == pytest.approx(bayes, abs=0.01)
    shown = attrs.evolve(law, coef=(-0.5, 2.0, -1.5))
    assert shown.formula() == "logit P(elongated) = -0.5 + 2·a − 1.5·b"


def test_a_feature_that_carries_nothing_is_not_taken_for_one_that_does():
    x, y = _runs(2000, (0.0, 1.5), seed=3)
    noise = np.random.default_rng(4).normal(size=(2000, 1))
    one = fit_boundary(x, y, ("a",))
    assert nested_p(one, fit_boundary(np.hstack([x, noise]), y, ("a", "noise"))) > 0.01
    assert nested_p(fit_boundary(noise, y, ("noise",)), fit_boundary(np.hstack([noise, x]), y, ("noise", "a"))) < 1e-20


@pytest.mark.parametrize("x,y,says", [
    (np.arange(10.0)[:, None], np.ones(10, bool), "one kind"),
    (np.arange(10.0)[:, None], np.arange(10) >= 5, "cannot be fitted"),  # separated perfectly: infinite coefficients
    (np.array([[0.0], [math.nan], [1.0], [2.0]]), np.array([True, False, True, False]), "not finite"),
    (np.zeros((4, 2)), np.array([True, False, True, False]), "features of shape"),
])
def test_runs_that_give_no_law_are_refused(x, y, says):
    with pytest.raises(ValueError, match=says):
        fit_boundary(x, y, ("a",))
