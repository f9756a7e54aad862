"""CasADi functions evaluated on numpy arrays without building a DM per argument and result.

A Newton iteration of a steady state evaluates its residual and Jacobian many thousands of times
in an optimisation or a sizing; through ``Function.__call__`` each evaluation wraps its numpy
arguments into DMs and each result is turned back into numpy through a Python list of every
element (``DM.full``), which cost several times the evaluation itself. CasADi's buffer interface
(``Function.buffer``, CasADi >= 3.6) evaluates into arrays it is given instead; the values are
the function's own, bit for bit (tested).
"""

from __future__ import annotations

import math
from functools import lru_cache

import casadi as ca
import numpy as np
import scipy.sparse


#: BLAS threads for a Newton step's dense solve (threadpoolctl; None: the libraries' own count): its matrices, at
#: most the dense limit's 600 unknowns, are too small for a second thread to pay, and beside another busy process
#: a two-thread solve waited for the busy core (benchmarks/results/twin_blas_threads.md).
NEWTON_BLAS_THREADS = 1


@lru_cache(maxsize=1)
def _blas_controller():
    from threadpoolctl import ThreadpoolController  # scans the loaded libraries: once

    return ThreadpoolController()


def newton_blas_threads():
    """A context in which the BLAS libraries run :data:`NEWTON_BLAS_THREADS` threads (their own count again
    after it)."""
    return _blas_controller().limit(limits=NEWTON_BLAS_THREADS, user_api="blas")


class Evaluator:
    """Numeric evaluation of ``fn`` (dense vector arguments). A call returns the results whose
    index is in ``matrices`` as 2-D arrays, or with ``sparse`` as scipy CSC matrices (CasADi's
    own compressed-column layout, stored zeros as CasADi stores them); the others as flat dense
    arrays (column-major). Results are copies; the buffers are this evaluator's, so one evaluator
    serves one caller (make one per solve, not one per thread)."""

    def __init__(self, fn: ca.Function, matrices=(), sparse: bool = False):
        self._layout = _layout(fn, tuple(matrices), sparse)
        self._buffer, self._evaluate = fn.buffer()
        self._args = [np.zeros(fn.nnz_in(i)) for i in range(fn.n_in())]
        self._res = [np.zeros(fn.nnz_out(i)) for i in range(fn.n_out())]
        for i, a in enumerate(self._args):
            self._buffer.set_arg(i, memoryview(a))
        for i, r in enumerate(self._res):
            self._buffer.set_res(i, memoryview(r))

    def __call__(self, *args):
        for a, v in zip(self._args, args, strict=True):
            a[:] = np.ravel(np.asarray(v, float))  # a wrong length raises here
        self._evaluate()
        out = []
        for r, layout in zip(self._res, self._layout):
            if layout[0] == "flat":
                out.append(r.copy())
            elif layout[0] == "csc":
                _, row, colind, shape = layout
                out.append(scipy.sparse.csc_matrix((r.copy(), row.copy(), colind.copy()), shape=shape))  # layout shared
            else:
                _, where, shape = layout
                full = np.zeros(math.prod(shape))
                full[where] = r
                out.append(full.reshape(shape))
        return out


@lru_cache(maxsize=128)
def _layout(fn: ca.Function, matrices: tuple, sparse: bool) -> tuple:
    """How :class:`Evaluator` lays out each result of ``fn`` (made once per function: a Newton
    solve makes an evaluator, and reading the sparsity patterns cost more than its iterations'
    arithmetic on the circuit twin); ValueError if an argument is not a dense vector."""
    for i in range(fn.n_in()):
        if not (fn.sparsity_in(i).is_dense() and fn.sparsity_in(i).is_vector()):
            raise ValueError(f"Evaluator: argument {fn.name_in(i)!r} of {fn.name()!r} is not a dense vector.")
    layout = []
    for i in range(fn.n_out()):
        sp = fn.sparsity_out(i)
        rows, cols = (np.array(v, dtype=np.intp) for v in sp.get_triplet())
        if i in matrices and sparse:
            layout.append(("csc", np.array(sp.row()), np.array(sp.colind()), sp.shape))
        elif i in matrices:  # row-major positions of the stored entries
            layout.append(("matrix", rows * sp.size2() + cols, sp.shape))
        elif sp.is_dense():
            layout.append(("flat",))
        else:  # column-major positions of the stored entries
            layout.append(("vector", cols * sp.size1() + rows, (sp.numel(),)))
    return tuple(layout)
