"""Integrators: accuracy against a reference solution, stability (the guard and the implicit method),
the stiffness operator, backend agreement, and the last-finite-state contract."""

from __future__ import annotations

import json
import math
from functools import lru_cache

import attrs
import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import example, given
from hypothesis import strategies as st

from bark import Lattice, Mechanics, Simulation, Stop
from bark.errors import BarkError, NonFiniteStateError, StepFailedError
from bark.model.forces import stiffness_matvec
from bark.analysis.reference import solve_reference
from bark.engine.scene import Scene
from bark.model.stability import explicit_h_max, lambda_max
from bark.engine.stepping import SAFETY, Numerics
from bark.contract.parts import GrowthPart
from bark.contract.strategies import Growth, Integrator
from bark_cli.main import cli
from bark_plugins.breakers import ThresholdBreaker
from bark_plugins.growth import SqrtGrowth
from bark_plugins.integrators import EulerCromer, ImplicitOverdamped

from conftest import build_sim

R0 = 0.2
"""Trunk radius of SqrtGrowth's default r0 (the cylinder the reference solutions live on)."""
SPACING = Lattice().spacing(R0)
"""Base spacing of the default lattice at r0 (≈ 0.025)."""
NO_BREAKS = 1e9
"""An f_max no tension reaches."""


def _sim(integrator, dt, *, n_bases=120, mechanics=None, G=0.0, backend="numpy", seed=3, stepping="fixed", **kwargs) -> Simulation:
    return Simulation(
        lattice=Lattice(n_bases=n_bases, jitter=0.05),
        mechanics=mechanics or Mechanics(f_max=NO_BREAKS),
        growth=SqrtGrowth(G=G),
        integrator=integrator,
        breakers=[ThresholdBreaker()],
        numerics=Numerics(dt=dt, backend=backend, stepping=stepping),
        seed=seed,
        **kwargs,
    )


def _displace(sim: Simulation, amplitude: float, seed: int = 0) -> None:
    """Move every base along the trunk surface (angle and height) by Gaussian noise of
    ``amplitude`` × the base spacing, so that the springs are out of equilibrium."""
    s = sim.state
    rng = np.random.default_rng(seed)
    r = np.hypot(s.x[:, 0], s.x[:, 1])
    theta = np.arctan2(s.x[:, 1], s.x[:, 0]) + rng.normal(scale=amplitude * SPACING / r)
    z = s.x[:, 2] + rng.normal(scale=amplitude * SPACING, size=s.n_bases)
    with s.writing("x"):
        s.x[:] = np.column_stack([r * np.cos(theta), r * np.sin(theta), z])


def _dense(matvec, size: int) -> np.ndarray:
    return np.column_stack([matvec(e) for e in np.eye(size)])


def _energy(sim) -> float:
    """Elastic energy ``½k Σ(|d| − l)²`` over intact springs + ``½c Σ|x − anchor|²``, from the formula."""
    state, mech = sim.state, sim.mechanics
    d = state.x[state.pairs[:, 1]] - state.x[state.pairs[:, 0]]
    stretch = np.linalg.norm(d, axis=1) - state.rest
    return 0.5 * mech.k * float(np.sum(stretch[state.intact] ** 2)) + 0.5 * mech.c * float(np.sum((state.x - state.anchor) ** 2))


# -- accuracy: observed order of convergence against a Radau reference ---------------------------

T_END = 2.0
DTS = (0.08, 0.04, 0.02, 0.01, 0.005)


def _convergence_sim(integrator, dt, backend="numpy") -> Simulation:
    """No growth, nothing breaks, bases displaced along the surface (about 12–16 % of a spacing)."""
    sim = _sim(integrator, dt, backend=backend)
    s = sim.state
    rng = np.random.default_rng(0)
    theta = np.arctan2(s.x[:, 1], s.x[:, 0]) + rng.normal(scale=0.02, size=s.n_bases)
    z = s.x[:, 2] + rng.normal(scale=0.003, size=s.n_bases)
    with s.writing("x"):
        s.x[:] = np.column_stack([R0 * np.cos(theta), R0 * np.sin(theta), z])
    return sim


@lru_cache(maxsize=None)
def _reference(overdamped: bool) -> np.ndarray:
    sim = _convergence_sim(EulerCromer(), 0.01)
    return solve_reference(sim.state, sim.forces, R0, T_END, overdamped=overdamped)


@pytest.mark.parametrize(
    "integrator, overdamped, backend",
    [
        (EulerCromer(), False, "numpy"),
        (EulerCromer(), False, "numba"),
        (ImplicitOverdamped(), True, "numpy"),
        (ImplicitOverdamped(), True, "numba"),
    ],
    ids=["euler-cromer-numpy", "euler-cromer-numba", "implicit-numpy", "implicit-numba"],
)
def test_observed_order_of_convergence_is_one(integrator, overdamped, backend):
    """Euler–Cromer (massive model) and linearised backward Euler (overdamped model) are first
    order: the position error at T = 2 halves with dt."""
    ref = _reference(overdamped)
    start = _convergence_sim(integrator, 0.01).state.x
    moved = float(np.abs(ref - start).max())
    assert moved > 1e-3, "test set-up: the reference solution should move the bases"
    errors = []
    for dt in DTS:
        sim = _convergence_sim(integrator, dt, backend)
        assert sim.clock.h == dt
        sim.run(Stop(until_time=T_END))
        assert sim.step_count == round(T_END / dt) and sim.n_broken == 0
        errors.append(float(np.abs(sim.state.x - ref).max()))
    slope = np.polyfit(np.log(DTS), np.log(errors), 1)[0]
    assert 0.85 <= slope <= 1.15, (slope, errors)
    assert errors[-1] < 0.01 * moved, errors  # converging to the reference, not to something else


# -- the implicit method is unconditionally stable ---------------------------------------------


implicit_mechanics = st.builds(
    Mechanics,
    k=st.floats(0.01, 100.0),
    c=st.floats(0.0, 10.0),
    b=st.floats(0.1, 50.0),
    m=st.floats(0.01, 10.0),
    f_max=st.just(NO_BREAKS),
)


@given(
    mechanics=implicit_mechanics,
    stiffness_steps=st.floats(1e-3, 1e3),
    amplitude=st.floats(0.005, 0.08),
    seed=st.integers(0, 2**31 - 1),
)
@example(mechanics=Mechanics(k=100.0, m=0.01, f_max=NO_BREAKS), stiffness_steps=0.2, amplitude=0.08, seed=0)  # dt = 0.01
@example(mechanics=Mechanics(k=100.0, m=0.01, f_max=NO_BREAKS), stiffness_steps=20.0, amplitude=0.08, seed=1)  # dt = 1
@example(mechanics=Mechanics(k=100.0, c=0.0, b=0.1, m=0.01, f_max=NO_BREAKS), stiffness_steps=1e3, amplitude=0.08, seed=2)
@pytest.mark.slow  # seconds of implicit solves: the quick subset (-m "not slow") leaves it out
def test_implicit_step_dissipates_energy_without_growth(mechanics, stiffness_steps, amplitude, seed):
    """With G = 0 the overdamped dynamics is a gradient flow, and the implicit step never raises the
    elastic energy — for dt up to 1000 × b/k, i.e. up to ~300 000 × the Euler–Cromer limit of the
    stiff scene (k = 100, m = 0.01: h_max ≈ 0.0034), and displacements up to 8 % of a spacing.

    Beyond that (dt·k/b ≳ 10⁴, displacements ≳ 15 % of a spacing) one *linearised* step can raise the
    energy slightly before it decays (measured: at most ×1.002 with the tangent-plane solve; it was
    ×3.6 when the step was solved in 3-D and then projected): the next test bounds that regime."""
    dt = min(50.0, max(1e-3, stiffness_steps * mechanics.b / mechanics.k))
    # adaptive: a fixed step is held to the accuracy limit; with nothing breaking, adaptive steps are dt
    sim = _sim(ImplicitOverdamped(), dt, n_bases=100, mechanics=mechanics, seed=seed % 1000, stepping="adaptive")
    assert sim.stability_limit == math.inf and sim.clock.h == dt  # never refused, never sub-stepped
    _displace(sim, amplitude, seed)
    energies = [_energy(sim)]
    assert energies[0] > 0
    for _ in range(8):
        sim.step()
        assert sim.state.is_finite()
        energies.append(_energy(sim))
    e = np.array(energies)
    slack = 1e-6 * e[:-1] + 1e-9 * e[0]  # CG stops at rtol 1e-8; round-off once E is near zero
    assert np.all(e[1:] <= e[:-1] + slack), e / e[0]
    assert e[-1] < e[0]  # it really relaxes


@given(
    mechanics=implicit_mechanics,
    dt=st.floats(1e-3, 50.0),
    amplitude=st.floats(0.005, 0.4),
    G=st.floats(0.0, 0.2),
    breaking=st.booleans(),
    seed=st.integers(0, 2**31 - 1),
)
@example(mechanics=Mechanics(k=100.0, m=0.01, f_max=NO_BREAKS), dt=0.01, amplitude=0.3, G=0.1, breaking=False, seed=0)
@example(mechanics=Mechanics(k=100.0, m=0.01, f_max=NO_BREAKS), dt=5.0, amplitude=0.3, G=0.1, breaking=True, seed=0)
@example(mechanics=Mechanics(k=62.0, c=0.0, b=0.1, m=1.0, f_max=NO_BREAKS), dt=24.0, amplitude=0.25, G=0.0, breaking=False,
         seed=0)  # dt·k/b ≈ 15 000 without anchors: CG short of its tolerance in maxiter, said so
@pytest.mark.slow  # seconds of implicit solves: the quick subset (-m "not slow") leaves it out
def test_implicit_step_stays_bounded_with_growth_and_large_displacements(mechanics, dt, amplitude, G, breaking, seed):
    """Any dt up to 50 (over 10⁴ × the stiff scene's explicit limit), large displacements, growth,
    breaking: the state stays finite and the elastic energy stays below a generous multiple of what
    was there plus what growth injects (an unstable method grows it geometrically)."""
    if breaking:
        mechanics = attrs.evolve(mechanics, f_max=0.0028)
    # adaptive: the way a step this long is taken (fixed, it is above the accuracy limit); the clock
    # halves it only around breaks
    sim = _sim(ImplicitOverdamped(), dt, n_bases=100, mechanics=mechanics, G=G, seed=seed % 1000, stepping="adaptive")
    assert sim.clock.h == dt
    _displace(sim, amplitude, seed)
    e0 = _energy(sim)
    steps = 12
    r_end = sim.growth.radius(steps * dt, np.zeros(1))
    # energy of the springs if every base just followed the surface out to r_end (|d| scales by ≤ r/r0)
    injected = 0.5 * mechanics.k * float(np.sum(((r_end / R0 - 1.0) * sim.state.rest) ** 2))
    bound = 100.0 * (e0 + injected) + 1e-300
    for _ in range(steps):
        try:
            sim.step()
        except StepFailedError as err:  # a solve short of its tolerance is said, and the last good state kept
            assert "conjugate-gradient" in str(err) and sim.state.is_finite()
            assert _energy(sim) <= bound
            return
        assert sim.state.is_finite() and np.all(np.isfinite(sim.state.anchor))
        assert _energy(sim) <= bound, (_energy(sim), e0, injected)
    assert sim.state.t == pytest.approx(steps * dt) or (breaking and 0 < sim.state.t < steps * dt)


# -- the explicit stability guard --------------------------------------------------------------


guard_mechanics = st.builds(
    Mechanics,
    k=st.floats(0.05, 20.0),
    c=st.floats(0.0, 1.0),
    b=st.floats(0.0, 10.0),
    m=st.floats(0.05, 5.0),
)


def _guarded(mechanics, bound, dt, stepping) -> Simulation:
    return _sim(EulerCromer(bound=bound), dt, n_bases=150, mechanics=mechanics, G=0.014, seed=5, stepping=stepping)


@given(
    mechanics=guard_mechanics,
    bound=st.sampled_from(["gershgorin", "lanczos"]),
    factor=st.one_of(st.just(1.0 + 1e-6), st.floats(1.0 + 1e-6, 50.0)),
)
def test_guard_refuses_or_substeps_exactly_above_h_max(mechanics, bound, factor):
    if bound == "lanczos":
        # Lanczos breaks down without anchors, and varies from call to call (by ~1e-7, and now and
        # then by ~1e-3 when it lands on the second eigenvalue: see the xfail tests below): keep
        # c > 0, and a margin above that noise
        mechanics = attrs.evolve(mechanics, c=max(mechanics.c, 0.01))
        eps = 1e-2
    else:
        eps = 1e-6
    factor = max(factor, 1.0 + eps)
    probe = _guarded(mechanics, bound, 1e-9, "fixed")
    h_max = EulerCromer(bound=bound).stability_limit(probe.state, probe.forces)
    assert 0.0 < h_max < math.inf
    assert probe.stability_limit == pytest.approx(h_max, rel=eps)

    below = _guarded(mechanics, bound, h_max * (1.0 - eps), "fixed").build()  # just below: accepted as is
    assert below.clock.h == below.numerics.dt
    with pytest.raises(BarkError) as err:
        _guarded(mechanics, bound, h_max * factor, "fixed").build()
    message = str(err.value)
    assert "h_max" in message and "\n" not in message

    dt = h_max * factor
    for stepping in ("auto", "adaptive"):
        auto = _guarded(mechanics, bound, dt, stepping).build()
        n = dt / auto.clock.h
        assert n == pytest.approx(round(n), abs=1e-9) and round(n) >= 2
        n = round(n)
        assert auto.clock.h <= SAFETY * h_max * (1 + eps)
        assert dt / (n - 1) > SAFETY * h_max * (1 - eps)  # the fewest sub-steps that do it
        assert _guarded(mechanics, bound, h_max * (1.0 - eps), stepping).build().clock.h == h_max * (1.0 - eps)

    auto = _guarded(mechanics, bound, dt, "auto")
    auto.run(Stop(until_time=dt))  # one dt = n sub-steps of size h
    assert auto.step_count == n and auto.state.t == pytest.approx(dt, rel=1e-12)


@given(mechanics=guard_mechanics.filter(lambda m: m.b > 0.01), factor=st.floats(1.0 + 1e-6, 50.0))
def test_fixed_implicit_steps_are_refused_above_the_fastest_relaxation_and_split_under_auto(mechanics, factor):
    """The implicit method has no stability limit, so its steps are bounded by the layer's fastest
    relaxation time b/λ_max: a fixed step above it is refused in one line, auto splits it, and
    adaptive stepping (whose overshoot control is the accuracy control) takes it as it is."""
    probe = _sim(ImplicitOverdamped(), 1e-9, n_bases=150, mechanics=mechanics, G=0.014, seed=5)
    tau = mechanics.b / lambda_max(probe.state, probe.forces, "gershgorin")
    assert ImplicitOverdamped().accuracy_limit(probe.state, probe.forces) == tau
    assert probe.stability_limit == math.inf
    below = _sim(ImplicitOverdamped(), tau * (1 - 1e-9), n_bases=150, mechanics=mechanics, G=0.014, seed=5).build()
    assert below.clock.h == below.numerics.dt
    dt = tau * factor
    with pytest.raises(BarkError) as err:
        _sim(ImplicitOverdamped(), dt, n_bases=150, mechanics=mechanics, G=0.014, seed=5).build()
    assert "accuracy limit" in str(err.value) and "adaptive" in str(err.value) and "\n" not in str(err.value)
    auto = _sim(ImplicitOverdamped(), dt, n_bases=150, mechanics=mechanics, G=0.014, seed=5, stepping="auto").build()
    n = round(dt / auto.clock.h)
    assert n >= 2 and auto.clock.h <= SAFETY * tau * (1 + 1e-9) and dt / (n - 1) > SAFETY * tau * (1 - 1e-9)
    adaptive = _sim(ImplicitOverdamped(), dt, n_bases=150, mechanics=mechanics, G=0.014, seed=5, stepping="adaptive")
    assert adaptive.build().clock.h == dt


def test_an_explicit_method_has_no_accuracy_limit_of_its_own():
    sim = _sim(EulerCromer(), 0.01)
    assert EulerCromer().accuracy_limit(sim.state, sim.forces) == math.inf


@given(
    beta=st.floats(0.0, 1e3),
    omega2=st.floats(1e-3, 1e6),
    eps=st.sampled_from([1e-3, -1e-3]),
)
def test_explicit_h_max_is_the_edge_of_euler_cromer_stability(beta, omega2, eps):
    """One mode ``x'' = −ω²x − βx'`` under Euler–Cromer: the amplification matrix has spectral radius
    ≤ 1 just below h_max and > 1 just above it."""
    h = explicit_h_max(beta, omega2) * (1.0 + eps)
    # v' = v + h(−ω²x − βv),  x' = x + h v'
    step = np.array([[1.0 - omega2 * h * h, h * (1.0 - beta * h)], [-omega2 * h, 1.0 - beta * h]])
    radius = float(np.max(np.abs(np.linalg.eigvals(step))))
    if eps < 0:
        assert radius <= 1.0 + 1e-9
    else:
        assert radius > 1.0 + 1e-6


def test_explicit_h_max_limits():
    assert explicit_h_max(0.0, 4.0) == pytest.approx(1.0)  # 2/ω without damping
    assert explicit_h_max(5.0, 0.0) == pytest.approx(0.4)  # 2/β without stiffness
    assert explicit_h_max(5.0, 2.31) == pytest.approx(0.369, abs=0.001)  # Table 2 (m = 1)


def test_explicit_h_max_without_cancellation():
    assert explicit_h_max(1.0, 1e-17) == pytest.approx(2.0, rel=1e-9)


def test_lanczos_bound_without_anchors():
    sim = _sim(EulerCromer(bound="lanczos"), 0.01, n_bases=150, mechanics=Mechanics(c=0.0))
    gershgorin = lambda_max(sim.state, sim.forces, "gershgorin")
    assert 0.0 < sim.stability_limit < math.inf
    assert 0.0 < lambda_max(sim.state, sim.forces, "lanczos") <= gershgorin


def test_lanczos_bound_is_deterministic():
    sim = _sim(EulerCromer(), 0.01, n_bases=150, mechanics=Mechanics(c=0.1))
    state, forces = sim.state, sim.forces
    values = {lambda_max(state, forces, "lanczos") for _ in range(3)}
    assert len(values) == 1, values


def test_stability_numbers_of_notes_section_3():
    """docs/numerics.md: Table 2 values give λ_max ≈ 2.31, h_max ≈ 0.369; k = 100, m = 0.01 gives
    h_max ≈ 0.0034."""
    sim = Scene.from_dict({"run": {"dt": 0.01}}).simulation()  # Table 2 values
    state, forces = sim.state, sim.forces
    assert lambda_max(state, forces, "lanczos") == pytest.approx(2.31, abs=0.02)
    assert EulerCromer(bound="lanczos").stability_limit(state, forces) == pytest.approx(0.369, abs=0.003)
    # Gershgorin, the default: c + 2k·(most springs on one base) = 0.1 + 2·0.4·4
    assert lambda_max(state, forces, "gershgorin") == pytest.approx(3.3, rel=1e-12)
    assert EulerCromer().stability_limit(state, forces) < EulerCromer(bound="lanczos").stability_limit(state, forces)
    stiff = Scene.from_dict({"mechanics": {"k": 100.0, "m": 0.01}, "run": {"dt": 1e-3}}).simulation()
    assert EulerCromer(bound="lanczos").stability_limit(stiff.state, stiff.forces) == pytest.approx(0.0034, abs=0.0002)


@given(
    scale=st.floats(1.0, 1.3),
    jitter=st.floats(0.0, 0.3),
    k=st.floats(0.05, 50.0),
    c=st.floats(0.01, 5.0),  # c = 0: see test_lanczos_bound_without_anchors
    broken=st.floats(0.0, 0.5),
    seed=st.integers(0, 2**31 - 1),
)
def test_gershgorin_bounds_lanczos_on_stretched_states(scale, jitter, k, c, broken, seed):
    sim = _sim(EulerCromer(), 1e-3, n_bases=150, mechanics=Mechanics(k=k, c=c), seed=seed % 1000)
    s = sim.state
    rng = np.random.default_rng(seed)
    with s.writing("x"):
        s.x[:, :2] *= scale
        s.x += rng.normal(scale=jitter * SPACING, size=s.x.shape)
    sim.break_springs(np.flatnonzero(rng.random(s.n_springs) < broken))  # graph and arrays together
    forces = sim.forces
    gershgorin = lambda_max(s, forces, "gershgorin")
    lanczos = lambda_max(s, forces, "lanczos")
    assert 0.0 < lanczos <= gershgorin
    # lanczos is the top eigenvalue, to its tolerance: check against a dense solve.  (It should never
    # be below it, but about one call in 200 lands up to ~0.15 % low: the random restarts of
    # test_lanczos_bound_is_deterministic sometimes converge to the second eigenvalue of a cluster.)
    matvec, _ = stiffness_matvec(s.x, s.pairs, s.rest, k, s.intact, c)
    top = np.linalg.eigvalsh(_dense(matvec, 3 * s.n_bases))[-1]
    assert top * (1 - 3e-3) <= lanczos <= top * (1 + 2e-4)


class _Unguarded(EulerCromer):
    """Euler–Cromer with the guard switched off, to probe the bound itself."""

    def stability_limit(self, state, forces) -> float:
        return math.inf


@pytest.mark.parametrize("k, m", [(0.4, 1.0), (100.0, 0.01)], ids=["table2", "stiff"])
def test_h_max_is_where_euler_cromer_really_becomes_unstable(k, m):
    """Just below the Lanczos h_max a velocity kick dies away; 10 % above it, it explodes."""
    mechanics = Mechanics(k=k, m=m, f_max=NO_BREAKS)
    h_max = _sim(EulerCromer(bound="lanczos"), 1e-9, n_bases=150, mechanics=mechanics).build().stability_limit
    peaks = {}
    for factor in (0.97, 1.1):
        sim = _sim(_Unguarded(), factor * h_max, n_bases=150, mechanics=mechanics)
        with sim.state.writing("v"):
            sim.state.v[:] = np.random.default_rng(0).normal(scale=1e-4, size=sim.state.v.shape)
        sim.step()  # the kick's first effect, the yardstick (later amplitudes are seen after each call)
        amplitude = [float(np.abs(sim.state.x - sim.state.anchor).max())]
        try:
            sim.run(Stop(until_time=600 * sim.build().clock.h * (1 - 1e-9)),
                    lambda s: amplitude.append(float(np.abs(s.state.x - s.state.anchor).max())))
        except NonFiniteStateError:
            amplitude.append(math.inf)
        peaks[factor] = max(amplitude) / amplitude[0]
    assert peaks[0.97] < 10.0, peaks
    assert peaks[1.1] > 1e3, peaks


# -- the stiffness operator --------------------------------------------------------------------


@given(
    scale=st.floats(1.01, 1.3),
    k=st.floats(0.01, 100.0),
    c=st.floats(0.0, 10.0),
    broken=st.floats(0.0, 0.5),
    seed=st.integers(0, 2**31 - 1),
)
@example(scale=1.05, k=0.4, c=0.1, broken=0.0, seed=0)
def test_stiffness_matvec_is_the_force_jacobian_when_nothing_is_compressed(scale, k, c, broken, seed):
    sim = _sim(EulerCromer(), 1e-3, n_bases=60, mechanics=Mechanics(k=k, c=c), seed=seed % 1000)
    s = sim.state
    rng = np.random.default_rng(seed)
    sim.break_springs(np.flatnonzero(rng.random(s.n_springs) < broken))  # graph and arrays together
    x = s.x * scale  # every spring stretched by `scale`: no transverse clamping
    with s.writing("anchor"):
        s.anchor[:] += rng.normal(scale=SPACING, size=s.anchor.shape)  # anchors off the bases
    matvec, diag = stiffness_matvec(x, s.pairs, s.rest, k, s.intact, c)
    size = x.size
    K = _dense(matvec, size)

    def force(flat):
        return sim.forces.elastic(s, np.asfortranarray(flat.reshape(x.shape))).ravel()

    eps = 1e-6 * SPACING
    jac = np.empty((size, size))
    for col in range(size):
        e = np.zeros(size)
        e[col] = eps
        jac[:, col] = -(force(x.ravel() + e) - force(x.ravel() - e)) / (2 * eps)
    np.testing.assert_allclose(K, jac, rtol=0, atol=1e-6 * (k + c))
    np.testing.assert_allclose(K, K.T, rtol=0, atol=1e-12 * (k + c))
    np.testing.assert_allclose(diag, np.diag(K), rtol=1e-12, atol=1e-15)


@given(
    squeeze=st.floats(0.7, 1.3),
    jitter=st.floats(0.0, 0.5),
    k=st.floats(0.01, 100.0),
    c=st.floats(0.0, 10.0),
    seed=st.integers(0, 2**31 - 1),
)
def test_stiffness_is_symmetric_positive_semidefinite_with_compressed_springs(squeeze, jitter, k, c, seed):
    """Compressed springs have their transverse term clamped at zero: K stays symmetric PSD, and the
    returned diagonal is still K's diagonal."""
    sim = _sim(EulerCromer(), 1e-3, n_bases=60, mechanics=Mechanics(k=k, c=c), seed=seed % 1000)
    s = sim.state
    x = s.x * squeeze + np.random.default_rng(seed).normal(scale=jitter * SPACING, size=s.x.shape)
    matvec, diag = stiffness_matvec(x, s.pairs, s.rest, k, s.intact, c)
    K = _dense(matvec, x.size)
    np.testing.assert_allclose(K, K.T, rtol=0, atol=1e-12 * (k + c))
    assert np.linalg.eigvalsh(0.5 * (K + K.T))[0] >= c - 1e-9 * (k + c)
    np.testing.assert_allclose(diag, np.diag(K), rtol=1e-12, atol=1e-15)


# -- backends agree ----------------------------------------------------------------------------


def _assert_same_run(a: Simulation, b: Simulation) -> None:
    la, lb = a.breaks.arrays(), b.breaks.arrays()
    assert la["spring"].size > 0, "test set-up: springs should break"
    np.testing.assert_array_equal(la["spring"], lb["spring"])
    np.testing.assert_array_equal(la["step"], lb["step"])
    np.testing.assert_array_equal(la["t"], lb["t"])
    np.testing.assert_allclose(la["tension"], lb["tension"], rtol=1e-12, atol=0)
    np.testing.assert_array_equal(a.state.intact, b.state.intact)
    assert a.step_count == b.step_count and a.state.t == b.state.t
    np.testing.assert_allclose(a.state.x, b.state.x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(a.state.v, b.state.v, rtol=0, atol=1e-12)
    np.testing.assert_allclose(a.state.anchor, b.state.anchor, rtol=0, atol=1e-12)


def test_numpy_and_numba_backends_give_the_same_run():
    a = build_sim(n_bases=400, seed=1, backend="numpy", stepping="fixed")
    b = build_sim(n_bases=400, seed=1, backend="numba", stepping="fixed")
    a.run(Stop(until_time=6.0))
    b.run(Stop(until_time=6.0))
    _assert_same_run(a, b)


def test_numba_step_by_step_equals_advance_chunks():
    a = build_sim(n_bases=400, seed=1, backend="numba", stepping="fixed")
    b = build_sim(n_bases=400, seed=1, backend="numba", stepping="fixed")
    stop = Stop(until_time=6.0)
    calls = 0
    while stop.reason(a) is None:
        a.step()
    while stop.reason(b) is None:
        b.advance(stop)
        calls += 1
    assert calls < b.step_count  # some advances really took several steps
    _assert_same_run(a, b)


@given(
    seed=st.integers(0, 2**31 - 1),
    G=st.floats(0.02, 0.1),
    dt=st.floats(0.01, 0.1),
    fmax_spread=st.floats(0.0, 0.1),
)
def test_backends_agree_on_random_scenes(seed, G, dt, fmax_spread):
    runs = []
    for backend in ("numpy", "numba"):
        sim = build_sim(n_bases=200, seed=seed, G=G, dt=dt, fmax_spread=fmax_spread, backend=backend, stepping="fixed")
        sim.run(Stop(until_time=4.0))
        runs.append(sim)
    if len(runs[0].breaks) == 0:
        assert len(runs[1].breaks) == 0
        np.testing.assert_allclose(runs[0].state.x, runs[1].state.x, rtol=0, atol=1e-12)
    else:
        _assert_same_run(*runs)


# -- non-finite states: the run stops at the last finite state -----------------------------------


@attrs.frozen(kw_only=True)
class _NaNAtCall(Integrator):
    """Euler–Cromer that poisons a position on its ``nan_at``-th call (``None``: never)."""

    nan_at: int | None = None
    calls: list = attrs.field(factory=list, eq=False)

    def step(self, state, dt: float, forces) -> None:
        EulerCromer.step(EulerCromer(), state, dt, forces)
        self.calls.append(dt)
        if len(self.calls) == self.nan_at:
            state.x[0, 0] = np.nan


def _assert_same_state(a: Simulation, b: Simulation) -> None:
    assert a.step_count == b.step_count and a.state.t == b.state.t
    np.testing.assert_allclose(a.state.x, b.state.x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(a.state.v, b.state.v, rtol=0, atol=1e-12)
    np.testing.assert_allclose(a.state.anchor, b.state.anchor, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(a.state.intact, b.state.intact)


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_nan_from_integrator_leaves_last_finite_state(backend):
    def make(nan_at):
        return Simulation(
            lattice=Lattice(n_bases=200), mechanics=Mechanics(), growth=SqrtGrowth(G=0.05),
            integrator=_NaNAtCall(nan_at=nan_at), breakers=[ThresholdBreaker()], seed=4,
            numerics=Numerics(dt=0.05, backend=backend, stepping="fixed"),
        )

    sim = make(5)
    with pytest.raises(NonFiniteStateError, match="NaN or infinite"):
        sim.run(Stop(until_time=1.0))
    assert sim.step_count == 4 and sim.state.t == 4 * sim.clock.h
    assert sim.state.is_finite() and np.all(np.isfinite(sim.state.anchor))
    ref = make(None)
    for _ in range(4):
        ref.step()
    _assert_same_state(sim, ref)
    # the restored state is a working one: carrying on gives the run that never saw a NaN
    assert sim.run(Stop(until_time=1.0)) == "time"
    ref.run(Stop(until_time=1.0))
    _assert_same_state(sim, ref)
    assert sim.breaks.arrays()["step"].tolist() == ref.breaks.arrays()["step"].tolist()


def nan_radius_after(t, z, p):
    """``r0 + G√t`` with ``p = (r0, G, t_bad)``, NaN once ``t > t_bad``: a part that fails."""
    return np.nan if t > p[2] else p[0] + p[1] * np.sqrt(t)


@attrs.frozen(kw_only=True)
class _NaNRadiusAfter(Growth):
    """``r0 + G√t`` (uniform), NaN once ``t > t_bad``."""

    r0: float = 0.2
    G: float = 0.05
    t_bad: float = 1.0

    def part(self) -> GrowthPart:
        return GrowthPart(radius=nan_radius_after, params=(self.r0, self.G, self.t_bad), uniform=True)


def _growth_sim(growth, backend, dt=0.05) -> Simulation:
    return Simulation(
        lattice=Lattice(n_bases=200), mechanics=Mechanics(f_max=NO_BREAKS), growth=growth, integrator=EulerCromer(),
        breakers=[ThresholdBreaker()], seed=4, numerics=Numerics(dt=dt, backend=backend, stepping="fixed"),
    )


@pytest.mark.parametrize("bad_step", [41, 30, 2])
def test_nan_inside_a_quiet_chunk_leaves_last_finite_state(bad_step):
    """The compiled kernel (numba) meets a NaN radius in the middle of a call: the simulation is put
    back to the step before (the call is replayed up to it)."""
    dt = 0.05
    sim = _growth_sim(_NaNRadiusAfter(t_bad=(bad_step - 0.5) * dt), "numba", dt)
    advances = []
    with pytest.raises(NonFiniteStateError):
        sim.run(Stop(until_time=100.0), lambda s: advances.append(s.step_count))
    good = bad_step - 1
    assert sim.step_count == good and sim.state.t == good * sim.clock.h
    assert sim.state.is_finite() and np.all(np.isfinite(sim.state.anchor))
    assert advances == []  # one compiled call took every step up to the bad one, and was put back
    for backend in ("numba", "numpy"):  # one step at a time, with the growth law that never fails
        ref = _growth_sim(SqrtGrowth(G=0.05), backend, dt)
        for _ in range(good):
            ref.step()
        _assert_same_state(sim, ref)


@pytest.mark.parametrize("bad_step", [41, 30])
def test_nan_inside_a_long_adaptive_call_leaves_the_numpy_backends_last_finite_state(bad_step, kernel_calls):
    """Adaptive steps at a uniform radius in one long call (no joins): the numba kernel reads each
    step from one of two buffers and writes it into the other, and takes a refused one back by not
    taking it.  A NaN radius met there is halved down to the smallest step, then refused for good:
    the simulation holds the last finite state, whichever buffer held it (an odd or even count of
    kept steps: two bad steps), to the bit of the numpy backend, which replays its calls instead."""
    dt = 0.05
    runs = {}
    for backend in ("numba", "numpy"):
        kernel_calls.clear()
        sim = Simulation(
            lattice=Lattice(n_bases=200), mechanics=Mechanics(f_max=NO_BREAKS),
            growth=_NaNRadiusAfter(t_bad=(bad_step - 0.5) * dt), integrator=EulerCromer(),
            breakers=[ThresholdBreaker()], seed=4, numerics=Numerics(dt=dt, backend=backend, stepping="adaptive"))
        with pytest.raises(NonFiniteStateError):
            sim.run(Stop(until_time=100.0))
        runs[backend] = sim, list(kernel_calls)
    (a, calls), (b, _) = runs["numba"], runs["numpy"]
    assert len(calls) == 1 and calls[0].undone  # one call, which took its refused step back itself
    assert a.step_count == b.step_count >= bad_step - 1 and a.state.t == b.state.t
    assert a.state.is_finite() and np.all(np.isfinite(a.state.anchor))
    for name in ("x", "v", "anchor", "intact"):
        assert np.array_equal(getattr(a.state, name), getattr(b.state, name)), name


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_nan_radius_on_the_step_path_leaves_last_finite_state(backend):
    """A non-finite radius also projects the anchors to NaN: they must come back too (found by this test)."""
    sim = _growth_sim(_NaNRadiusAfter(t_bad=9.5 * 0.05), backend)
    with pytest.raises(NonFiniteStateError):
        for _ in range(20):
            sim.step()  # the step path (run() on numba would take the quiet kernel)
    assert sim.step_count == 9 and sim.state.t == 9 * sim.clock.h
    assert sim.state.is_finite() and np.all(np.isfinite(sim.state.anchor))
    ref = _growth_sim(SqrtGrowth(G=0.05), backend)
    for _ in range(9):
        ref.step()
    _assert_same_state(sim, ref)


# -- the stiff scene through the command line ----------------------------------------------------

STIFF = ["simulate", "--k", "100", "--m", "0.01", "--dt", "0.01", "--n-bases", "300", "--until-time", "0.2", "--quiet"]


@pytest.mark.parametrize("extra,words", [
    ([], "stability limit h_max"),
    (["--integrator", "implicit-overdamped"], "accuracy limit for fixed steps, 0.006249"),  # b/λ = 5/800.1
])
def test_cli_refuses_stiff_scene_with_fixed_steps(tmp_path, extra, words):
    out = tmp_path / "out"
    result = CliRunner().invoke(cli, [*STIFF, "--stepping", "fixed", *extra, "--out", str(out)])
    assert result.exit_code == 2, result.output
    text = result.output.strip()
    assert "\n" not in text and "Traceback" not in text
    assert words in text and "--dt 0.01" in text
    assert not out.exists()


@pytest.mark.parametrize(
    "extra",
    [["--stepping", "auto"], ["--stepping", "adaptive"], ["--stepping", "adaptive", "--integrator", "implicit-overdamped"],
     ["--stepping", "auto", "--integrator", "implicit-overdamped"],
     ["--stepping", "fixed", "--integrator", "implicit-overdamped", "--dt", "0.005"]],
    ids=["auto", "adaptive", "implicit", "implicit-auto", "implicit-fixed"],
)
def test_cli_runs_stiff_scene_with_substeps_or_implicit(tmp_path, extra):
    out = tmp_path / "out"
    result = CliRunner().invoke(cli, [*STIFF, *extra, "--out", str(out)])
    assert result.exit_code == 0, result.output
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stop_reason"] == "time"
    assert summary["t"] == pytest.approx(0.2, abs=1e-9)
    with np.load(out / "state.npz", allow_pickle=False) as data:
        assert np.all(np.isfinite(data["x"]))


@pytest.mark.parametrize("stepping, dt, extra", [
    ("fixed", 0.05, {}),
    ("adaptive", 0.3, {}),
    ("adaptive", 0.3, {"growth": "bulge"}),
    ("fixed", 0.05, {"breaker": "probabilistic"}),
    ("adaptive", 0.3, {"growth": "bulge", "join": True}),
])
def test_the_backends_agree_to_the_bit(stepping, dt, extra):
    """numpy and numba evaluate the same physics functions in the same order (a base's spring forces
    are summed in the order of bark.model.forces.SpringOrder by both, also when bases join during the run
    and their springs' ids follow the joins): the same run, bit for bit — positions, break log,
    tensions.  So the backend is a matter of speed alone."""
    from bark.model.lattice import Lattice
    from bark_plugins.breakers import ProbabilisticBreaker
    from bark_plugins.growth import Bulge, BulgeGrowth

    runs = []
    for backend in ("numpy", "numba"):
        growth = (BulgeGrowth(base=SqrtGrowth(G=0.05), bulges=[Bulge(z=0.1, half_width=0.05, magnitude=0.01, decay=0.07, G=0.02)])
                  if extra.get("growth") else None)
        breakers = [ProbabilisticBreaker()] if extra.get("breaker") else None
        lattice = Lattice(n_bases=700, n_start=400, join_rate=60.0, join_every=0.1, jitter=0.05) if extra.get("join") else None
        sim = build_sim(n_bases=400, G=0.05, dt=dt, seed=3, stepping=stepping, backend=backend, fmax_spread=0.05,
                        growth=growth, breakers=breakers, lattice=lattice)
        sim.run(Stop(until_time=6.0))
        runs.append(sim)
    a, b = runs
    assert a.n_broken > 20
    for name in ("x", "v", "anchor", "intact"):
        assert np.array_equal(getattr(a.state, name), getattr(b.state, name)), name
    la, lb = a.breaks.arrays(), b.breaks.arrays()
    for key in la:
        assert np.array_equal(la[key], lb[key]), key


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_the_benchmarks_plain_numpy_step_is_the_same_model(backend):
    """The baseline every speed-up is quoted against computes what bark computes (to round-off: it
    sums forces in another order), so the ratios compare like with like."""
    from bark_cli.bench import PlainNumpy

    sim = build_sim(n_bases=400, G=0.05, dt=0.05, seed=2, backend=backend, fmax_spread=0.05)
    sim.run(Stop(until_time=1.0))
    plain = PlainNumpy(sim)
    sim.run(Stop(until_time=4.0))
    for _ in range(60):
        plain.step()
    assert sim.n_broken > 20
    np.testing.assert_allclose(plain.x, sim.state.x, rtol=0, atol=1e-10)
    np.testing.assert_array_equal(plain.intact_in_bark_order, sim.state.intact)


def test_the_benchmarks_plain_numba_step_is_bark_s_to_the_bit():
    """``benchmarks/plain_numba.py``'s kernel, which bark's compiled step is timed against, computes
    what bark computes in the same order: the same positions and breaks to the bit, breaking included."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parent.parent / "benchmarks" / "plain_numba.py"
    spec = importlib.util.spec_from_file_location("plain_numba", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    sim = build_sim(n_bases=400, G=0.05, dt=0.05, seed=2, backend="numba", fmax_spread=0.05)
    sim.run(Stop(until_time=1.0))
    plain = module.PlainNumba(sim)
    sim.run(Stop(until_time=4.0))
    plain.steps(60)
    assert sim.n_broken > 20
    np.testing.assert_array_equal(plain.x, sim.state.x)
    np.testing.assert_array_equal(plain.intact_in_bark_order, sim.state.intact)


@pytest.mark.parametrize("bound", ["gershgorin", "lanczos"])
def test_a_lattice_still_to_grow_is_bounded_as_the_whole_lattice_laid_out(bound):
    """The stability limit of a lattice whose bases join during the run is taken on the whole lattice
    (the most springs a base will have), laid out as a simulation with every base lays it out: the
    same positions, springs and rest lengths, without building that simulation (its graph)."""
    mechanics = Mechanics(k=1.0, c=0.03, b=2.0)
    lattice = Lattice(n_bases=1500, n_start=60, join_rate=50.0, join_every=0.1, offsets=(21, 34), jitter=0.05)
    growing = Simulation(lattice=lattice, mechanics=mechanics, growth=SqrtGrowth(r0=0.2), integrator=EulerCromer(bound=bound),
                         breakers=[ThresholdBreaker()], seed=7).build()
    full = Simulation(lattice=attrs.evolve(lattice, n_start=None, join_rate=0.0), mechanics=mechanics,
                      growth=SqrtGrowth(r0=0.2), integrator=EulerCromer(bound=bound), breakers=[ThresholdBreaker()],
                      seed=7).build()
    whole = growing.whole_lattice()
    for name in ("x", "v", "anchor", "anchor_dir", "pairs", "rest", "intact"):
        np.testing.assert_array_equal(getattr(whole, name), getattr(full.state, name), err_msg=name)
    alone = Simulation(lattice=attrs.evolve(lattice, n_bases=60, n_start=None, join_rate=0.0), mechanics=mechanics,
                       growth=SqrtGrowth(r0=0.2), integrator=EulerCromer(bound=bound), breakers=[ThresholdBreaker()],
                       seed=7).build()
    assert growing.stability_limit == min(alone.stability_limit, full.stability_limit)
    assert full.stability_limit < alone.stability_limit  # the first 60 bases have fewer springs a base
    assert growing.rng.bit_generator.state == alone.rng.bit_generator.state  # the simulation's generator: not drawn
