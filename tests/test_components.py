"""Patch labels on whole arrays (``bark.model.components``) against scipy's connected components,
the oracle they replace at run time (scipy.sparse.csgraph's import is a third of a short run)."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from bark.model.components import components, count_patches


def scipy_labels(n, pairs, kept):
    p = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)[np.asarray(kept, bool)]
    return connected_components(coo_matrix((np.ones(len(p)), (p[:, 0], p[:, 1])), shape=(n, n)),
                                directed=False)[1].astype(np.int32)


@st.composite
def graphs(draw):
    n = draw(st.integers(1, 120))
    m = draw(st.integers(0, 3 * n))
    ends = st.integers(0, n - 1)
    pairs = np.array(draw(st.lists(st.tuples(ends, ends), min_size=m, max_size=m)), dtype=np.int64).reshape(-1, 2)
    kept = np.array(draw(st.lists(st.booleans(), min_size=m, max_size=m)), dtype=bool)
    return n, pairs, kept


@settings(max_examples=300, deadline=None)
@given(graphs())
def test_any_graph_is_labelled_as_scipy_labels_it(graph):
    """Same labels, same numbering (by each component's smallest base), same dtype: springs in any
    order, repeated, reversed, joining a base to itself, or none."""
    n, pairs, kept = graph
    labels = components(n, pairs, kept)
    assert labels.dtype == np.int32
    np.testing.assert_array_equal(labels, scipy_labels(n, pairs, kept))


@pytest.mark.parametrize("shape", ["chain", "reversed chain", "shuffled chain", "star", "two stars", "lattice"])
def test_the_deep_cases_of_pointer_jumping(shape):
    """The shapes that make union-find deep: a long path in any order of its springs and bases, stars,
    a lattice with most springs broken."""
    rng = np.random.default_rng(7)
    n = 20_000
    path = np.column_stack([np.arange(n - 1), np.arange(1, n)])
    pairs = {"chain": path, "reversed chain": path[::-1, ::-1],
             "shuffled chain": rng.permutation(n)[path][rng.permutation(n - 1)],
             "star": np.column_stack([np.full(n - 1, n - 1), np.arange(n - 1)]),
             "two stars": np.column_stack([np.arange(n - 2) % 2 + n - 2, np.arange(n - 2)]),
             "lattice": np.array([(i, i + d) for d in (1, 140, 141) for i in range(n - d)])}[shape]
    kept = rng.random(len(pairs)) < 0.45 if shape == "lattice" else np.ones(len(pairs), bool)
    np.testing.assert_array_equal(components(n, pairs, kept), scipy_labels(n, pairs, kept))


def test_no_bases_and_no_springs():
    assert components(0, np.empty((0, 2), np.int64), np.empty(0, bool)).shape == (0,)
    np.testing.assert_array_equal(components(4, np.empty((0, 2), np.int64), np.empty(0, bool)), [0, 1, 2, 3])
    assert count_patches(components(4, np.array([[0, 1], [2, 3]]), np.array([True, False])), 2) == 1


def test_a_run_labels_its_patches_without_importing_scipy_sparse(tmp_path):
    """A short run on numpy, its patch statistics and files included, never imports scipy.sparse
    (the import it saves is the point of labelling on whole arrays)."""
    import subprocess
    import sys

    code = ("import sys; from bark_cli.main import main\n"
            "sys.argv = ['bark', 'simulate', '--until-time', '0.3', '--backend', 'numpy', '--out', sys.argv[1], '--quiet']\n"
            "try:\n    main()\n"
            "except SystemExit as e:\n    assert not e.code, e.code\n"
            "print(sorted(m for m in sys.modules if m.startswith('scipy.sparse')))")
    out = subprocess.run([sys.executable, "-c", code, str(tmp_path / "run")], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", out.stdout
    assert (tmp_path / "run" / "summary.json").exists()


@st.composite
def lattices(draw):
    """Springs as the numba kernel holds them: runs ``(position, length, first i, offset o)`` of
    springs ``(i, i + o)`` (an offset may be negative), free positions between runs, any live mask."""
    n = draw(st.integers(1, 150))
    offsets = draw(st.lists(st.integers(-n + 1, n - 1).filter(lambda o: o != 0), max_size=4)) if n > 1 else []
    starts, lengths, firsts, gaps = [], [], [], 0
    for o in offsets:
        first = draw(st.integers(max(0, -o), n - 1 - max(o, 0)))
        length = draw(st.integers(0, n - max(o, 0) - first))
        starts.append(gaps)
        lengths.append(length)
        firsts.append(first)
        gaps += length + draw(st.integers(0, 3))
    live = np.array(draw(st.lists(st.booleans(), min_size=gaps, max_size=gaps)), dtype=bool)
    runs = tuple(np.array(a, dtype=np.int64) for a in (starts, lengths, firsts, offsets))
    return n, runs, live


@settings(max_examples=300, deadline=None)
@given(lattices(), st.integers(1, 9))
def test_the_kernel_counts_patches_as_the_labels_count_them(lattice, min_size):
    """The count a kernel call takes for a patch-count stop (``_patch_count``, over its runs and live
    mask) is ``count_patches`` of scipy's labels of the same springs, and the compiled labels
    (``_components``, which shares its union) are scipy's."""
    from bark.engine.kernels.numba_backend import _components, _patch_count

    n, runs, live = lattice
    pairs = [(i + q, i + q + o) for s, length, i, o in zip(*runs) for q in range(length)]
    kept = [live[s + q] for s, length, i, o in zip(*runs) for q in range(length)]
    pairs = np.array(pairs, dtype=np.int64).reshape(-1, 2)
    expected = scipy_labels(n, pairs, kept)
    assert _patch_count(runs, live, n, min_size) == count_patches(expected, min_size)
    labels = np.empty(n, np.int32)
    _components(n, pairs[:, 0], pairs[:, 1], np.array(kept, dtype=bool), labels)
    np.testing.assert_array_equal(labels, expected)
