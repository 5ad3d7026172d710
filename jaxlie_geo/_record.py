"""The host side of ``pose_graph.solve`` and ``splines.fit``: their options' checks, and the
record of a solve (the cost and the wall-clock time at each linearisation point, from
``least_squares.solve``'s ``callback``) with its progress line.

A leaf module. ``callback`` is one function for every solve, so that the compiled loop
(which ``jit`` keys on its callback) is reused; it writes to the innermost ``Record``
that ``recording`` holds open.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import sys
import time
import typing
from typing import Dict, Iterator, List, Tuple

import numpy as onp

from . import hints

#: The names ``linear_solver`` accepts.
LINEAR_SOLVERS = typing.get_args(hints.LinearSolver)


@dataclasses.dataclass(frozen=True)
class Solve:
    """The record of a solve, which ``pose_graph.solve`` and ``splines.fit`` extend.

    Attributes:
        costs: ``(iterations + 1,)``, the cost before the first and after every accepted
            step.
        times: ``(iterations + 1,)``, for each cost the wall-clock seconds from the start
            of the call to its evaluation (the first includes building the problem and, for
            a new problem size, compiling).
        iterations: accepted steps.
        time: wall-clock seconds of the whole call.
        stop_reason: why it stopped, in words (``least_squares.StopReason.description``).
        converged: whether it stopped at a minimum: on the tolerance, or with no step
            lowering the cost at any damping (rather than at the iteration limit, for
            Gauss–Newton on a step that raised the cost or a singular system, or, for either
            method, where the cost is not finite).
    """

    costs: onp.ndarray
    times: onp.ndarray
    iterations: int
    time: float
    stop_reason: str
    converged: bool


def check_options(
    caller: str, method: str, linear_solver: str, max_iterations: int, **positive: float
) -> None:
    """``ValueError`` naming the argument, for a method, linear solver or iteration limit
    out of range, or a value of ``positive`` that is not a positive finite number."""
    if method not in ("lm", "gn"):
        raise ValueError(f"{caller}: method must be 'lm' or 'gn', got {method!r}")
    if linear_solver not in LINEAR_SOLVERS:
        names = ", ".join(repr(s) for s in LINEAR_SOLVERS)
        raise ValueError(f"{caller}: linear_solver must be one of {names}, got {linear_solver!r}")
    for name, value in positive.items():
        if not (value > 0 and math.isfinite(value)):
            raise ValueError(f"{caller}: {name} must be a positive number, got {value!r}")
    if not (isinstance(max_iterations, int) and max_iterations >= 0):
        raise ValueError(
            f"{caller}: max_iterations must be a non-negative int, got {max_iterations!r}"
        )


class Record:
    """Costs and times of one solve, and its progress line on stderr: iteration, cost, step
    size, λ and time; redrawn in place on a terminal, one line per iteration otherwise."""

    def __init__(self, start: float, progress: bool, max_iterations: int):
        self.start, self.progress, self.max_iterations = start, progress, max_iterations
        self.tty = progress and sys.stderr.isatty()
        self.points: Dict[int, Tuple[float, float]] = {}

    def add(self, it: int, cost: float, step: float, lam: float) -> None:
        if it in self.points:  # sharded: every device reports each point
            return
        seconds = time.perf_counter() - self.start
        self.points[it] = (cost, seconds)
        if not self.progress:
            return
        width = 20
        filled = min(width, round(width * it / max(self.max_iterations, 1)))
        line = (
            f"[{'#' * filled}{'.' * (width - filled)}] iteration {it:4d}  cost {cost:.9e}  "
            f"step {step:.2e}  λ {lam:.1e}  {seconds:7.2f} s"
        )
        sys.stderr.write(("\r" + line) if self.tty else (line + "\n"))
        sys.stderr.flush()

    def close(self, reason: str) -> None:
        """The last line: why it stopped."""
        if self.progress:
            sys.stderr.write(("\n" if self.tty else "") + f"stopped: {reason}\n")
            sys.stderr.flush()

    def arrays(self, iterations: int) -> Tuple[onp.ndarray, onp.ndarray]:
        """``(costs, times)``, one entry per linearisation point 0..iterations."""
        rows = [self.points[it] for it in range(iterations + 1)]
        return onp.asarray([c for c, _ in rows]), onp.asarray([t for _, t in rows])


_OPEN: List[Record] = []


@contextlib.contextmanager
def recording(record: Record) -> Iterator[Record]:
    """``callback`` writes to ``record`` inside this block (block on the solve's result
    before leaving it, so that every call has arrived)."""
    _OPEN.append(record)
    try:
        yield record
    finally:
        _OPEN.pop()


def callback(it: int, cost: float, step: float, lam: float) -> None:
    """``least_squares.solve``'s callback: to the innermost open record."""
    _OPEN[-1].add(it, cost, step, lam)
