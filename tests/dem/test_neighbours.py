"""The Verlet list against an all-pairs search: every pair (i < j) within R_i + R_j + skin, by the
minimum image along z in a periodic slice, grouped by i, with its bond index; nothing else."""

import numpy as np
import pytest

from dem.kernels import NEIGHBOUR_BUFFER_MAX, build_neighbour_list


def _all_pairs(pos, rad, skin, lz):
    """The reference: every i < j tested, in j order within each i."""
    pairs = []
    for i in range(len(pos)):
        d = pos[i + 1:] - pos[i]
        if lz > 0:
            d[:, 2] -= lz * np.floor(d[:, 2] / lz + 0.5)
        rc = rad[i] + rad[i + 1:] + skin
        pairs += [(i, i + 1 + k) for k in np.flatnonzero(np.sum(d * d, axis=1) < rc * rc)]
    return set(pairs)


@pytest.mark.parametrize("one_scan", [True, False])
@pytest.mark.parametrize("lz, n", [(0.0, 400), (0.1, 500), (0.02, 300), (0.011, 60), (0.3, 800)])
def test_the_list_is_every_pair_within_reach(lz, n, one_scan):
    """A slice of 3 cells (the fewest that wrap), one cell thick (0.02 m, 0.011 m: no wrap
    offsets), many cells, and no periodicity; radii 4-6 mm, skin 1 mm. Both ways of filling the
    list: one scan into the buffer, and (a buffer above its cap) a count pass and a second scan."""
    rng = np.random.default_rng(int(1000 * lz) + n)
    rad = rng.uniform(0.004, 0.006, n)
    box = np.array([0.12, 0.1, lz if lz > 0 else 0.1])
    pos = rng.uniform(0.0, 1.0, (n, 3)) * box
    skin = 0.001
    partner = np.full((n, 2), -1, dtype=np.int64)
    index = np.full((n, 2), -1, dtype=np.int64)
    ref = _all_pairs(pos, rad, skin, lz)
    bonded = sorted(ref)[::7]  # some pairs carry a bond, numbered in this order
    for b, (i, j) in enumerate(bonded):
        s = int(np.sum(partner[i] >= 0))
        if s < 2:
            partner[i, s], index[i, s] = j, b
    cap = NEIGHBOUR_BUFFER_MAX if one_scan else 0
    pi, pj, pb, first = build_neighbour_list(pos, rad, skin, lz, partner, index, cap)
    assert set(zip(pi.tolist(), pj.tolist())) == ref and len(pi) == len(ref)
    assert np.all(np.diff(pi) >= 0) and np.all(pi < pj)
    np.testing.assert_array_equal(first, np.searchsorted(pi, np.arange(n + 1)))
    want = {(int(i), int(j)): int(index[i, s]) for i in range(n) for s in range(2)
            for j in [partner[i, s]] if j >= 0}
    got = {(int(i), int(j)): int(b) for i, j, b in zip(pi, pj, pb) if b >= 0}
    assert got == want and len(want) > 0
