"""Preconditioned conjugate gradients on the pose-graph normal equations, on one CPU thread.

For each dataset, A = H + λI at the initial estimate (H as ``sparse_cholesky.normal_matrix``
builds it) and b = −g are solved by ``scipy.sparse.linalg.cg`` to relative residual 1e-10
(at most 5,000 iterations) with the preconditioners:

* none; block-Jacobi (the inverse of each k×k diagonal block: the solver's own ``pcg``);
* smoothed-aggregation algebraic multigrid (``pyamg``, one V-cycle): its defaults, and
  block-aware (A as BSR with k×k blocks, near-nullspace the k constant vectors, symmetric);
* incomplete LU (``scipy.sparse.linalg.spilu``, symmetric ordering, no pivoting);

and, for reference, by CHOLMOD (the solver's ``SparseCholesky``, numeric factorisation and
solve after the symbolic analysis). Reported: setup and solve time (median of 3 runs when a
run takes under 5 s), iterations, relative residual ||Ax − b|| / ||b||, and the error of x
relative to the CHOLMOD solution. Prints a Markdown table.

  python -m benchmarks.pcg_preconditioners
  python -m benchmarks.pcg_preconditioners --datasets sphere2500 --damping 1e-5
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"  # one thread: before numpy is imported

import argparse  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402
import scipy.sparse.linalg as spla  # noqa: E402

from benchmarks import sparse_cholesky as _sc  # noqa: E402


def block_jacobi(A, k):
    n = A.shape[0]
    blocks = np.stack([A[i : i + k, i : i + k].toarray() for i in range(0, n, k)])
    inverse = np.linalg.inv(blocks)
    matvec = lambda r: np.einsum("nab,nb->na", inverse, r.reshape(-1, k)).ravel()
    return spla.LinearOperator((n, n), matvec=matvec)


def amg(A, k, block):
    import pyamg

    if not block:
        return pyamg.smoothed_aggregation_solver(A).aspreconditioner(cycle="V")
    B = np.kron(np.ones((A.shape[0] // k, 1)), np.eye(k))
    ml = pyamg.smoothed_aggregation_solver(
        sp.bsr_matrix(A, blocksize=(k, k)), B=B, symmetry="symmetric"
    )
    return ml.aspreconditioner(cycle="V")


def ilu(A, drop_tol, fill_factor):
    lu = spla.spilu(
        A.tocsc(),
        drop_tol=drop_tol,
        fill_factor=fill_factor,
        permc_spec="MMD_AT_PLUS_A",
        diag_pivot_thresh=0.0,
    )
    return spla.LinearOperator(A.shape, matvec=lu.solve)


PRECONDITIONERS = {
    "none": lambda A, k: None,
    "block-Jacobi": block_jacobi,
    "AMG (pyamg SA, defaults)": lambda A, k: amg(A, k, False),
    "AMG (pyamg SA, BSR k×k, symmetric)": lambda A, k: amg(A, k, True),
    "ILU (spilu 1e-4, fill 10)": lambda A, k: ilu(A, 1e-4, 10),
    "ILU (spilu 1e-5, fill 20)": lambda A, k: ilu(A, 1e-5, 20),
}


def timed(run):
    """(median setup, median solve, last result) of ``run() -> (setup, solve, result)``."""
    runs = [run()]
    if runs[0][0] + runs[0][1] < 5.0:
        runs += [run(), run()]
    return statistics.median(r[0] for r in runs), statistics.median(r[1] for r in runs), runs[-1][2]


def measure(name: str, damping: float):
    from jaxlie_geo._sparse import SparseCholesky

    pattern, data, g = _sc.normal_matrix(name)  # data: H + 1e-5·I
    g, n = np.asarray(g).ravel(), pattern.size
    k = 6 if "sphere" in name or "pose3" in name else 3
    data = data.copy()
    data[pattern.diagonal] += damping - 1e-5
    upper = sp.csc_matrix((data, pattern.indices, pattern.indptr), shape=(n, n))
    A = (upper + sp.triu(upper, 1).T).tocsr()
    assert abs(A - A.T).max() == 0.0
    b = -g  # the solver's convention: A x = −g
    residual = lambda x: np.linalg.norm(A @ x - b) / np.linalg.norm(b)
    chol = SparseCholesky(pattern, "cholmod")
    zero = np.zeros(n)
    x_ref = chol.solve(data, zero, g)  # the symbolic analysis, untimed
    assert residual(x_ref) < 1e-10 and residual(spla.spsolve(A.tocsc(), b)) < 1e-10

    def direct():
        t = time.perf_counter()
        x = chol.solve(data, zero, g)
        return 0.0, time.perf_counter() - t, (x, None)

    rows = [("CHOLMOD (refactorise + solve)", *timed(direct))]
    for label, make in PRECONDITIONERS.items():

        def run(make=make):
            t = time.perf_counter()
            M = make(A, k)
            setup = time.perf_counter() - t
            count = [0]
            callback = lambda xk: count.__setitem__(0, count[0] + 1)
            t = time.perf_counter()
            x, _ = spla.cg(A, b, rtol=1e-10, maxiter=5000, M=M, callback=callback)
            return setup, time.perf_counter() - t, (x, count[0])

        rows.append((label, *timed(run)))
    for label, setup, solve, (x, its) in rows:
        error = np.linalg.norm(x - x_ref) / np.linalg.norm(x_ref)
        its = "–" if its is None else f"{its:,}"
        print(
            f"| {name} | {damping:g} | {label} | {setup:.3f} | {its} | {solve:.3f} | "
            f"{setup + solve:.3f} | {residual(x):.1e} | {error:.1e} |",
            flush=True,
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--datasets", nargs="*", default=["w10000", "sphere2500"])
    parser.add_argument("--damping", nargs="*", type=float, default=[1e-5, 1e-2])
    args = parser.parse_args()
    print(
        "| dataset | λ | preconditioner | setup (s) | CG iterations | solve (s) | total (s) "
        "| rel. residual | rel. error vs CHOLMOD |"
    )
    print("|---|--:|---|--:|--:|--:|--:|--:|--:|")
    for name in args.datasets:
        for damping in args.damping:
            measure(name, damping)


if __name__ == "__main__":
    main()
