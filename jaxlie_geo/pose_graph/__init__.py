"""Pose graphs: g2o and TORO files, and a sparse Gauss–Newton / Levenberg–Marquardt solver.

A pose graph holds poses Tᵢ (SE2 or SE3) and relative-pose measurements Zᵢⱼ ≈ Tᵢ⁻¹ Tⱼ
with their information matrices; ``solve`` finds the poses that minimise
½ Σ ρ(‖rᵢⱼ‖²_Ω) with rᵢⱼ = log(Zᵢⱼ⁻¹ Tᵢ⁻¹ Tⱼ). See ``docs/pose-graphs.md``.

    graph = pose_graph.read("w10000.graph")
    solution = pose_graph.solve(graph, progress=True)
    pose_graph.write("w10000-optimised.g2o", solution.graph)
"""

from ._factors import Cauchy as Cauchy
from ._factors import Huber as Huber
from ._files import read as read
from ._files import write as write
from ._graph import PoseGraph as PoseGraph
from ._solver import Solution as Solution
from ._solver import graph_cost as graph_cost
from ._solver import solve as solve

__all__ = ["PoseGraph", "read", "write", "solve", "Solution", "graph_cost", "Huber", "Cauchy"]
