"""Fragments of a broken agglomerate, their size distribution and t10.

Rule for a piece (documented and tested in ``tests/dem/test_fragments_lab.py``):

1. spheres joined by *intact* bonds form a graph;
2. a **bridge** of that graph (a bond whose removal disconnects it, i.e. a bond that is the
   single last link between two groups) does **not** hold two groups together when each side
   has at least ``min_side_spheres`` spheres (default 2): two pieces hinging on one last bond
   are counted as two pieces. A lone sphere hanging on its only bond stays with its piece (it is
   a surface sphere, not a hinge);
3. pieces are the connected components of the graph after those bridges are cut.

Bridges are found with Tarjan's low-link depth-first search (Tarjan, Inf. Process. Lett. 2
(1974) 160), side sizes from the DFS subtree sizes.

Sizes: a fragment of sphere volume ``V`` from a particle of size ``D0`` and total sphere
volume ``V0`` has the size ``D0 (V/V0)^(1/3)`` (equal-solidity equivalent size; the intact
particle has size ``D0``). The size distribution is reported on a sqrt(2) sieve series
``D0 sqrt(2)^-k``; ``t10`` is the mass fraction passing ``D0/10`` (Narayanan & Whiten 1988).
With ``n`` spheres a single sphere has size about ``D0 n^(-1/3)``: t10 resolves only if that is
well below ``D0/10``, i.e. ``n`` above ~1000 (the result's ``t10_resolved`` says so).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

from dem.errors import DemInputError
from dem.materials import check_float


@dataclass(frozen=True)
class FragmentResult:
    """Pieces after a test.

    Fields
    ------
    labels : (n_spheres,) piece id of each sphere (0 = largest piece).
    n_fragments : number of pieces (single spheres count).
    sizes_m : (n_fragments,) equivalent sizes, largest first.
    mass_fractions : (n_fragments,) mass fraction of each piece, largest first.
    largest_mass_fraction : mass fraction of the largest piece.
    t10 : mass fraction passing ``D0/10``.
    t10_resolved : whether a single sphere is smaller than ``D0/10`` on average.
    bridges_cut : number of single-bond hinges cut by rule 2.
    size_distribution : DataFrame ``sieve_size_m``, ``sieve_size_rel`` (= size/D0),
        ``passing_frac`` (cumulative mass fraction finer than the sieve).
    """

    labels: np.ndarray
    n_fragments: int
    sizes_m: np.ndarray
    mass_fractions: np.ndarray
    largest_mass_fraction: float
    t10: float
    t10_resolved: bool
    bridges_cut: int
    size_distribution: pd.DataFrame
    original_size_m: float = float("nan")

    def t(self, n: float) -> float:
        """t_n: mass fraction finer than ``D0 / n`` (t10 = t(10); t2, t4 are resolved by coarse agglomerates)."""
        if not (n >= 1):
            raise DemInputError(f"The 'n' parameter of FragmentResult.t must be a float >= 1. Got {n!r}.")
        return float(np.sum(self.mass_fractions[self.sizes_m < self.original_size_m / n]))


def _find_bridges(n: int, edges: np.ndarray):
    """Bridges of an undirected graph; returns (edge ids, side sizes (child side, other side))."""
    m = edges.shape[0]
    adj_start = np.zeros(n + 1, dtype=np.int64)
    if m:
        np.add.at(adj_start, edges[:, 0] + 1, 1)
        np.add.at(adj_start, edges[:, 1] + 1, 1)
    np.cumsum(adj_start, out=adj_start)
    adj_to = np.empty(2 * m, dtype=np.int64)
    adj_eid = np.empty(2 * m, dtype=np.int64)
    fill = adj_start[:-1].copy()
    for e in range(m):
        a, b = edges[e]
        adj_to[fill[a]] = b
        adj_eid[fill[a]] = e
        fill[a] += 1
        adj_to[fill[b]] = a
        adj_eid[fill[b]] = e
        fill[b] += 1
    disc = np.full(n, -1, dtype=np.int64)
    low = np.zeros(n, dtype=np.int64)
    sub = np.ones(n, dtype=np.int64)
    comp = np.full(n, -1, dtype=np.int64)
    comp_size: list[int] = []
    bridges: list[tuple[int, int]] = []  # (edge id, child vertex)
    t = 0
    for root in range(n):
        if disc[root] >= 0:
            continue
        cid = len(comp_size)
        members = 0
        stack = [(root, -1, adj_start[root])]
        disc[root] = low[root] = t
        t += 1
        comp[root] = cid
        members += 1
        while stack:
            v, pe, it = stack[-1]
            if it < adj_start[v + 1]:
                stack[-1] = (v, pe, it + 1)
                w = adj_to[it]
                e = adj_eid[it]
                if e == pe:
                    continue
                if disc[w] < 0:
                    disc[w] = low[w] = t
                    t += 1
                    comp[w] = cid
                    members += 1
                    stack.append((w, e, adj_start[w]))
                else:
                    low[v] = min(low[v], disc[w])
            else:
                stack.pop()
                if stack:
                    p = stack[-1][0]
                    low[p] = min(low[p], low[v])
                    sub[p] += sub[v]
                    if low[v] > disc[p]:
                        bridges.append((pe, v))
        comp_size.append(members)
    ids = np.array([b[0] for b in bridges], dtype=np.int64)
    child = np.array([sub[b[1]] for b in bridges], dtype=np.int64)
    other = np.array([comp_size[comp[b[1]]] - sub[b[1]] for b in bridges], dtype=np.int64)
    return ids, child, other


def _components(n: int, edges: np.ndarray) -> np.ndarray:
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    if edges.shape[0] == 0:
        return np.arange(n)
    g = coo_matrix((np.ones(edges.shape[0]), (edges[:, 0], edges[:, 1])), shape=(n, n))
    _, lab = connected_components(g, directed=False)
    return lab


def find_fragments(bond_pairs: np.ndarray, intact: np.ndarray, sphere_volume_m3: np.ndarray,
                   original_size_m: float, *, min_side_spheres: int = 2,
                   n_sieves: int = 16) -> FragmentResult:
    """Pieces (see the module rule), their sizes, the sqrt(2) sieve distribution and t10.

    ``bond_pairs`` (m, 2) whole sphere indices; ``intact`` (m,) booleans, True for an intact bond
    (:attr:`dem.bonds.BondSet.intact`; integer state codes are refused: 0 is the *intact* code);
    ``sphere_volume_m3`` (n,) finite volumes > 0; ``original_size_m`` finite > 0;
    ``n_sieves`` an int >= 1."""
    vol = np.asarray(sphere_volume_m3, dtype=float).reshape(-1)
    n = vol.shape[0]
    if n < 1 or not np.all(np.isfinite(vol) & (vol > 0)):
        raise DemInputError(
            "The 'sphere_volume_m3' parameter of find_fragments must be one finite volume > 0 per sphere "
            f"(at least one). Got {n} entries, min {vol.min() if n else None!r}.")
    raw = np.asarray(bond_pairs)
    if raw.size and not (raw.dtype.kind in "iu" or (raw.dtype.kind == "f" and np.all(raw == np.round(raw)))):
        raise DemInputError(
            f"The 'bond_pairs' parameter of find_fragments must hold whole sphere indices. Got dtype {raw.dtype}.")
    pairs = raw.astype(np.int64).reshape(-1, 2)
    if pairs.size and (pairs.min() < 0 or pairs.max() >= n):
        raise DemInputError(
            f"The 'bond_pairs' parameter of find_fragments must index the {n} spheres of sphere_volume_m3. "
            f"Got indices from {int(pairs.min())} to {int(pairs.max())}.")
    if pairs.size and np.any(pairs[:, 0] == pairs[:, 1]):  # a sphere bonded to itself held a piece together
        raise DemInputError("The 'bond_pairs' parameter of find_fragments must pair two spheres; rows "
                            f"{np.nonzero(pairs[:, 0] == pairs[:, 1])[0][:5].tolist()} bond a sphere to itself.")
    intact = np.asarray(intact)
    if intact.size and intact.dtype != np.bool_:
        raise DemInputError(
            "The 'intact' parameter of find_fragments must be booleans (BondSet.intact: True = intact), not "
            f"bond state codes (0 = intact). Got dtype {intact.dtype}.")
    intact = intact.astype(bool).reshape(-1)
    if not (isinstance(n_sieves, (int, np.integer)) and n_sieves >= 1):
        raise DemInputError(f"The 'n_sieves' parameter of find_fragments must be an int >= 1. Got {n_sieves!r}.")
    if intact.shape[0] != pairs.shape[0]:
        raise DemInputError(
            f"The 'intact' parameter of find_fragments must have one entry per bond ({pairs.shape[0]}). "
            f"Got {intact.shape[0]}.")
    if not (isinstance(min_side_spheres, (int, np.integer)) and min_side_spheres >= 1):
        raise DemInputError(
            f"The 'min_side_spheres' parameter of find_fragments must be an int >= 1. Got {min_side_spheres!r}.")
    original_size_m = check_float("find_fragments", "original_size_m", original_size_m, 0.0, math.inf,
                                  lo_open=True, hi_open=True)
    edges = pairs[intact]
    ids, child, other = _find_bridges(n, edges)
    cut = ids[(child >= min_side_spheres) & (other >= min_side_spheres)]
    keep = np.ones(edges.shape[0], dtype=bool)
    keep[cut] = False
    lab = _components(n, edges[keep])
    frag_vol = np.bincount(lab, weights=vol)
    order = np.argsort(-frag_vol, kind="stable")
    remap = np.empty_like(order)
    remap[order] = np.arange(order.size)
    labels = remap[lab]
    frag_vol = frag_vol[order]
    total = float(np.sum(vol))
    frac = frag_vol / total
    sizes = original_size_m * frac ** (1.0 / 3.0)
    sieves = original_size_m * math.sqrt(2.0) ** (1 - np.arange(n_sieves + 1))
    passing = np.array([float(np.sum(frac[sizes < s])) for s in sieves])
    psd = pd.DataFrame({"sieve_size_m": sieves, "sieve_size_rel": sieves / original_size_m,
                        "passing_frac": passing})
    t10 = float(np.sum(frac[sizes < original_size_m / 10.0]))
    single = original_size_m * (1.0 / n) ** (1.0 / 3.0)
    return FragmentResult(labels=labels, n_fragments=int(frag_vol.size), sizes_m=sizes,
                          mass_fractions=frac, largest_mass_fraction=float(frac[0]), t10=t10,
                          t10_resolved=bool(single < 0.1 * original_size_m), bridges_cut=int(cut.size),
                          size_distribution=psd, original_size_m=float(original_size_m))
