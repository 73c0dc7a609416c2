"""Reference solutions for accuracy measurements: the model's ODE solved by scipy's ``solve_ivp``.

With no growth (G = 0) a base constrained to the trunk surface moves on a cylinder of fixed radius
``r``.  In coordinates ``(θ, z)`` its equations of motion are exact ordinary differential equations:

* massive (the paper's model, eqs. 4–6 with the surface constraint):
  ``m r θ'' = F·e_θ``,  ``m z'' = F_z``,  with ``F`` = springs + anchors − b·v and
  ``v = r θ' e_θ + z' e_z`` (the constraint force is normal to the surface and does no work);
* overdamped (the massless limit the ``implicit-overdamped`` integrator solves):
  ``b r θ' = F_el·e_θ``,  ``b z' = F_el,z``.

The integrators in bark discretise these (Euler–Cromer plus projection onto the surface, or
linearised backward Euler plus projection); a tight-tolerance Radau solution is the reference that
their position error is measured against.
"""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

__all__ = ["cylinder_rhs", "solve_reference", "to_cylinder", "from_cylinder"]


def to_cylinder(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(θ, z)`` of Cartesian points (θ unwrapped only within (−π, π])."""
    return np.arctan2(x[:, 1], x[:, 0]), x[:, 2].copy()


def from_cylinder(theta: np.ndarray, z: np.ndarray, radius: float) -> np.ndarray:
    """Points at angles ``theta`` (radians) and heights ``z`` on a cylinder of radius ``radius`` about the z
    axis: ``(r cos θ, r sin θ, z)``, shape ``(n, 3)``."""
    return np.column_stack([radius * np.cos(theta), radius * np.sin(theta), z])


def cylinder_rhs(state, forces, radius: float, overdamped: bool = False):
    """Right-hand side ``y' = f(t, y)`` of the constrained dynamics of ``state``'s springs and
    anchors (``forces``, the simulation's ``ForceField``) on a cylinder of ``radius`` (intact springs
    only; nothing breaks).

    ``y`` is ``(θ, z, θ', z')`` (massive) or ``(θ, z)`` (overdamped), each block of length n.
    """
    mech = forces.mechanics
    fixed = state.copy()  # its springs and anchors, as they are now
    n = state.n_bases

    def elastic(theta, z):
        x = np.asfortranarray(from_cylinder(theta, z, radius))
        f = forces.elastic(fixed, x)
        e_theta = np.column_stack([-np.sin(theta), np.cos(theta)])
        return np.einsum("ij,ij->i", f[:, :2], e_theta), f[:, 2]

    if overdamped:

        def rhs(t, y):
            f_theta, f_z = elastic(y[:n], y[n:])
            return np.concatenate([f_theta / (mech.b * radius), f_z / mech.b])

    else:

        def rhs(t, y):
            theta, z, w, u = y[:n], y[n : 2 * n], y[2 * n : 3 * n], y[3 * n :]
            f_theta, f_z = elastic(theta, z)
            f_theta = f_theta - mech.b * radius * w
            f_z = f_z - mech.b * u
            return np.concatenate([w, u, f_theta / (mech.m * radius), f_z / mech.m])

    return rhs


def solve_reference(state, forces, radius: float, t_end: float, overdamped: bool = False, rtol: float = 1e-10) -> np.ndarray:
    """Positions at ``t_end`` (Cartesian, n × 3) from ``state``'s positions and velocities, by
    Radau at ``rtol`` (absolute tolerance ``rtol`` × the base spacing scale)."""
    theta, z = to_cylinder(state.x)
    if overdamped:
        y0 = np.concatenate([theta, z])
    else:
        e_theta = np.column_stack([-np.sin(theta), np.cos(theta)])
        w = np.einsum("ij,ij->i", state.v[:, :2], e_theta) / radius
        y0 = np.concatenate([theta, z, w, state.v[:, 2]])
    sol = solve_ivp(cylinder_rhs(state, forces, radius, overdamped), (0.0, t_end), y0, method="Radau",
                    rtol=rtol, atol=rtol * 1e-2, dense_output=False)
    if not sol.success:
        raise RuntimeError(f"reference solve failed: {sol.message}")
    n = state.n_bases
    y = sol.y[:, -1]
    return from_cylinder(y[:n], y[n : 2 * n], radius)
