"""The normal equations (H + λD) δ = −g of a linearised pose graph, kept block-sparse.

H = Σ_edges Aᵀ A has a k × k block on the diagonal for every pose and one off the
diagonal for every pair of poses joined by an edge; g = Σ Aᵀ e. Two ways to solve:

- **Sparse Cholesky on the host.** The blocks are summed into the upper triangle of H in
  compressed-column form, through a scatter map built once per graph (its pattern never
  changes), and factorised with a symbolic analysis once per graph and a numeric
  factorisation at every damping a Levenberg–Marquardt loop tries, by one of two packages:

  * CHOLMOD (Chen, Davis, Hager and Rajamanickam, *Algorithm 887: CHOLMOD, supernodal
    sparse Cholesky factorization and update/downdate*, ACM TOMS 35(3), 2008) through
    ``cvxopt`` (``cvxopt.cholmod``), supernodal. cvxopt is GPL-3 licensed, as CHOLMOD's
    supernodal module is: an optional extra (``jaxlie_geo[cholmod]``), never a dependency.
  * QDLDL (Stellato, Banjac, Goulart, Bemporad and Boyd, *OSQP: an operator splitting
    solver for quadratic programs*, 2020, §5.1), the square-root-free LDLᵀ with an
    approximate-minimum-degree ordering, Apache-2.0 (``jaxlie_geo[pose-graph]``): the
    fallback. Its supernodes are single columns, so the blocks of a 3D graph factorise
    several times slower (``docs/design/pose-graph-solver.md``).
- **Preconditioned conjugate gradients** (``jax.scipy.sparse.linalg.cg``) on any device,
  matrix-free: H x = Σ Aᵀ(A x) over the edges, which shard across devices with the edges.
  The preconditioner is block Jacobi: the inverse of H's k × k diagonal blocks.
"""

from __future__ import annotations

import importlib
from typing import Any, Optional

import jax
import jax.numpy as jnp
import numpy as onp

from .._xla import matmul
from ._factors import Linearisation, Problem, mv, tr

#: Damping D = diag(H), clipped below to this so that a direction the data do not
#: constrain is still damped (as in Ceres Solver's Levenberg–Marquardt strategy).
DAMPING_FLOOR = 1e-6


def gradient_and_diagonal(
    lin: Linearisation, p: Problem, num_poses: int
) -> tuple[jax.Array, jax.Array]:
    """g = Σ Aᵀe, ``(N, k)``, and H's diagonal blocks Σ AᵀA, ``(N, k, k)``."""
    seg = jax.ops.segment_sum
    n = num_poses
    g = seg(mv(tr(lin.A_i), lin.e), p.edge_i, n) + seg(mv(tr(lin.A_j), lin.e), p.edge_j, n)
    g = g.at[0].add(mv(lin.A_0.T, lin.e_0))
    D = seg(matmul(tr(lin.A_i), lin.A_i), p.edge_i, n) + seg(
        matmul(tr(lin.A_j), lin.A_j), p.edge_j, n
    )
    D = D.at[0].add(matmul(lin.A_0.T, lin.A_0))
    return g, D


def hessian_values(lin: Linearisation) -> jax.Array:
    """Every edge's contributions to H in the order ``BlockPattern`` expects: per edge the
    upper triangles of A_iᵀA_i and A_jᵀA_j and all of A_iᵀA_j; then the anchor's upper
    triangle. Flat, ``(E·(k² + k(k+1)) + k(k+1)/2,)``."""
    k = lin.e.shape[-1]
    iu = onp.triu_indices(k)
    H_ii = matmul(tr(lin.A_i), lin.A_i)[:, iu[0], iu[1]]
    H_jj = matmul(tr(lin.A_j), lin.A_j)[:, iu[0], iu[1]]
    H_ij = matmul(tr(lin.A_i), lin.A_j).reshape(-1, k * k)
    H_00 = matmul(lin.A_0.T, lin.A_0)[iu[0], iu[1]]
    return jnp.concatenate([jnp.concatenate([H_ii, H_jj, H_ij], axis=1).ravel(), H_00])


class BlockPattern:
    """The upper triangle of H in compressed-column form, and the map that sums the
    values of ``hessian_values`` into it (one ``numpy.bincount``), built once per graph.

    Arguments:
        edge_i, edge_j: ``(E,)`` pose indices of the edges, i ≠ j.
        num_poses: N.
        k: the tangent dimension.
    """

    def __init__(self, edge_i: onp.ndarray, edge_j: onp.ndarray, num_poses: int, k: int):
        iu_a, iu_b = onp.triu_indices(k)
        a, b = onp.divmod(onp.arange(k * k), k)
        i = edge_i.astype(onp.int64)[:, None]
        j = edge_j.astype(onp.int64)[:, None]
        # H_ij[a, b] sits at (i k + a, j k + b) when i < j, else transposed at (j k + b, i k + a).
        row_ij = onp.where(i < j, i * k + a, j * k + b)
        col_ij = onp.where(i < j, j * k + b, i * k + a)
        rows = onp.concatenate([i * k + iu_a, j * k + iu_a, row_ij], axis=1).ravel()
        cols = onp.concatenate([i * k + iu_b, j * k + iu_b, col_ij], axis=1).ravel()
        rows = onp.concatenate([rows, iu_a])  # the anchor on pose 0
        cols = onp.concatenate([cols, iu_b])
        size = num_poses * k
        diagonal = onp.arange(size)  # every diagonal entry exists, even if unconstrained
        keys = onp.concatenate([cols * size + rows, diagonal * size + diagonal])
        unique, inverse = onp.unique(keys, return_inverse=True)
        self.size = size
        self.nnz = len(unique)
        self.indices = (unique % size).astype(onp.int64)
        self.indptr = onp.searchsorted(unique // size, onp.arange(size + 1)).astype(onp.int64)
        self.columns = onp.repeat(onp.arange(size), onp.diff(self.indptr))  # of each nonzero
        self.scatter = inverse[: len(rows)].astype(onp.int64)
        self.diagonal = inverse[len(rows) :].astype(onp.int64)

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


class SparseCholesky:
    """(H + λD) δ = −g on the host by CHOLMOD (``backend="cholmod"``, supernodal unless
    ``supernodal=False``) or QDLDL (``"qdldl"``); the symbolic analysis is done once, on the
    first ``solve``."""

    def __init__(self, pattern: BlockPattern, backend: str = "qdldl", supernodal: bool = True):
        if backend not in ("cholmod", "qdldl"):
            raise ValueError(
                f"SparseCholesky: backend must be 'cholmod' or 'qdldl', got {backend!r}"
            )
        if not installed(backend):
            extra, package = (
                ("cholmod", "cvxopt") if backend == "cholmod" else ("pose-graph", "qdldl")
            )
            raise ImportError(
                f"linear_solver={backend!r} needs the {package} package: pip install "
                f"'jaxlie_geo[{extra}]', or use linear_solver='pcg'."
            )
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


def pcg(
    lin: Linearisation,
    p: Problem,
    g: jax.Array,
    D: jax.Array,
    damping: jax.Array,
    tolerance: float,
    max_iterations: int,
) -> jax.Array:
    """δ ``(N, k)`` solving (H + diag(damping)) δ = −g by conjugate gradients with the
    block-Jacobi preconditioner (D + diag(damping))⁻¹, D the diagonal blocks of H."""
    n, k = g.shape

    def matvec(x: jax.Array) -> jax.Array:
        u = mv(lin.A_i, x[p.edge_i]) + mv(lin.A_j, x[p.edge_j])
        y = jax.ops.segment_sum(mv(tr(lin.A_i), u), p.edge_i, n)
        y = y + jax.ops.segment_sum(mv(tr(lin.A_j), u), p.edge_j, n)
        y = y.at[0].add(mv(lin.A_0.T, mv(lin.A_0, x[0])))
        return y + damping * x

    blocks = D + damping[..., None] * jnp.eye(k, dtype=D.dtype)
    inverse = jnp.linalg.inv(blocks)
    delta, _ = jax.scipy.sparse.linalg.cg(
        matvec, -g, tol=tolerance, maxiter=max_iterations, M=lambda r: mv(inverse, r)
    )
    return delta
