"""The numpy backend: vectorised array operations, no compiled code (the reference)."""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from bark.forces import anchor_forces, spring_forces, tensions
from bark.state import project_to_surface

NAME = "numpy"


def elastic_forces(state, x: np.ndarray) -> np.ndarray:
    mech = state.mechanics
    f = spring_forces(x, state.pairs, state.rest, mech.k, state.intact, state.incidence)
    if mech.c:
        f += anchor_forces(x, state.anchor, mech.c)
    return f


def euler_cromer_step(state, h: float) -> None:
    state.v += state.forces() * (h / state.mechanics.m)
    state.x += state.v * h


def measure(state, out: np.ndarray) -> float:
    out[:] = tensions(state.x, state.pairs, state.rest, state.mechanics.k)
    if not np.isfinite(out).all():
        return float("nan")
    if not state.intact.any():
        return float("-inf")
    return float(np.max(out[state.intact] / state.fmax[state.intact]))


def constrain_measure(state, r_x, r_anchor, out: np.ndarray) -> float:
    project_to_surface(state.x, r_x, state.v)
    state.anchor[:, :2] = np.reshape(r_anchor, (-1, 1)) * state.anchor_dir
    return measure(state, out)


def patch_labels(state) -> np.ndarray:
    """Connected components of the intact springs (scipy.sparse.csgraph)."""
    p = state.pairs[state.intact]
    adj = coo_matrix((np.ones(len(p)), (p[:, 0], p[:, 1])), shape=(state.n_bases, state.n_bases))
    return connected_components(adj, directed=False)[1].astype(np.int32)
