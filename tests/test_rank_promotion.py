"""``jax.numpy_rank_promotion("raise")``: users who set it (to catch accidental broadcasting
in their own code) must not see it fire inside ours, whose batch axes broadcast by design.

Reference: the same calls with rank promotion allowed, and explicit broadcasting of the
batch shapes.
"""

from __future__ import annotations

import jax
import numpy as np
import pytest
from _calls import TWO_OPERANDS, context, module_calls, public_calls
from conftest import over_groups


@pytest.mark.parametrize("higher", ["T", "U"])
@over_groups
def test_rank_promotion_raise(G, higher):
    """Every public function and module function, values and derivatives, runs under
    ``jax.numpy_rank_promotion("raise")`` with batch axes of different ranks: T and x of
    batch (2, 3) against U, points and times of batch (3,), and (``higher="U"``, for the
    functions of two operands) the reverse. Results have the broadcast batch shape, and
    equal those computed with rank promotion allowed. jaxlie fails this for compose and
    inverse; our group inverses, SO3/SE2 Jacobians, binary operations, geodesics and
    motion failed too. Rank promotion is checked as operations are traced, so every call is
    traced (``jax.eval_shape``, which also gives the batch shape) and only the sample that
    is compared with promotion allowed is compiled and run."""
    dtype = np.float32
    hi, lo = (2, 3), (3,)
    bT, bU = (hi, lo) if higher == "T" else (lo, hi)
    ctx = context(G, dtype, bT, bU)
    calls = {**public_calls(G), **module_calls(G)}
    del calls["stack"]  # needs equal batch shapes
    if higher == "U":
        calls = {k: v for k, v in calls.items() if k in TWO_OPERANDS}
    compared = {"multiply", "apply", "interpolate_array_t", "jacobians.apply", "pose_at", "grad"}
    for name, call in calls.items():
        with jax.numpy_rank_promotion("raise"):
            shapes = jax.eval_shape(lambda call=call: call(ctx))
        if name in TWO_OPERANDS - {"grad", "propagate_compose", "propagate_apply", "pose_at"}:
            batch = jax.tree.leaves(shapes)[0].shape[:2]
            assert batch == hi, (name, batch)
        if name in compared:  # a sample, run, against implicit promotion
            with jax.numpy_rank_promotion("raise"):
                got = call(ctx)
            with jax.numpy_rank_promotion("allow"):
                want = call(ctx)
            for g, w in zip(jax.tree.leaves(got), jax.tree.leaves(want)):
                np.testing.assert_array_equal(np.asarray(g), np.asarray(w), err_msg=name)
