"""``jax_debug_nans`` without jit: JAX then checks the output of every primitive, values that a
select discards included, so a NaN made and thrown away inside a kernel raises. Valid input
must make none; input without a direction must give NaN.

Reference: the delicate tangents of ``special_tangents`` (0, 1e-12, exactly π, pure
translations), where 0/0 forms and inf·0 lurk.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _calls import module_calls, public_calls
from conftest import over_groups, special_tangents, to_np


@over_groups
def test_debug_nans_without_jit(G):
    """Under ``jax_debug_nans`` with jit disabled, JAX checks every primitive's output, even
    values a select discards: no public or module function, value or derivative, may make
    a NaN from valid input at the delicate tangents (0, 1e-12, exactly π, pure
    translations). ``normalize`` (a NaN constant for direction-less input) and
    ``motion.arc`` (sign(ω)·inf at ω = 0) raised FloatingPointError for every valid pose.
    Input without a direction still gives NaN, and the alarm then is right."""
    dtype = np.float64
    x = special_tangents(G, dtype)[:6]
    n = x.shape[0]
    ctx = {
        "dtype": dtype,
        "T": G.exp(x),
        "U": G.exp(x[::-1].copy()),
        "x": x,
        "p": np.zeros((n, G.space_dim), dtype),
        "t": np.linspace(0.0, 1.0, n).astype(dtype),
        "theta": np.asarray([0.0, 1e-12, np.pi, -np.pi, 1.0, 2.0], dtype),
    }
    calls = {**public_calls(G), **module_calls(G)}
    with jax.disable_jit(), jax.debug_nans(True):
        for name, call in calls.items():
            try:
                call(ctx)
            except FloatingPointError as e:
                raise AssertionError(f"{G.__name__}.{name}: {str(e).splitlines()[0]}") from None
        bad = G(jnp.zeros(G.parameters_dim, dtype))
        with pytest.raises(FloatingPointError):
            bad.normalize()
    out = bad.normalize()
    rot = out.rotation() if hasattr(out, "rotation") else out
    assert np.all(np.isnan(to_np(rot.parameters()))), out
