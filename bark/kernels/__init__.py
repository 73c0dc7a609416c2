"""Compute backends for the hot loop: the same functions, in numpy or compiled with numba.

=======================================  ========================================================
function                                 does
=======================================  ========================================================
``elastic_forces(state, x) -> f``        spring (eq. 1) + anchor (eq. 2) forces at ``x``
``euler_cromer_step(state, h)``          eqs. 4, 7, 8 in place: forces, then ``v``, then ``x``
``measure(state, out) -> max_load``      tension ``k(|d| − l)`` of every spring into ``out``; returns
                                         the largest ``tension / fmax`` over intact springs (NaN if
                                         any tension is not finite)
``constrain_measure(state, r_x, r_a,     eq. 9 in place on the bases (radial velocity removed) and
out) -> max_load``                       anchors (radius × fixed direction), then ``measure``
``patch_labels(state) -> labels``        connected components of the intact springs, numbered in
                                         order of each component's smallest base (as scipy does)
=======================================  ========================================================

numba also has ``euler_cromer_quiet``, many Euler–Cromer steps in one compiled call (the quiet path
of ``Simulation.advance``, named by ``EulerCromer.quiet_kernel``), which can also break springs by
the ``over-threshold`` rule inside the call; a backend without it steps one by one.

``numpy`` is always there; ``numba`` is used when importable.  ``auto`` picks numba if it imports,
else numpy.  Both give the same results to round-off (summation order differs).
"""

from __future__ import annotations

import importlib
from types import ModuleType

from bark.errors import BarkError

__all__ = ["BACKENDS", "resolve", "load"]

BACKENDS = ("auto", "numpy", "numba")


def _numba_available() -> bool:
    try:
        importlib.import_module("numba")
    except ImportError:
        return False
    return True


def resolve(name: str) -> str:
    """The concrete backend ``name`` stands for (``auto`` → ``numba`` if importable, else ``numpy``)."""
    if name not in BACKENDS:
        raise BarkError(f"backend = {name!r}: must be one of {', '.join(BACKENDS)}")
    if name == "auto":
        return "numba" if _numba_available() else "numpy"
    if name == "numba" and not _numba_available():
        raise BarkError("backend = 'numba' but numba is not installed: pip install numba, or use backend = 'numpy'")
    return name


def load(name: str) -> ModuleType:
    """The kernel module of backend ``name`` (imported only when asked for)."""
    return importlib.import_module(f"bark.kernels.{resolve(name)}_backend")
