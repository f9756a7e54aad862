"""twin.solve.numeric.Evaluator: a CasADi function's values on numpy, bit for bit those of its
ordinary call, in every layout it returns; and the steady-state Newton on either layout."""

import casadi as ca
import numpy as np
import pytest

import twin.solve.steady as steady
from twin import Twin
from twin.solve.numeric import Evaluator


@pytest.fixture(scope="module")
def lab():
    tw = Twin("B")
    return tw, tw.steady(feed_tph=0.031, speed_frac_critical=0.7)


def _inputs(tw, ss, seed):
    """A state near the steady one (every mass moved by up to 20 %): Jacobians not at a root."""
    x = ss.x * (1.0 + 0.2 * np.random.default_rng(seed).uniform(-1.0, 1.0, ss.x.size))
    return np.concatenate([x, tw.model.z_of(x)]), ss.u, ss.d


@pytest.mark.parametrize("sparse", [False, True])
def test_the_jacobians_are_the_functions_own_bit_for_bit(lab, sparse):
    tw, ss = lab
    fn = steady._jacobians(tw.model)
    ev = Evaluator(fn, matrices=(1, 2), sparse=sparse)  # dH/dw (a sparse row) left a flat vector
    for seed in range(3):
        w, u, d = _inputs(tw, ss, seed)
        r, J, ju, jh = ev(w, u, d)
        want = fn(w, u, d)
        assert np.array_equal(r, np.asarray(want[0], float).ravel())
        for got, dm in ((J, want[1]), (ju, want[2])):
            assert isinstance(got, np.ndarray) != sparse
            dense = got.toarray() if sparse else got
            assert dense.shape == dm.shape and np.array_equal(dense, np.asarray(ca.DM(dm), float))
        assert jh.shape == (w.size,) and np.array_equal(jh, np.asarray(ca.DM(want[3]), float).ravel())
        assert fn.nnz_out(3) < w.size  # the row is sparse: its scatter is what was checked


def test_results_are_copies_and_arguments_are_checked(lab):
    tw, ss = lab
    ev = Evaluator(steady._jacobians(tw.model), matrices=(1,))
    first = ev(*_inputs(tw, ss, 0))
    kept = [a.copy() for a in first]
    ev(*_inputs(tw, ss, 1))
    assert all(np.array_equal(a, b) for a, b in zip(first, kept))
    w, u, d = _inputs(tw, ss, 0)
    with pytest.raises(ValueError):
        ev(w[:-1], u, d)  # one value short
    with pytest.raises(ValueError):
        ev(w, u)  # an argument missing
    m = ca.SX.sym("m", 2, 2)
    with pytest.raises(ValueError, match="'i0'.*not a dense vector"):
        Evaluator(ca.Function("f", [m], [m * 2]))


def test_newton_on_sparse_blocks_finds_the_dense_steady_state(lab, monkeypatch):
    """Above DENSE_MAX_UNKNOWNS the Newton matrix is CSC and solved by sparse LU: the same steady
    state (free feed, and at constant load) to round-off."""
    tw, ss = lab
    dense_load = tw.steady_at_constant_load(0.7, load_frac=1.1)
    monkeypatch.setattr(steady, "DENSE_MAX_UNKNOWNS", 0)
    sparse = tw.steady(feed_tph=0.031, speed_frac_critical=0.7)
    sparse_load = tw.steady_at_constant_load(0.7, load_frac=1.1)
    assert np.allclose(sparse.x, ss.x, rtol=1e-9, atol=1e-15) and sparse.p80_um == pytest.approx(ss.p80_um, rel=1e-9)
    assert sparse_load.feed_tph == pytest.approx(dense_load.feed_tph, rel=1e-9)
    assert sparse_load.outputs["load_frac"] == pytest.approx(1.1, rel=1e-9)


def test_the_newton_solves_run_on_one_blas_thread_and_give_it_back(monkeypatch):
    """A steady state's dense solves are small: on a 2-core machine beside another busy process OpenBLAS's second
    thread made them ~2x slower (benchmarks/results/twin_blas_threads.md). Every solve of a steady state runs with
    the BLAS libraries at NEWTON_BLAS_THREADS threads; after it they have their own count again."""
    from threadpoolctl import threadpool_info

    import twin.solve.steady as steady
    from twin import Twin
    from twin.solve.numeric import NEWTON_BLAS_THREADS

    def blas_threads():
        return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]

    own = blas_threads()
    seen, solve = [], steady._solve

    def watched(A, b):
        seen.append(blas_threads())
        return solve(A, b)

    monkeypatch.setattr(steady, "_solve", watched)
    Twin("B").steady()
    assert seen and all(threads == [NEWTON_BLAS_THREADS] * len(own) for threads in seen)
    assert blas_threads() == own
