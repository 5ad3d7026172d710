"""The numeric tier's machinery: many properties of one group and dtype from one evaluation.

In JAX the cost of a test is the programs it compiles, so the numeric property tests share
them: one batch shape for every group and dtype, each operation evaluated once per process
for all the properties that read it. A module of the numeric tier writes

* a *program*: a pure function ``program(G, data) -> dict of arrays`` that evaluates every
  operation its properties need on the batch ``data`` (a dict of arrays and group elements);
  ``run(program, G, data)`` evaluates it (see ``run`` for how it compiles: the batch shape
  is fixed, so every module and every seed of the random batches reuses the same compiled
  operations) and returns numpy arrays;
* *checks*: functions ``check(G, dtype, data, out)`` registered with ``@checks.add``, each
  asserting one property of the outputs against an independent reference (numpy, scipy,
  the generators of conftest, autodiff evaluated inside the program);

and tests parametrised over the check names, which read the outputs computed once per
process (``results``), so a failure names the property, the group and the dtype.

The batch (``regime_batch``) has two batch axes and spans the regimes of every kernel:
``special_tangents`` (zero, 1e-12, pure translations, exactly π, π − 1e-6, long
translations), generic angles up to 3, tiny (1e-12), small (1e-8 … 0.1, log-uniform),
near π (2.9 … 3) and a mixed draw, with Haar-random elements ``T``, ``U``, ``V``.
"""

from __future__ import annotations

import functools
from typing import Any, Callable, Dict, Tuple

import jax
import numpy as np
from conftest import (
    random_element,
    random_points,
    random_tangent,
    special_tangents,
)

BATCH: Tuple[int, ...] = (4, 8)
"""The numeric tier's batch shape: two batch axes, 32 elements."""

_KINDS = (("generic", 5), ("tiny", 5), ("small", 5), ("large", 5), ("mixed", 5))

Data = Dict[str, Any]
Out = Dict[str, np.ndarray]
Check = Callable[[type, Any, Data, Out], None]


def regime_tangents(G: type, seed: int, dtype: Any, max_angle: float = 3.0) -> np.ndarray:
    """32 tangents of ``dtype`` in the shape ``BATCH``: the 7 special tangents, then 5 of each
    regime of ``conftest.random_tangent`` (angles up to ``max_angle``)."""
    parts = [np.asarray(special_tangents(G, np.float64))]
    for i, (kind, n) in enumerate(_KINDS):
        parts.append(random_tangent(G, seed + i, (n,), np.float64, kind, max_angle=max_angle))
    x = np.concatenate(parts)
    return x.reshape(*BATCH, G.tangent_dim).astype(dtype)


def regime_batch(G: type, dtype: Any, seed: int = 0) -> Data:
    """The inputs of a numeric program: tangents ``x`` (``regime_tangents``), ``y`` (generic,
    angles up to 3) and ``x10`` (angles up to 10), elements ``T``, ``U``, ``V`` (Haar),
    points ``p``, all in the shape ``BATCH``; the seed varies all of them."""
    return {
        "x": regime_tangents(G, seed, dtype),
        "y": random_tangent(G, seed + 1, BATCH, dtype),
        "x10": random_tangent(G, seed + 2, BATCH, dtype, max_angle=10.0),
        "T": random_element(G, seed, BATCH, dtype),
        "U": random_element(G, seed + 1, BATCH, dtype),
        "V": random_element(G, seed + 2, BATCH, dtype),
        "p": random_points(G, seed, BATCH, dtype),
    }


def run(program: Callable[..., Out], G: type, data: Data) -> Out:
    """``program(G, data)`` as float64-comparable numpy arrays.

    The program runs eagerly: each library operation in it is the library's own jitted
    function, compiled once per group, dtype and shape and shared by every module that
    uses the same batch. Jitting a whole program as one compiles slower than its operations
    one by one (test_axioms' program in float64, cold cache: SO3 6.4 s against 5.7 s in 43
    programs, SE3 13.5 s against 8.5 s, Sim3 35.2 s against 21.2 s: XLA's compile time
    grows faster than linearly with a program's size), and its operations could not be
    shared. A derivative inside a program is a module-level ``jax.jit`` function,
    compiled once per group and dtype.
    """
    return jax.tree.map(np.asarray, program(G, data))


class Checks(dict):
    """Named property checks of one module (``@checks.add`` registers a function)."""

    def add(self, fn: Check) -> Check:
        self[fn.__name__] = fn
        return fn

    def run_all(self, G: type, dtype: Any, data: Data, out: Out) -> None:
        """Every check; the first failure names its property."""
        for name, fn in self.items():
            try:
                fn(G, dtype, data, out)
            except AssertionError as e:
                raise AssertionError(f"{name}: {e}") from e


@functools.lru_cache(maxsize=None)
def results(
    prepare: Callable[[type, Any, int], Data],
    program: Callable[..., Out],
    G: type,
    dtype: Any,
    seed: int = 0,
) -> Tuple[Data, Out]:
    """``(data, run(program, G, data))`` with ``data = prepare(G, dtype, seed)``, computed
    once per process: the session's results that the parametrised tests read."""
    data = prepare(G, dtype, seed)
    return data, run(program, G, data)
