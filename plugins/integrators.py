"""Built-in integrators."""

from __future__ import annotations

from typing import ClassVar

import attrs
import numpy as np

from bark.validators import one_of, positive, positive_int
from bark.errors import BarkError, Ref, StepFailedError
from bark.model.stability import euler_cromer_h_max, lambda_max
from bark.contract.parts import IntegratorPart
from bark.contract.strategies import Integrator

__all__ = ["EulerCromer", "ImplicitOverdamped"]


def euler_cromer_update(x, v, f, hm, h, p):
    """One axis of one base (eqs. 7–8): the velocity first, then the position with the new velocity
    (no numbers of its own: ``p`` is empty)."""
    v = v + f * hm
    return x + v * h, v


@attrs.frozen(kw_only=True)
class EulerCromer(Integrator):
    """Semi-implicit (symplectic) Euler, the paper's method (eqs. 7–8)::

        v ← v + F(x, v)/m · dt
        x ← x + v · dt

    First order; stable while ``dt`` is below ``h_max = (√(β² + 4ω²) − β)/ω²`` with ``β = b/m`` and
    ``ω² = λ_max(K)/m`` (docs/numerics.md; ≈ 0.36 for Table 2's values).  Its part is its
    ``update``: the engine runs it inside its stepping kernel.
    """

    bound: str = attrs.field(default="gershgorin", validator=one_of("gershgorin", "lanczos"))
    """How λ_max(K) is bounded for the stability guard: gershgorin (c + 2k·max degree; holds for
    every state of the run, however stretched) or lanczos (the current state's exact value, a
    little less conservative)."""

    def part(self) -> IntegratorPart:
        """Compiled: ``v += h·f/m``, then ``x += h·v``."""
        return IntegratorPart(update=euler_cromer_update)

    def stability_limit(self, state, forces) -> float:
        """The largest stable step for this state: the damped explicit bound, from the stiffness's largest
        eigenvalue as ``bound`` bounds it."""
        return euler_cromer_h_max(state, forces, self.bound)


@attrs.frozen(kw_only=True)
class ImplicitOverdamped(Integrator):
    """The massless (overdamped) limit ``b·dx/dt = F(x)``, by linearised backward Euler on the
    trunk surface::

        P (b·I + dt·K) P Δx = P dt·F(x),    x ← x + Δx,    v ← Δx/dt

    with ``K = −∂F/∂x`` the stiffness of springs and anchors at the current state (its transverse
    term clamped at zero for compressed springs, so ``K`` is positive semi-definite) and ``P`` the
    projection of each base's displacement onto the plane tangent to the trunk there: the step is
    solved where the bases can move.  (Solved in 3-D, the system is nearly singular along the radius
    when dt·k/b is large, and the radial part the surface constraint then discards can drag the
    bases along.)  Stable for any ``dt``; first order.  The mass ``m`` plays no part (m → 0).

    The linear system is solved by conjugate gradients (``scipy.sparse.linalg.cg``), matrix-free,
    with a Jacobi preconditioner.  Why CG and not a sparse direct solve: the matrix is symmetric
    positive definite (``b > 0``), it changes every step (a direct solver would refactorise every
    step, with fill-in), and ``b·I`` dominates its diagonal, so CG converges in a few tens of
    iterations at a cost of about one force evaluation each, in O(springs) memory, at 70 000 bases
    as at 3000.
    """

    overdamped: ClassVar[bool] = True
    rtol: float = attrs.field(default=1e-8, validator=positive)
    """Relative residual at which CG stops."""
    maxiter: int = attrs.field(default=1000, validator=positive_int)
    """Most CG iterations per step."""

    def stability_limit(self, state, forces) -> float:
        """Stable for any step — given damping, which the overdamped limit divides by."""
        if forces.mechanics.b <= 0:
            raise BarkError("{0}: the implicit-overdamped integrator needs damping > 0 (and the 'damping' effect)",
                            Ref("mechanics", "b", forces.mechanics.b))
        return float("inf")

    def accuracy_limit(self, state, forces) -> float:
        """The layer's fastest relaxation time ``b/λ_max(K)`` (λ by Gershgorin's bound, as the explicit
        stability guard takes it): a fixed step longer than that resolves none of the relaxation
        that follows a break, and springs that would break one after another break together."""
        return forces.mechanics.b / lambda_max(state, forces, "gershgorin")

    def step(self, state, dt: float, forces) -> None:
        """One backward-Euler step ``dt`` of the overdamped motion ``b·dx/dt = f``: its linear system ``(b·I +
        dt·K)`` on the trunk's tangent planes solved by conjugate gradients."""
        from scipy.sparse.linalg import LinearOperator, cg  # here, not at import: a run without it never pays for it

        mech = forces.mechanics
        matvec, diag = forces.stiffness(state)
        size = diag.size
        e_r = state.x[:, :2] / np.hypot(state.x[:, 0], state.x[:, 1])[:, None]

        def tangential(p: np.ndarray) -> np.ndarray:
            p = p.reshape(-1, 3).copy()
            p[:, :2] -= np.einsum("ij,ij->i", p[:, :2], e_r)[:, None] * e_r
            return p.ravel()

        def apply(p: np.ndarray) -> np.ndarray:
            # P (bI + dt K) P on the tangent planes, b·I along the radii: SPD, and it keeps a
            # tangential right-hand side's solution tangential
            pt = tangential(p)
            return tangential(mech.b * pt + dt * matvec(pt)) + mech.b * (p - pt)

        a = LinearOperator((size, size), matvec=apply, dtype=float)
        precond = 1.0 / (mech.b + dt * diag)
        m = LinearOperator((size, size), matvec=lambda r: precond * r, dtype=float)
        rhs = tangential(dt * np.ascontiguousarray(forces.elastic(state)).ravel())
        scale = float(np.max(np.abs(rhs)))  # solve for rhs/scale: tiny forces must not underflow in CG
        if scale > 0.0:
            dx, info = cg(a, rhs / scale, rtol=self.rtol, atol=0.0, maxiter=self.maxiter, M=m)
            if info != 0:  # before the state changes: the run stops at the last good one
                raise StepFailedError(
                    f"the implicit-overdamped step from t = {state.t:.6g} did not reach rtol = {self.rtol:g} in "
                    f"maxiter = {self.maxiter} conjugate-gradient iterations: raise the integrator's maxiter or "
                    "rtol, or lower dt")
            dx = tangential(dx * scale).reshape(state.x.shape)
        else:
            dx = np.zeros_like(state.x)
        state.x += dx
        np.divide(dx, dt, out=state.v)
