"""Batches: indexing, reshaping, stacking and iteration as NumPy does them on the batch axes,
broadcasting between operands, large batches run in chunks (``_batch.in_chunks``), sharded
batches, and the memory the compiled programs allocate.

References: NumPy's indexing and stacking of the parameter array, explicit broadcasting,
the numpy matrix representation, the whole-batch path for the chunked one, one device's
result for the sharded one, and XLA's buffer assignment for memory.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import (
    GROUPS,
    assert_close,
    homogeneous_apply,
    is_se,
    over_dtypes,
    over_groups,
    over_groups_dtypes,
    over_seeds,
    random_element,
    random_points,
    to_np,
)

import jaxlie_geo
from jaxlie_geo import SE3, _batch, _xla

# ---------------------------------------------------------------------------------
# Indexing, reshaping, stacking and iteration.


@over_groups_dtypes
@over_seeds
def test_indexing_reshape_stack(G, dtype, seed):
    """Indexing, ``reshape`` and ``stack`` act on the batch axes as NumPy does on the
    parameter array with the parameter axis kept last; an indexed element behaves like the
    element itself."""
    T = random_element(G, seed, (2, 4), dtype)
    p = to_np(T.parameters())
    assert len(T) == 2
    np.testing.assert_array_equal(to_np(T[0].parameters()), p[0])
    np.testing.assert_array_equal(to_np(T[:, 1].parameters()), p[:, 1])
    np.testing.assert_array_equal(to_np(T[-1, 2].parameters()), p[-1, 2])
    np.testing.assert_array_equal(to_np(T[..., 1:3].parameters()), p[:, 1:3])
    assert T[0].get_batch_axes() == (4,) and T[:, 1].get_batch_axes() == (2,)
    assert T[1, 3].get_batch_axes() == ()
    assert type(T[0]) is G and T[0].parameters().dtype == dtype
    R = T.reshape((8,))
    assert R.get_batch_axes() == (8,)
    np.testing.assert_array_equal(to_np(R.parameters()), p.reshape(8, -1))
    assert T.reshape(4, 2).get_batch_axes() == (4, 2)
    np.testing.assert_array_equal(to_np(T.reshape(4, 2).parameters()), p.reshape(4, 2, -1))
    for shape in ((-1,), (2, -1), (-1, 1, 2)):  # -1 as in NumPy, the parameter axis kept
        np.testing.assert_array_equal(
            to_np(T.reshape(*shape).parameters()), p.reshape(*shape, G.parameters_dim)
        )
    S0 = jaxlie_geo.stack([T[0], T[1]], axis=0)
    np.testing.assert_array_equal(to_np(S0.parameters()), p)
    S1 = jaxlie_geo.stack([T[0], T[1]], axis=1)
    assert S1.get_batch_axes() == (4, 2)
    np.testing.assert_array_equal(to_np(S1.parameters()), np.swapaxes(p, 0, 1))
    Su = jaxlie_geo.stack([T[0, 0], T[1, 1], T[0, 3]])
    assert Su.get_batch_axes() == (3,) and Su.parameters().dtype == dtype
    np.testing.assert_array_equal(to_np(Su.parameters()), p[[0, 1, 0], [0, 1, 3]])
    # an indexed element behaves like the element itself
    assert_close(T[1, 2].log(), to_np(T.log())[1, 2], dtype)


@over_groups
def test_iteration_truthiness_and_static_index_range(G):
    """Iteration runs over the first batch axis (and ends), elements are always true (as in
    jaxlie), and static indices follow NumPy's rules, raising where NumPy raises."""
    T = random_element(G, 3, (3, 2), np.float32)
    p = to_np(T.parameters())
    parts = list(T)  # over the first batch axis; before, iteration never ended
    assert len(parts) == 3 and all(type(e) is G and e.get_batch_axes() == (2,) for e in parts)
    for i, e in enumerate(parts):
        np.testing.assert_array_equal(to_np(e.parameters()), p[i])
    a, b, c = T
    np.testing.assert_array_equal(to_np(c.parameters()), p[2])
    with pytest.raises(TypeError, match="unbatched"):
        list(T[0, 0])
    assert bool(T) and bool(G.identity())  # jaxlie's elements are always true
    # static integers out of range raise, as in NumPy (JAX alone would clamp to the end)
    # (also after ..., and in static integer lists and NumPy arrays; these once clamped)
    for index in (
        3,
        -4,
        (0, 2),
        (slice(None), -3),
        (None, 5),
        (..., 2),
        (..., -3),
        (0, ..., 5),
        [3],
        np.array([0, 3]),
        ([0, 1], ..., [2]),
        (0, 1, 0),
        (..., None, 2),
    ):
        with pytest.raises(IndexError, match="out of range"):
            T[index]
    np.testing.assert_array_equal(to_np(T[-3, -2].parameters()), p[0, 0])
    np.testing.assert_array_equal(to_np(T[None, 2].parameters()), p[None, 2])
    for index in (
        (..., 1),
        (..., -2),
        (2, ..., 1),
        (None, ..., 0, None),
        [2, 0],
        np.array([-3, 1]),
        ([0, 2], ..., [1, 0]),
        (p[..., 0] > 0,),
        (..., np.array([True, False])),
        (np.array([0, 2]), ...),
        (np.array([True, False, True]), ...),
        (..., 1, True),
        (True, 0),
        (np.True_, ..., None),
    ):
        idx = index if isinstance(index, tuple) else (index,)
        if not any(i is Ellipsis for i in idx):
            idx = (*idx, ...)
        want = p[(*idx, slice(None))]  # NumPy's rules on the batch axes, parameters last
        np.testing.assert_array_equal(to_np(T[index].parameters()), want)
    # advanced indices apart (NumPy moves their axes first): the parameter axis stays last
    U = random_element(G, 4, (2, 5, 3), np.float32)
    q = to_np(U.parameters())
    for index in ((0, slice(None), [1, 2]), ([1, 0], slice(None), [2, 2]), (0, ..., [1, 2])):
        got = U[index]
        np.testing.assert_array_equal(to_np(got.parameters()), q[(*index, slice(None))])
        assert got.log().shape == (*got.get_batch_axes(), G.tangent_dim)


@over_groups
def test_stack_axis_counts_batch_axes(G):
    """``stack(..., axis)`` counts among the batch axes, as ``np.stack`` on the batch:
    axis=-1 adds the last batch axis (the parameter axis stays last), and an axis past
    the batch rank raises instead of wrapping."""
    T, U = random_element(G, 1, (4,), np.float64), random_element(G, 2, (4,), np.float64)
    p, q = to_np(T.parameters()), to_np(U.parameters())
    S = jaxlie_geo.stack([T, U], axis=-1)
    assert S.get_batch_axes() == (4, 2)
    np.testing.assert_array_equal(to_np(S.parameters()), np.stack([p, q], axis=-2))
    for axis in (2, -3):
        with pytest.raises(ValueError, match="out of range"):
            jaxlie_geo.stack([T, U], axis=axis)


# ---------------------------------------------------------------------------------
# Broadcasting between operands.


@over_groups_dtypes
@over_seeds
def test_batch_axes_broadcast_between_operands(G, dtype, seed):
    """Batch axes of (3, 1) and (1, 4) broadcast to (3, 4) in compose, apply and interpolate
    (numpy matrix products and explicit broadcasting as references), and in SE constructors
    from parts."""
    P = G.parameters_dim
    T = G(jnp.asarray(np.asarray(random_element(G, seed, (3,), dtype).parameters())[:, None]))
    U = G(jnp.asarray(np.asarray(random_element(G, seed, (2, 4), dtype).parameters())[:1]))
    assert T.get_batch_axes() == (3, 1) and U.get_batch_axes() == (1, 4)
    MT, MU = to_np(T.as_matrix()), to_np(U.as_matrix())
    TU = T @ U
    assert TU.get_batch_axes() == (3, 4) and TU.parameters().dtype == dtype
    assert_close(TU.as_matrix(), MT @ MU, dtype, 4)
    p = random_points(G, seed, (1, 4), dtype)
    got = T @ p
    assert got.shape == (3, 4, G.space_dim) and got.dtype == dtype
    assert_close(
        got,
        homogeneous_apply(
            G,
            np.broadcast_to(MT, (3, 4, *MT.shape[-2:])),
            np.broadcast_to(to_np(p), (3, 4, G.space_dim)),
        ),
        dtype,
        4,
    )
    # interpolate broadcasts endpoints and times like explicit broadcasting does
    ts = np.linspace(0.0, 1.0, 4).astype(dtype)
    got = T.interpolate(U, ts)
    assert got.get_batch_axes() == (3, 4) and got.parameters().dtype == dtype
    T_full = G(jnp.asarray(np.broadcast_to(np.asarray(T.parameters()), (3, 4, P))))
    U_full = G(jnp.asarray(np.broadcast_to(np.asarray(U.parameters()), (3, 4, P))))
    want = T_full.interpolate(U_full, np.broadcast_to(ts, (3, 4)))
    assert_close(got.parameters(), want.parameters(), dtype)
    # an SE element built from a batched rotation and a translation broadcasts too
    if is_se(G):
        t = np.zeros((1, 4, G.space_dim), dtype)
        assert G.from_rotation_and_translation(T.rotation(), t).get_batch_axes() == (3, 4)


# ---------------------------------------------------------------------------------
# Large batches in chunks (``_batch.in_chunks``), sharded batches and memory.


@pytest.fixture
def small_chunks(monkeypatch):
    """``in_chunks`` with 256-element chunks from 512 elements on, so that a test-sized
    batch takes the chunked path. The sizes are read at trace time: the tests that use this
    fixture use batch shapes no other test traces, so no cached trace predates the change
    (and the jit caches, which every later test on this worker reuses, are not cleared)."""
    monkeypatch.setattr(_batch, "CHUNK", 256)
    monkeypatch.setattr(_batch, "CHUNKED_FROM", 512)
    yield
    monkeypatch.undo()


def _chunked_ops():
    """The operations that run large batches in chunks (``_batch.in_chunks``): f(params,
    other params, t) and its arguments' shapes."""
    ops = [
        (G, "interpolate", lambda p, q, t, G=G: G(p).interpolate(G(q), t).parameters())
        for G in GROUPS
        if G._schedule.interpolate_in_chunks
    ]
    assert ops  # SE3's
    return ops


@pytest.mark.parametrize(("G", "op", "f"), _chunked_ops(), ids=lambda x: getattr(x, "__name__", x))
@over_dtypes
def test_in_chunks_equals_whole_batch(G, op, f, dtype, small_chunks):
    """A large batch runs chunk by chunk (a loop in the compiled program); values, vmap
    and gradients (taken whole, by design: no loop) agree with the whole-batch path within
    a few ulp. The batch, 7 × 143, is not a multiple of the chunk, so the last chunk
    overlaps its predecessor; t extrapolates beyond 1 in the first chunk only."""
    batch = (7, 143)
    T, U = random_element(G, 0, batch, dtype), random_element(G, 1, batch, dtype)
    t = np.random.default_rng(2).uniform(-0.5, 0.9, batch).astype(dtype)
    t[0, :5] = 1.5

    def loss(p, q, t):
        return jnp.sum(jnp.sin(f(p, q, t)))

    args = (T.parameters(), U.parameters(), jnp.asarray(t))
    # Chunking is CPU-only; elsewhere both paths are the whole batch.
    assert ("while" in jax.jit(f).lower(*args).as_text()) == (jax.default_backend() == "cpu")
    assert "while" not in jax.jit(jax.grad(loss)).lower(*args).as_text()
    got, grads = f(*args), jax.grad(loss, argnums=(0, 1, 2))(*args)
    stacked = jax.vmap(f)(*(jnp.stack([a, a[::-1]]) for a in args))
    # The whole-batch path: f mapped over the 7 rows, each of 143 elements, below
    # CHUNKED_FROM (under vmap the decision sees the per-example batch).
    whole = jax.vmap(f)
    assert "while" not in jax.jit(whole).lower(*args).as_text()
    want = whole(*args)
    want_grads = jax.grad(lambda *a: jnp.sum(jnp.sin(whole(*a))), argnums=(0, 1, 2))(*args)
    assert_close(got, want, dtype, 4)
    for g, w in zip(grads, want_grads):
        assert_close(g, w, dtype, 16)
    assert_close(stacked[0], want, dtype, 4)
    assert_close(stacked[1], f(*(a[::-1] for a in args)), dtype, 4)


def _run_script(script: str) -> str:
    """Run ``script`` in a new Python process on CPU (the device count is fixed at jax's
    start), with ``GROUP_NAMES`` replaced by the names of the groups; its stdout."""
    code = script.replace("GROUP_NAMES", repr([G.__name__ for G in GROUPS]))
    out = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=600,
        env={**os.environ, "JAX_PLATFORMS": "cpu"},
    )
    assert out.returncode == 0, out.stderr[-3000:]
    return out.stdout


_SHARDED_SCRIPT = r"""
import os, sys
os.environ["XLA_FLAGS"] = "--xla_force_host_platform_device_count=4"
import jax, jax.numpy as jnp, numpy as np
from jax.sharding import NamedSharding, PartitionSpec as P
import jaxlie_geo
from jaxlie_geo import _batch

_batch.CHUNK, _batch.CHUNKED_FROM = 256, 512  # chunk a test-sized batch (as small_chunks)
n = 4096  # 1024 per device: shard_map's per-device batch is chunked too
rng = np.random.default_rng(0)
ops = {}
for G in (getattr(jaxlie_geo, name) for name in GROUP_NAMES):
    if G._schedule.interpolate_in_chunks:
        ops[G.__name__ + ".interpolate"] = (
            lambda a, b, t, G=G: G.exp(a).interpolate(G.exp(b), t).parameters(), G.tangent_dim)
SE3 = jaxlie_geo.SE3
ops["SE3.grad"] = (lambda a, b, t: jax.grad(
    lambda a: jnp.sum(SE3.exp(a).interpolate(SE3.exp(b), t).log() ** 2))(a), 6)
AxisType = getattr(jax.sharding, "AxisType", None)
for kind in ("Auto", "Explicit") if AxisType is not None else ("default",):
    extra = {} if AxisType is None else {"axis_types": (getattr(AxisType, kind),)}
    mesh = jax.make_mesh((4,), ("b",), **extra)
    for name, (f, k) in ops.items():
        # angles well below π: the gradient of log is ill-conditioned near π (60-80 ulp
        # between any two evaluation orders there), which is not what this test is about
        a, b = (0.5 * rng.normal(size=(n, k)).astype(np.float32) for _ in range(2))
        t = rng.uniform(-0.5, 1.5, n).astype(np.float32)
        want = np.asarray(jax.jit(f)(a, b, t))  # on one device, whole
        args = [jax.device_put(x, NamedSharding(mesh, P("b"))) for x in (a, b, t)]
        compiled = jax.jit(f).lower(*args).compile()
        assert "all-gather" not in compiled.as_text(), (kind, name)
        got = compiled(*args)
        assert tuple(got.sharding.spec)[:1] == ("b",), (kind, name, got.sharding)
        mapped = getattr(jax, "shard_map", None)
        if mapped is None:
            from jax.experimental.shard_map import shard_map as mapped
        g = jax.jit(mapped(f, mesh=mesh, in_specs=(P("b"),) * 3, out_specs=P("b"))).lower(*args)
        if hasattr(jax, "shard_map") and not name.endswith("grad"):
            assert "while" in g.as_text(), (kind, name)  # chunks per device
        for out in (got,) + (() if name.endswith("grad") else (g.compile()(*args),)):
            # In the row's scale. Shards and chunks compile and round differently (fusion),
            # and interpolate chains five operations: in
            # float32 each path is up to 10 ulp from a float64 evaluation, and the gradient
            # (through ten) 20-26 ulp.
            scale = np.maximum(1.0, np.max(np.abs(want), axis=-1, keepdims=True))
            err = np.max(np.abs(np.asarray(out) - want) / scale) / np.finfo(np.float32).eps
            assert err <= (64 if name.endswith("grad") else 16), (kind, name, err)
        print(kind, name, "ok", f"{err:.2f}")
"""


def test_chunked_ops_on_a_sharded_batch():
    """A batch sharded over several CPU devices (jax.sharding, 4 forced host devices, in
    a subprocess: the device count is fixed at jax's start). ``in_chunks``'s loop slices
    the batch axis, so it must not run there: with Explicit axes it failed to trace
    (dynamic_update_slice sharding mismatch) and with Auto axes XLA gathered the whole
    batch on every device and returned it replicated. The result keeps the input's
    sharding, the program has no all-gather, values match one device's, and inside
    ``shard_map`` (each device's own shard) the chunks run again."""
    stdout = _run_script(_SHARDED_SCRIPT)
    assert stdout.count(" ok") >= 4, stdout


_COLLECTIVES_SCRIPT = r"""
import json, os, time
flags = os.environ.get("XLA_FLAGS", "")
os.environ["XLA_FLAGS"] = flags + " --xla_force_host_platform_device_count=4"
import jax, jax.numpy as jnp, numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec as P
import jaxlie_geo
from jaxlie_geo import _batch, jacobians, manifold

COLLECTIVES = ("all-reduce", "all-gather", "collective-permute", "all-to-all", "reduce-scatter")
_batch.CHUNK, _batch.CHUNKED_FROM = 256, 512  # as small_chunks: the chunk decision is made
n = 1024  # above the batch size from which interpolate chunks (lowered to 512 here)
mesh = Mesh(np.array(jax.devices()), ("b",))
batched = NamedSharding(mesh, P("b"))
shard_map = getattr(jax, "shard_map", None)
if shard_map is None:
    from jax.experimental.shard_map import shard_map


def ops(G):
    # name -> (f, the inputs it takes); each f maps batches (n, ...) to batches (n, ...).
    # x: tangents, p and q: parameters, v: points, t: times, m: matrices.
    def loss(x, q):  # one element's scalar
        return jnp.sum((G.exp(x) @ G(q)).log() ** 2)

    return {
        "exp": (lambda x: G.exp(x).parameters(), "x"),
        "log": (lambda p: G(p).log(), "p"),
        "compose": (lambda p, q: (G(p) @ G(q)).parameters(), "pq"),
        "apply": (lambda p, v: G(p) @ v, "pv"),
        "inverse": (lambda p: G(p).inverse().parameters(), "p"),
        "normalize": (lambda p: G(p).normalize().parameters(), "p"),
        "interpolate": (lambda p, q, t: G(p).interpolate(G(q), t).parameters(), "pqt"),
        "as_matrix": (lambda p: G(p).as_matrix(), "p"),
        "from_matrix": (lambda m: G.from_matrix(m).parameters(), "m"),
        "adjoint": (lambda p: G(p).adjoint(), "p"),
        "is_valid": (lambda p: G(p).is_valid(), "p"),
        "jac_right": (G.jac_right, "x"),
        "jac_left": (G.jac_left, "x"),
        "jac_right_inv": (G.jac_right_inv, "x"),
        "jac_left_inv": (G.jac_left_inv, "x"),
        "jacobians.compose": (lambda p, q: jacobians.compose(G(p), G(q)), "pq"),
        "jacobians.inverse": (lambda p: jacobians.inverse(G(p)), "p"),
        "jacobians.between": (lambda p, q: jacobians.between(G(p), G(q)), "pq"),
        "jacobians.rminus": (lambda p, q: jacobians.rminus(G(p), G(q)), "pq"),
        "jacobians.rplus": (lambda p, x: jacobians.rplus(G(p), x), "px"),
        "jacobians.apply": (lambda p, v: jacobians.apply(G(p), v), "pv"),
        "jacobians.exp": (lambda x: jacobians.exp(G, x), "x"),
        "jacobians.log": (lambda p: jacobians.log(G(p)), "p"),
        "manifold.rplus": (lambda p, x: manifold.rplus(G(p), x).parameters(), "px"),
        "manifold.rminus": (lambda p, q: manifold.rminus(G(p), G(q)), "pq"),
        "vmap(grad)": (jax.vmap(jax.grad(loss)), "xq"),
    }


def collectives(f, *args):
    text = jax.jit(f).lower(*args).compile().as_text()
    return [c for c in COLLECTIVES if c in text]


rng = np.random.default_rng(0)
report = {"collectives": {}, "sharding": {}, "constant": [], "shard_map": {}}
start = time.perf_counter()
for G in (getattr(jaxlie_geo, name) for name in GROUP_NAMES):
    x, y = ((0.5 * rng.normal(size=(n, G.tangent_dim))).astype(np.float32) for _ in range(2))
    inputs = {
        "x": x,
        "p": np.asarray(G.exp(x).parameters()),
        "q": np.asarray(G.exp(y).parameters()),
        "m": np.asarray(G.exp(x).as_matrix()),
        "v": rng.normal(size=(n, G.space_dim)).astype(np.float32),
        "t": rng.uniform(0, 1, n).astype(np.float32),
    }
    sharded = {key: jax.device_put(a, batched) for key, a in inputs.items()}
    nans = {key: jax.device_put(np.full_like(a, np.nan), batched) for key, a in inputs.items()}
    table = ops(G)

    def every_op(arrays):
        return {name: f(*(arrays[c] for c in kinds)) for name, (f, kinds) in table.items()}

    # One program for all of the group's operations (half the compile time of one program
    # each); each operation is compiled alone only to name the ones with collectives.
    if collectives(every_op, sharded):
        for name, (f, kinds) in table.items():
            found = collectives(f, *(sharded[c] for c in kinds))
            if found:
                report["collectives"][f"{G.__name__}.{name}"] = found
    compiled = jax.jit(every_op).lower(sharded).compile()
    out, out_nan = compiled(sharded), compiled(nans)
    for name in table:
        for i, (a, b) in enumerate(zip(jax.tree.leaves(out[name]), jax.tree.leaves(out_nan[name]))):
            where = f"{G.__name__}.{name}[{i}]"
            if np.array_equal(np.asarray(a), np.asarray(b)):  # the same for NaN input
                report["constant"].append(where)
            elif not a.sharding.is_equivalent_to(batched, a.ndim):
                report["sharding"][where] = str(a.sharding)
    # shard_map: each device maps its own shard; equal to one device's whole batch
    for name, want in (("exp", inputs["p"]), ("log", np.asarray(G(inputs["p"]).log()))):
        f, kinds = table[name]
        got = jax.jit(shard_map(f, mesh=mesh, in_specs=P("b"), out_specs=P("b")))(sharded[kinds])
        err = float(np.max(np.abs(np.asarray(got) - want)) / np.finfo(np.float32).eps)
        if not err <= 8:
            report["shard_map"][f"{G.__name__}.{name}"] = f"{err:.1f} eps from one device"
report["seconds"] = round(time.perf_counter() - start, 1)
print(json.dumps(report))
"""


def test_elementwise_ops_on_a_sharded_batch_have_no_collectives():
    """Every elementwise operation of every group (exp, log, compose, apply, inverse,
    normalize, interpolate, as_matrix, from_matrix, adjoint, is_valid, the four Jacobians
    of exp, the ``jacobians`` functions, ``manifold.rplus``/``rminus`` and a gradient),
    jitted on a batch sharded over 4 CPU devices (``Mesh``, ``NamedSharding``,
    ``PartitionSpec("b")``; in a subprocess, as the device count is fixed at jax's start),
    compiles to a program with no all-reduce, all-gather, collective-permute, all-to-all or
    reduce-scatter, and returns its outputs sharded over the batch axis as its inputs were.
    Each element's result depends on that element alone, so a collective would be a
    batch-level decision, such as a ``lax.cond`` on ``jnp.any`` over the batch (an
    all-reduce). The batch, 1024 elements, is above the batch size from which
    ``interpolate`` may run in chunks (``_batch.in_chunks``, lowered here to 512).

    The gradient is ``vmap(grad(f))`` of one element's scalar f (through exp, compose and
    log): a gradient of a sum over the batch is elementwise too, but the sum itself is a
    reduction over the batch, which would need an all-reduce wherever its value is kept
    (``value_and_grad``), so the per-element form states the property without depending on
    XLA dropping the unused sum.

    Outputs that do not depend on the input (the same for NaN input: SO2's Jacobians and
    adjoint, which are 1; the Jacobians of compose and between with respect to the second
    operand, the identity) are constants XLA places by its own rule (replicated or on one
    device), with no communication; they are exempt from the sharding check. Inside
    ``shard_map`` (each device its own shard), exp and log give one device's values."""
    report = json.loads(_run_script(_COLLECTIVES_SCRIPT).strip().splitlines()[-1])
    assert report["collectives"] == {}, report["collectives"]
    assert report["sharding"] == {}, report["sharding"]
    assert report["shard_map"] == {}, report["shard_map"]
    for G in GROUPS:  # the constant test is not vacuous: these depend on their input
        for name in ("exp", "log", "compose", "is_valid", "vmap(grad)"):
            assert f"{G.__name__}.{name}[0]" not in report["constant"], report["constant"]


@pytest.mark.parametrize("G", [G for G in GROUPS if G._schedule.interpolate_in_chunks], ids=str)
def test_barrier_tangent_pass_through_keeps_derivatives(G, small_chunks, monkeypatch):
    """``materialize``'s jax ≥ 0.11 form (tangents bypass the barrier, ``_xla._barrier``)
    gives the gradient through the chunked ``interpolate`` (through ``in_chunks``' custom
    JVP, where jax 0.11.2 failed with JAX's own barrier rule) and the forward-mode
    Jacobian of an interpolation that JAX's rule gives on the whole batch."""
    batch = (3, 201)
    T, U = random_element(G, 3, batch, np.float32), random_element(G, 4, batch, np.float32)
    t = np.random.default_rng(5).uniform(0, 1, batch).astype(np.float32)

    def loss(p, q, t):
        return jnp.sum(jnp.sin(G(p).interpolate(G(q), t).parameters()))

    def fwd(p):
        return jax.jacfwd(lambda p: G(p).interpolate(U[0, 0], 0.3).log())(p)

    args = (T.parameters(), U.parameters(), jnp.asarray(t))
    results = {}
    for through in (False, True):
        monkeypatch.setattr(_xla, "TANGENTS_PASS_THROUGH", through)
        # the reference: the whole batch under JAX's barrier rule
        monkeypatch.setattr(_batch, "CHUNKED_FROM", 512 if through else 2**30)
        jax.clear_caches()
        if jax.default_backend() == "cpu":
            assert ("while" in jax.jit(loss).lower(*args).as_text()) == through
        results[through] = (
            jax.jit(jax.grad(loss, argnums=(0, 1, 2)))(*args),
            fwd(T.parameters()[0, 0]),
        )
    for got, want in zip(jax.tree.leaves(results[True]), jax.tree.leaves(results[False])):
        assert_close(got, want, np.float32, 4)


def test_interpolate_memory_at_2_22_elements():
    """A 2^22-element SE3 interpolate needs no more than inputs + outputs + one
    temporary of the output's size. XLA's buffer assignment for the compiled program (not
    run) reports the temporaries; before chunking they were 268 MB, 2.3 outputs. Chunking
    is CPU-only (``_batch.in_chunks`` says why)."""
    if jax.default_backend() != "cpu":
        pytest.skip("interpolate chunks its batch on CPU only")
    n = 2**22
    spec = jax.ShapeDtypeStruct((n, 7), jnp.float32)
    for t in (jax.ShapeDtypeStruct((n,), jnp.float32), jax.ShapeDtypeStruct((), jnp.float32)):
        compiled = (
            jax.jit(lambda a, b, t: SE3(a).interpolate(SE3(b), t).parameters())
            .lower(spec, spec, t)
            .compile()
        )
        memory = compiled.memory_analysis()
        assert memory.output_size_in_bytes == n * 7 * 4
        assert memory.temp_size_in_bytes <= memory.output_size_in_bytes, t.shape


@pytest.mark.parametrize("op", ["compose", "apply", "inverse"])
@over_groups
def test_group_operations_allocate_no_temporaries(G, op):
    """Compose, apply and inverse of 2^20 elements already in memory stream from
    the inputs to the output with no temporary buffer. The SE groups materialize whole
    elements once and call the rotation's barrier-free kernels on slices: with jax ≥ 0.11 a
    second barrier on a slice made XLA copy it (a 2^22-element SE3 compose had 185 MB of
    temporaries, apply 67, inverse 117). jax 0.10 elides those copies, so there the buffer
    check alone would pass either way; the count of barriers in the jaxpr (at most one per
    operation; the old SE3 compose had 3, apply 2) fails on such code with every jax, on
    every backend. The buffer sizes are XLA:CPU's assignment; GPUs were not measured."""
    n = 2**20
    P, D = G.parameters_dim, G.space_dim
    spec = jax.ShapeDtypeStruct((n, P), jnp.float32)
    fns = {
        "compose": (lambda a, b: (G(a) @ G(b)).parameters(), (spec, spec)),
        "apply": (lambda a, p: G(a) @ p, (spec, jax.ShapeDtypeStruct((n, D), jnp.float32))),
        "inverse": (lambda a: G(a).inverse().parameters(), (spec,)),
    }
    f, specs = fns[op]
    assert str(jax.make_jaxpr(f)(*specs)).count("optimization_barrier") <= 1
    if jax.default_backend() != "cpu":
        pytest.skip("buffer assignment checked on XLA:CPU only")
    memory = jax.jit(f).lower(*specs).compile().memory_analysis()
    assert memory.output_size_in_bytes >= n * 4 * D
    # Measured exceptions, one buffer of the size of the output's rotation or scale:
    # Sim(3) reads e^σ (e^−σ) several times and XLA:CPU computes it once into one float per
    # element; SE_2(3)'s inverse rotates two vectors by R⁻¹ and XLA:CPU keeps R⁻¹'s
    # quaternion (four floats per element).
    allowed = {"Sim3": 4, "SE23": 16 if op == "inverse" else 0}.get(G.__name__, 0) * n
    assert memory.temp_size_in_bytes <= allowed + 2**16, memory.temp_size_in_bytes


def _flops(f, *specs) -> float:
    cost = jax.jit(f).lower(*specs).compile().cost_analysis()
    return float((cost[0] if isinstance(cost, list) else cost).get("flops", 0.0))


@over_groups
def test_chains_of_compositions_cost_each_step_once(G):
    """A chain of K compositions of computed elements, log(exp(x) @ exp(x/K) @ … @ exp(x)),
    costs each step once: XLA's flop count of the compiled program grows by the cost of one
    exp and one compose per step. Without the barriers of ``Schedule.reread`` XLA fuses
    each product into every read of it, which multiplies the work per step (SO3: twice the
    flops; SE3: growing with K, and an SO3 chain of 4 at 10⁶ elements did not finish in
    minutes)."""
    n = 1024
    x = jax.ShapeDtypeStruct((n, G.tangent_dim), jnp.float32)
    p = jax.ShapeDtypeStruct((n, G.parameters_dim), jnp.float32)

    def chain(K):
        def f(x):
            T = G.exp(x)
            for k in range(1, K + 1):
                T = T @ G.exp(x * (k / K))
            return T.log()

        return _flops(f, x)

    step = _flops(lambda x: G.exp(x).parameters(), x) + _flops(
        lambda a, b: (G(a) @ G(b)).parameters(), p, p
    )
    c2, c4, c6 = chain(2), chain(4), chain(6)
    for more in (c4 - c2, c6 - c4):
        assert more <= 2 * 1.25 * step, (c2, c4, c6, step)
