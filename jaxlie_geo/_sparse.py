"""Block-sparse normal equations (H + λD) δ = −g of a least-squares problem, and their
solvers.

The residuals come in *factors*: factor f depends on m variables ``index[f]`` (distinct),
has a whitened residual e_f ``(r,)`` and Jacobian blocks A_f,a = ∂e_f/∂δ_index[f,a]
``(r, k)``, k the tangent dimension of every variable. Then H = Σ_f A_fᵀ A_f has a k × k
block at (u, v) for every pair of variables that share a factor, and g = Σ_f A_fᵀ e_f.
A pose graph's edges are factors on two poses and its anchor one on the first; a spline's
samples are factors on the ``degree + 1`` control points that shape them.

The host solvers, and the device one ``least_squares`` adds:

- **Sparse Cholesky.** The per-factor blocks are summed into the upper triangle of H in
  compressed-column form, through a scatter map built once per problem (its pattern never
  changes), and factorised with a symbolic analysis once and a numeric factorisation at
  every damping a Levenberg–Marquardt loop tries, by one of two packages:

  * CHOLMOD (Chen, Davis, Hager and Rajamanickam, *Algorithm 887: CHOLMOD, supernodal
    sparse Cholesky factorization and update/downdate*, ACM TOMS 35(3), 2008) through
    ``cvxopt`` (``cvxopt.cholmod``), supernodal. cvxopt is GPL-3 licensed, as CHOLMOD's
    supernodal module is: an optional extra (``jaxlie_geo[cholmod]``), never a dependency.
  * QDLDL (Stellato, Banjac, Goulart, Bemporad and Boyd, *OSQP: an operator splitting
    solver for quadratic programs*, 2020, §5.1), the square-root-free LDLᵀ with an
    approximate-minimum-degree ordering, Apache-2.0 (``jaxlie_geo[pose-graph]``). Its
    supernodes are single columns, so the blocks of a 3D graph factorise several times
    slower (``docs/design/pose-graph-solver.md``).
- **Banded Cholesky**: LAPACK's ``pbtrf`` through SciPy (installed with JAX), on H stored by
  diagonals; O(size · bandwidth²) time and O(size · bandwidth) memory. Right when the
  variables' order keeps H narrow, as a spline's does (bandwidth (degree + 1)·k).
- **Dense Cholesky**: LAPACK's ``potrf`` on all of H, O(size³): for small problems.
- **Preconditioned conjugate gradients** on any device, matrix-free, in
  ``least_squares``.
"""

from __future__ import annotations

import importlib
from typing import Any, Optional, Sequence

import numpy as onp


class BlockPattern:
    """The upper triangle of H in compressed-column form, and the map that sums the factors'
    blocks' upper-triangle values into it (one ``numpy.bincount``), built once per problem.

    Arguments:
        indices: per factor set, the host array ``(F, m)`` of its factors' variables.
        num_variables: n; H is ``(n·k, n·k)``.
        k: the tangent dimension.

    Attributes:
        size, nnz: n·k and the number of stored (upper-triangle) entries.
        indices, indptr, columns: the compressed-column pattern (row of every entry, start
            of every column, column of every entry).
        scatter, diagonal: where each block value (of every distinct variable tuple) and
            each diagonal entry sits among the ``nnz``.
        segment_ids, segment_counts: per factor set, the id of each factor's variable tuple
            and the number of distinct tuples where tuples repeat (``None`` and F where
            they do not).
        bandwidth: the largest column − row of a stored entry.
    """

    def __init__(self, indices: Sequence[onp.ndarray], num_variables: int, k: int):
        size = num_variables * k
        rows, cols = [], []
        self.segment_ids: list = []
        self.segment_counts: list = []
        for index in indices:
            index = onp.asarray(index, onp.int64)
            same = index[:, :, None] == index[:, None, :]
            if onp.any(same & ~onp.eye(index.shape[1], dtype=bool)):
                raise ValueError("BlockPattern: a factor names one variable twice")
            if float(num_variables) ** index.shape[1] < 2.0**62:  # one int64 key per tuple
                key = index @ (num_variables ** onp.arange(index.shape[1], dtype=onp.int64))
                _, first, ids = onp.unique(key, return_index=True, return_inverse=True)
                tuples = index[first]
            else:
                tuples, ids = onp.unique(index, axis=0, return_inverse=True)
            repeats = len(tuples) < len(index)
            self.segment_ids.append(ids.ravel().astype(onp.int32) if repeats else None)
            self.segment_counts.append(len(tuples) if repeats else len(index))
            if repeats:
                index = tuples
            p, q = onp.triu_indices(index.shape[1] * k)
            r = index[:, p // k] * k + p % k
            c = index[:, q // k] * k + q % k
            rows.append(onp.minimum(r, c).ravel())
            cols.append(onp.maximum(r, c).ravel())
        row, col = onp.concatenate(rows), onp.concatenate(cols)
        diagonal = onp.arange(size)  # every diagonal entry exists, even if unconstrained
        keys = onp.concatenate([col * size + row, diagonal * size + diagonal])
        unique, inverse = onp.unique(keys, return_inverse=True)
        self.size = size
        self.nnz = len(unique)
        self.indices = (unique % size).astype(onp.int64)
        self.indptr = onp.searchsorted(unique // size, onp.arange(size + 1)).astype(onp.int64)
        self.columns = onp.repeat(onp.arange(size), onp.diff(self.indptr))  # of each nonzero
        self.scatter = inverse[: len(row)].astype(onp.int64)
        self.diagonal = inverse[len(row) :].astype(onp.int64)
        self.bandwidth = int(onp.max(self.columns - self.indices))

    def assemble(self, values: onp.ndarray) -> onp.ndarray:
        """The nonzeros of H's upper triangle, in compressed-column order."""
        return onp.bincount(self.scatter, weights=values, minlength=self.nnz)


def installed(backend: str) -> bool:
    """Whether the package of a sparse Cholesky backend (``"cholmod"``, ``"qdldl"``)
    imports."""
    modules = {"cholmod": ("cvxopt", "cvxopt.cholmod"), "qdldl": ("qdldl", "scipy.sparse")}
    try:
        for module in modules[backend]:
            importlib.import_module(module)
    except ImportError:
        return False
    return True


def require(backend: str) -> None:
    """``ImportError`` naming the extra to install, where ``backend``'s package does not
    import."""
    if not installed(backend):
        extra, package = ("cholmod", "cvxopt") if backend == "cholmod" else ("pose-graph", "qdldl")
        raise ImportError(
            f"linear_solver={backend!r} needs the {package} package: pip install "
            f"'jaxlie_geo[{extra}]', or use linear_solver='pcg'."
        )


class SparseCholesky:
    """(H + λD) δ = −g on the host by CHOLMOD (``backend="cholmod"``, supernodal unless
    ``supernodal=False``) or QDLDL (``"qdldl"``); the symbolic analysis is done once, on the
    first ``solve``."""

    def __init__(self, pattern: BlockPattern, backend: str = "qdldl", supernodal: bool = True):
        if backend not in ("cholmod", "qdldl"):
            raise ValueError(
                f"SparseCholesky: backend must be 'cholmod' or 'qdldl', got {backend!r}"
            )
        require(backend)
        self.backend = backend
        self.supernodal = supernodal
        self.pattern = pattern
        self._solver: Optional[Any] = None
        self._matrix: Optional[Any] = None

    def solve(self, data: onp.ndarray, damping: onp.ndarray, g: onp.ndarray) -> onp.ndarray:
        """δ for the nonzeros ``data`` of H, the diagonal ``damping`` λD added, and the
        gradient ``g`` (flat)."""
        pat = self.pattern
        damped = data.copy()
        damped[pat.diagonal] += damping
        if self.backend == "cholmod":
            return self._solve_cholmod(damped, g)
        csc = importlib.import_module("scipy.sparse").csc_matrix
        matrix = csc((damped, pat.indices, pat.indptr), shape=(pat.size, pat.size))
        if self._solver is None:
            self._solver = importlib.import_module("qdldl").Solver(matrix, upper=True)
        else:
            self._solver.update(matrix, upper=True)
        return -self._solver.solve(g)

    def _solve_cholmod(self, damped: onp.ndarray, g: onp.ndarray) -> onp.ndarray:
        cvxopt = importlib.import_module("cvxopt")
        cholmod = importlib.import_module("cvxopt.cholmod")
        pat = self.pattern
        if self._matrix is None:
            # Built once in compressed-column order (sorted, no duplicates), so that its
            # values are ``damped`` in the same order; the symbolic analysis once too.
            self._matrix = cvxopt.spmatrix(
                cvxopt.matrix(damped),
                cvxopt.matrix(pat.indices.astype(onp.int64)),
                cvxopt.matrix(pat.columns.astype(onp.int64)),
                (pat.size, pat.size),
            )
            if list(self._matrix.I) != pat.indices.tolist():  # pragma: no cover
                raise AssertionError("cvxopt reordered the compressed-column pattern")
            saved = cholmod.options.get("supernodal")
            cholmod.options["supernodal"] = 2 if self.supernodal else 0  # never "choose" (1)
            try:
                self._solver = cholmod.symbolic(self._matrix, uplo="U")
            finally:  # cvxopt's options are global: leave them as they were
                if saved is None:
                    del cholmod.options["supernodal"]
                else:
                    cholmod.options["supernodal"] = saved
        else:
            self._matrix.V = cvxopt.matrix(damped)  # (``V`` is a copy: ``V[:] =`` is lost)
        try:
            cholmod.numeric(self._matrix, self._solver)
        except ArithmeticError:  # not positive definite: a non-finite step, as QDLDL gives
            return onp.full(pat.size, onp.nan)
        x = cvxopt.matrix(-g)
        cholmod.solve(self._solver, x)
        return onp.asarray(x).ravel()


class BandedCholesky:
    """(H + λD) δ = −g on the host by LAPACK's banded Cholesky (``scipy.linalg``), H held by
    its ``pattern.bandwidth + 1`` upper diagonals; ``dense=True`` holds and factorises all
    of H instead (``potrf``)."""

    def __init__(self, pattern: BlockPattern, dense: bool = False):
        self.pattern, self.dense = pattern, dense
        self.linalg = importlib.import_module("scipy.linalg")
        u, n = pattern.bandwidth, pattern.size
        rows, cols = pattern.indices, pattern.columns
        self.shape = (n, n) if dense else (u + 1, n)
        self.where = rows * n + cols if dense else (u + rows - cols) * n + cols

    def solve(self, data: onp.ndarray, damping: onp.ndarray, g: onp.ndarray) -> onp.ndarray:
        """As ``SparseCholesky.solve``; a matrix that is not positive definite gives NaN."""
        damped = data.copy()
        damped[self.pattern.diagonal] += damping
        H = onp.zeros(self.shape)
        H.flat[self.where] = damped
        la = self.linalg
        try:
            if self.dense:
                return la.cho_solve(la.cho_factor(H, check_finite=False), -g, check_finite=False)
            return la.cho_solve_banded((la.cholesky_banded(H, check_finite=False), False), -g)
        except la.LinAlgError:
            return onp.full(self.pattern.size, onp.nan)
