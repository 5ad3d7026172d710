"""The sparse factorisations of the pose-graph solver on each public dataset's normal matrix.

For each dataset in ``gtsam``'s wheel, H + λI at the initial estimate (the matrix the
solver's first Levenberg–Marquardt step factorises, λ = 1e-5) is factorised and solved by:

* QDLDL (``qdldl``): the symbolic analysis and first factorisation, then a refactorisation
  of the same pattern (``update``) and solve;
* CHOLMOD through ``cvxopt``, simplicial and supernodal: ``cholmod.symbolic`` once, then
  ``cholmod.numeric`` and ``cholmod.solve``;

each through the solver's own ``SparseCholesky``.

Times are the median of ``--repeats`` refactorisations (one thread each, the process
alone), with the first (analysis included) reported apart. Every solution is checked
against QDLDL's to 1e-8 relative. Prints a Markdown table; the design note
``docs/design/pose-graph-solver.md`` quotes it.

  python -m benchmarks.sparse_cholesky
  python -m benchmarks.sparse_cholesky --datasets sphere2500 --repeats 20
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from benchmarks import common as C
from jaxlie_geo._xla import x64

DATASETS = {
    "w10000": ("w10000", {}),
    "sphere2500": ("sphere2500", {}),
    "pose3example-grid": ("pose3example-grid", {}),
    "w20000": ("w20000", {"information_order": "g2o"}),
}


def normal_matrix(name: str):
    """(pattern, upper-triangle values of H + 1e-5·I, g) at the dataset's initial poses."""
    import gtsam

    from jaxlie_geo import pose_graph
    from jaxlie_geo.pose_graph import _solver

    file, options = DATASETS[name]
    graph = pose_graph.read(gtsam.findExampleDataFile(file), **options)
    with x64(True):
        p, poses = _solver._problem(graph, 1e-6, None)
        edges = np.stack([np.asarray(p.edge_i), np.asarray(p.edge_j)], -1)
        path = _solver.lsq.system(
            _solver._GraphModel(graph.group, None), p, [edges, np.zeros((1, 1))],
            graph.num_poses, 3 if graph.dim == 2 else 6, "qdldl",
        )  # fmt: skip
        path.linearise(poses)
    data = path.values.copy()
    data[path.pattern.diagonal] += 1e-5
    return path.pattern, data, path.g


def timed(solver, data: np.ndarray, g: np.ndarray, repeats: int):
    """(first solve, analysis included; median of ``repeats`` refactorisations and solves;
    the solution) of a ``SparseCholesky``."""
    zero = np.zeros(len(g))
    first = time.perf_counter()
    out = solver.solve(data, zero, g)
    first = time.perf_counter() - first
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        out = solver.solve(data, zero, g)
        times.append(time.perf_counter() - t)
    return first, statistics.median(times), out


def measure(name: str, repeats: int) -> dict:
    from jaxlie_geo._sparse import SparseCholesky

    pattern, data, g = normal_matrix(name)
    row = {"unknowns": pattern.size, "nonzeros (upper)": pattern.nnz}
    methods = {
        "qdldl": ("qdldl", True),
        "cholmod simplicial": ("cholmod", False),
        "cholmod supernodal": ("cholmod", True),
    }
    for method, (backend, supernodal) in methods.items():
        row[method] = timed(SparseCholesky(pattern, backend, supernodal), data, g, repeats)
        got, want = row[method][2], row["qdldl"][2]
        assert np.allclose(got, want, rtol=1e-8, atol=1e-8 * np.abs(want).max()), (name, method)
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--datasets", nargs="*", default=list(DATASETS))
    parser.add_argument("--repeats", type=int, default=10)
    args = parser.parse_args()
    info = C.machine_info("benchmarks.sparse_cholesky")
    print(f"{info['cpu']}, {info['cores']} cores; jax {info['jax']}; commit {info['commit']}\n")
    methods = ("qdldl", "cholmod simplicial", "cholmod supernodal")
    print("| dataset | unknowns | nonzeros (upper) | " + " | ".join(methods) + " |")
    print("|---|--:|--:|" + "--:|" * len(methods))
    for name in args.datasets:
        row = measure(name, args.repeats)
        cells = [f"{row[m][1] * 1e3:.1f} ms ({row[m][0] * 1e3:.0f} first)" for m in methods]
        print(
            f"| {name} | {row['unknowns']:,} | {row['nonzeros (upper)']:,} | "
            + " | ".join(cells)
            + " |",
            flush=True,
        )


if __name__ == "__main__":
    main()
