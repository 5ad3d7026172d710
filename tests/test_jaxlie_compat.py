"""jaxlie_geo as a drop-in replacement for jaxlie 1.5: the same code, run once with
``import jaxlie_geo as jaxlie`` and once with the real jaxlie, gives the same numbers.

Values are compared at ``COMPAT_TOL`` (jaxlie's own kernels are less accurate than ours);
parameters are compared directly where both libraries define them by the same formula
(so a quaternion sign flip would show), matrices elsewhere.
"""

from __future__ import annotations

import dataclasses
import inspect

import jax
import jax.numpy as jnp
import jax_dataclasses as jdc  # a dependency of jaxlie
import jaxlie as jaxlie_ref  # the test extra installs it; never skipped
import numpy as np
import pytest
from conftest import (
    JAXLIE_GROUPS,
    QUATERNION_GROUPS,
    assert_close_compat,
    group_name,
    is_se,
    over_dtypes,
    over_jaxlie_groups,
    over_jaxlie_groups_dtypes,
    random_element,
    random_points,
    random_tangent,
    to_np,
)
from flax import serialization  # the test extra installs it

import jaxlie_geo
from benchmarks.mpref import x64_for

REF = {
    jaxlie_geo.SO2: jaxlie_ref.SO2,
    jaxlie_geo.SE2: jaxlie_ref.SE2,
    jaxlie_geo.SO3: jaxlie_ref.SO3,
    jaxlie_geo.SE3: jaxlie_ref.SE3,
}


def ref_of(T):
    """The same element in jaxlie."""
    return REF[type(T)](T.parameters())


# ---------------------------------------------------------------------------------
# The public surface.


def test_every_public_name_of_jaxlie_exists():
    """Every public name of jaxlie, jaxlie.manifold, jaxlie.utils and jaxlie.hints exists here
    (read from the installed jaxlie)."""
    for mod_ref, mod in (
        (jaxlie_ref, jaxlie_geo),
        (jaxlie_ref.manifold, jaxlie_geo.manifold),
        (jaxlie_ref.utils, jaxlie_geo.utils),
        (jaxlie_ref.hints, jaxlie_geo.hints),
    ):
        for name in dir(mod_ref):
            if not name.startswith("_") and not inspect.ismodule(getattr(mod_ref, name)):
                assert hasattr(mod, name), f"{mod.__name__}.{name} missing"
    assert jaxlie_geo.hints.RollPitchYaw._fields == jaxlie_ref.hints.RollPitchYaw._fields


@over_jaxlie_groups
def test_class_attributes_fields_and_bases(G):
    """The dimension attributes and dataclass field names equal jaxlie's; the bases are ours."""
    R = REF[G]
    for attr in ("matrix_dim", "parameters_dim", "tangent_dim", "space_dim"):
        assert getattr(G, attr) == getattr(R, attr), attr
    assert [f.name for f in dataclasses.fields(G)] == [f.name for f in dataclasses.fields(R)]
    assert issubclass(G, jaxlie_geo.MatrixLieGroup)
    assert issubclass(G, jaxlie_geo.SEBase if is_se(G) else jaxlie_geo.SOBase)


def _signature_names(fn):
    return [
        p.name
        for p in inspect.signature(fn).parameters.values()
        if p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)
    ]


@over_jaxlie_groups
def test_method_signatures_are_supersets(G):
    """Every public jaxlie method exists with jaxlie's parameter names, in jaxlie's order
    (extra trailing parameters such as ``dtype`` are allowed)."""
    R = REF[G]
    for name in dir(R):
        if name.startswith("_") or not callable(getattr(R, name)):
            continue
        assert hasattr(G, name), f"{G.__name__}.{name} missing"
        ref_names = _signature_names(getattr(R, name))
        ours = _signature_names(getattr(G, name))
        assert ours[: len(ref_names)] == ref_names, (name, ours, ref_names)
    for name in ("manifold", "utils"):
        mod_ref, mod = getattr(jaxlie_ref, name), getattr(jaxlie_geo, name)
        for fn in dir(mod_ref):
            obj = getattr(mod_ref, fn)
            if fn.startswith("_") or not inspect.isfunction(obj):
                continue
            ref_names = _signature_names(obj)  # reduce_axes included: it is positional
            assert _signature_names(getattr(mod, fn))[: len(ref_names)] == ref_names, fn


@over_jaxlie_groups
def test_jitted_methods_compile_ahead_of_time(G):
    """jaxlie's public methods are ``jax.jit`` functions, classmethods included, so
    ``SO3.exp.lower(tangent).compile()`` works there; so it does here, and the compiled
    function returns what the call does."""
    R = REF[G]
    staged = [n for n in dir(R) if not n.startswith("_") and hasattr(getattr(R, n), "lower")]
    assert {"exp", "identity", "from_matrix", "sample_uniform"} <= set(staged)
    # parameters() is a plain attribute read here (no dispatch), not a jitted function.
    assert [n for n in staged if not hasattr(getattr(G, n), "lower")] == ["parameters"]
    x = jnp.linspace(0.1, 0.7, G.tangent_dim)
    compiled = G.exp.lower(x).compile()
    np.testing.assert_array_equal(compiled(x).parameters(), G.exp(x).parameters())
    matrix = G.exp(x).as_matrix()
    np.testing.assert_array_equal(
        G.from_matrix.lower(matrix).compile()(matrix).parameters(),
        G.from_matrix(matrix).parameters(),
    )
    assert G.identity.lower((2,)).compile()().parameters().shape == (2, G.parameters_dim)
    drawn = G.sample_uniform.eval_shape(jax.random.PRNGKey(0), (5,))
    assert drawn.parameters().shape == (5, G.parameters_dim)


@over_jaxlie_groups_dtypes
def test_flax_serialization_interchanges_with_jaxlie(G, dtype):
    """jaxlie's elements serialize with flax (jax_dataclasses registers them); ours too,
    with the same state dict, so bytes written by either library load in the other, and
    a round trip returns the parameters bit for bit."""
    T = random_element(G, 31, (2, 3), dtype)
    p = to_np(T.parameters())
    ours, theirs = serialization.to_bytes(T), serialization.to_bytes(ref_of(T))
    assert ours == theirs
    back = serialization.from_bytes(G.identity((2, 3), dtype), theirs)
    assert type(back) is G
    np.testing.assert_array_equal(to_np(back.parameters()), p)
    in_jaxlie = serialization.from_bytes(ref_of(G.identity((2, 3), dtype)), ours)
    np.testing.assert_array_equal(to_np(in_jaxlie.parameters()), p)
    # Nested: a geodesic is a pytree dataclass holding an element.
    path = jaxlie_geo.geodesic(T, T.inverse())
    state = serialization.to_state_dict(path)
    fields = [f.name for f in dataclasses.fields(REF[G])]
    assert set(state) == {"start", "tangent"} and list(state["start"]) == fields
    again = serialization.from_bytes(path, serialization.to_bytes(path))
    np.testing.assert_array_equal(to_np(again(0.3).parameters()), to_np(path(0.3).parameters()))
    other = next(H for H in JAXLIE_GROUPS if H.parameters_dim != G.parameters_dim)
    with pytest.raises(ValueError, match=f"{G.__name__} state dict: missing field"):
        serialization.from_bytes(G.identity(), serialization.to_bytes(other.identity()))


@over_jaxlie_groups
def test_copy_and_mutate_as_in_jaxlie(G):
    """jax_dataclasses.copy_and_mutate reassigns a field of a copy, on jaxlie's elements and
    on ours (also when the element sits inside a user's jdc dataclass); the original and,
    after the block, the copy stay frozen; a changed shape is refused unless
    ``validate=False``."""
    T = random_element(G, 41, (3,), jnp.float32)
    field = dataclasses.fields(G)[0].name
    new = to_np(random_element(G, 42, (3,), jnp.float32).parameters())
    results = []
    for start in (T, ref_of(T)):
        with jdc.copy_and_mutate(start) as U:
            setattr(U, field, jnp.asarray(new))
        results.append(to_np(U.parameters()))
        np.testing.assert_array_equal(to_np(start.parameters()), to_np(T.parameters()))
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(U, field, jnp.asarray(new))
    np.testing.assert_array_equal(results[0], new)
    np.testing.assert_array_equal(results[1], new)
    with pytest.raises(ValueError, match=rf"{G.__name__}.{field}: copy_and_mutate needs"):
        with jdc.copy_and_mutate(T) as U:
            setattr(U, field, jnp.asarray(new[0]))
    with jdc.copy_and_mutate(T, validate=False) as U:
        setattr(U, field, jnp.asarray(new[0]))
    assert U.get_batch_axes() == ()

    @jdc.pytree_dataclass
    class State:
        pose: G  # type: ignore[valid-type]
        velocity: jax.Array

    state = State(T, jnp.zeros(3))
    with jdc.copy_and_mutate(state) as moved:
        setattr(moved.pose, field, jnp.asarray(new))
    np.testing.assert_array_equal(to_np(moved.pose.parameters()), new)
    np.testing.assert_array_equal(to_np(state.pose.parameters()), to_np(T.parameters()))


# ---------------------------------------------------------------------------------
# Core operations, side by side.


@over_jaxlie_groups_dtypes
def test_core_operations_side_by_side(G, dtype):
    """exp, log, as/from_matrix (with jaxlie's quaternion sign), apply, multiply and the other
    methods give jaxlie's values at the side-by-side tolerance."""
    T = random_element(G, 21, (3,), dtype)
    U = random_element(G, 22, (3,), dtype)
    x = random_tangent(G, 21, (3,), dtype, max_angle=3.0)
    p = random_points(G, 21, (3,), dtype)
    TR, UR, R = ref_of(T), ref_of(U), REF[G]

    def same(ours, ref, what):
        assert_close_compat(ours, ref, dtype, msg=f"{G.__name__}.{what}")

    same(G.exp(x).parameters(), R.exp(x).parameters(), "exp")
    same(T.log(), TR.log(), "log")
    same(T.as_matrix(), TR.as_matrix(), "as_matrix")
    M = to_np(U.as_matrix()).astype(dtype)
    same(G.from_matrix(M).as_matrix(), R.from_matrix(M).as_matrix(), "from_matrix")
    same(G.from_matrix(M).parameters(), R.from_matrix(M).parameters(), "from_matrix sign")
    same(T.apply(p), TR.apply(p), "apply")
    same(T @ p, TR @ p, "@ points")
    same((T @ U).parameters(), (TR @ UR).parameters(), "multiply")
    same(T.multiply(U).parameters(), TR.multiply(UR).parameters(), "multiply")
    same(T.inverse().parameters(), TR.inverse().parameters(), "inverse")
    same(T.adjoint(), TR.adjoint(), "adjoint")
    same(T.jlog(), TR.jlog(), "jlog")
    same(T.parameters(), TR.parameters(), "parameters")
    assert T.get_batch_axes() == TR.get_batch_axes()
    same(G.identity((2,)).parameters(), R.identity((2,)).parameters(), "identity")
    # normalize of perturbed parameters
    noisy = (to_np(T.parameters()) * 1.3 + 0.01).astype(dtype)
    same(
        G(jnp.asarray(noisy)).normalize().parameters(),
        R(noisy).normalize().parameters(),
        "normalize",
    )
    assert G(jnp.asarray(noisy)).normalize().parameters().dtype == dtype
    # as_matrix of non-unit parameters: jaxlie's matrices (for SO3, the rotation of q/|q|)
    same(G(jnp.asarray(noisy)).as_matrix(), R(noisy).as_matrix(), "as_matrix non-unit")
    # The action and composition of non-unit parameters (jaxlie's q p q* scales SO3's by |q|²;
    # SO2's R p by |z|), and the gradient with respect to raw parameters, radial part
    # included, which a projected-gradient optimiser follows (jaxlie's se3_optimization).
    same(G(jnp.asarray(noisy)).apply(p), R(noisy).apply(p), "apply non-unit")
    same(
        G(jnp.asarray(noisy)).multiply(U).parameters(),
        R(noisy).multiply(UR).parameters(),
        "multiply non-unit",
    )
    same(
        G(jnp.asarray(noisy)).inverse().parameters(),
        R(noisy).inverse().parameters(),
        "inverse non-unit",
    )

    def raw_grad(lib_G, params):
        return jax.grad(lambda q: jnp.sum(jnp.sin(lib_G(q).apply(p))))(params)

    same(raw_grad(G, jnp.asarray(noisy)), raw_grad(R, jnp.asarray(noisy)), "grad of apply")


@over_dtypes
def test_factories_side_by_side(dtype):
    """The group-specific factories and readers (radians, rpy, quaternion orderings,
    rotation-and-translation) give jaxlie's values."""
    L, J = jaxlie_geo, jaxlie_ref
    rng = np.random.default_rng(0)
    a = rng.uniform(-3.0, 3.0, size=(3, 5)).astype(dtype)
    roll, pitch, yaw = a[0], a[1] * 0.5, a[2]
    t2 = rng.normal(size=(5, 2)).astype(dtype)
    t3 = rng.normal(size=(5, 3)).astype(dtype)

    def same(ours, ref, what):
        assert_close_compat(ours, ref, dtype, msg=what)

    # SO2
    same(
        L.SO2.from_radians(yaw).as_matrix(), J.SO2.from_radians(yaw).as_matrix(), "SO2.from_radians"
    )
    same(L.SO2.from_radians(yaw).as_radians(), J.SO2.from_radians(yaw).as_radians(), "as_radians")
    # SO3
    for name in ("from_x_radians", "from_y_radians", "from_z_radians"):
        same(getattr(L.SO3, name)(yaw).parameters(), getattr(J.SO3, name)(yaw).parameters(), name)
    Rl = L.SO3.from_rpy_radians(roll, pitch, yaw)
    Rj = J.SO3.from_rpy_radians(roll, pitch, yaw)
    same(Rl.parameters(), Rj.parameters(), "from_rpy_radians")
    for name in ("compute_roll_radians", "compute_pitch_radians", "compute_yaw_radians"):
        same(getattr(Rl, name)(), getattr(Rj, name)(), name)
    for ours, ref in zip(Rl.as_rpy_radians(), Rj.as_rpy_radians()):
        same(ours, ref, "as_rpy_radians")
    same(Rl.as_rpy_radians().roll, roll, "rpy round trip")
    same(Rl.as_rpy_radians().yaw, yaw, "rpy round trip")
    xyzw = Rj.as_quaternion_xyzw()
    same(Rl.as_quaternion_xyzw(), xyzw, "as_quaternion_xyzw")
    same(
        L.SO3.from_quaternion_xyzw(np.asarray(xyzw)).parameters(),
        J.SO3.from_quaternion_xyzw(xyzw).parameters(),
        "from_quaternion_xyzw",
    )
    # SE2
    El = L.SE2.from_xy_theta(t2[:, 0], t2[:, 1], yaw)
    Ej = J.SE2.from_xy_theta(t2[:, 0], t2[:, 1], yaw)
    same(El.parameters(), Ej.parameters(), "SE2.from_xy_theta")
    # SE2/SE3 constructors and accessors
    for Gl, Gj, Rl_, Rj_, t in (
        (L.SE2, J.SE2, L.SO2.from_radians(yaw), J.SO2.from_radians(yaw), t2),
        (L.SE3, J.SE3, Rl, Rj, t3),
    ):
        A = Gl.from_rotation_and_translation(Rl_, t)
        B = Gj.from_rotation_and_translation(Rj_, t)
        same(A.parameters(), B.parameters(), f"{Gl.__name__}.from_rotation_and_translation")
        assert A.parameters().dtype == dtype
        same(Gl.from_rotation(Rl_).as_matrix(), Gj.from_rotation(Rj_).as_matrix(), "from_rotation")
        same(
            Gl.from_translation(t).as_matrix(),
            Gj.from_translation(t).as_matrix(),
            "from_translation",
        )
        same(A.rotation().parameters(), B.rotation().parameters(), "rotation()")
        same(A.translation(), B.translation(), "translation()")


@pytest.mark.parametrize(
    "make_key", [jax.random.PRNGKey, jax.random.key], ids=["PRNGKey", "typed_key"]
)
@over_jaxlie_groups
def test_sample_uniform_same_draws(G, make_key):
    """Same key, same draws (float64 under x64, as jaxlie draws the default dtype)."""
    for seed, batch in ((0, ()), (1, (5,)), (2, (2, 3))):
        key = make_key(seed)
        ours = G.sample_uniform(key, batch)
        ref = REF[G].sample_uniform(key, batch)
        assert ours.parameters().dtype == jnp.float64
        np.testing.assert_array_equal(to_np(ours.parameters()), to_np(ref.parameters()))
        np.testing.assert_array_equal(
            to_np(G.sample_uniform(key, batch, dtype=jnp.float64).parameters()),
            to_np(ours.parameters()),
        )


@over_jaxlie_groups
def test_sample_uniform_float32_matches_jaxlie_without_x64(G):
    """dtype=float32 under x64 draws what jaxlie draws when x64 is off."""
    key = jax.random.PRNGKey(3)
    with x64_for("float32"):  # x64 off, on every supported jax
        ref = np.asarray(REF[G].sample_uniform(key, (4,)).parameters())
    ours = G.sample_uniform(key, (4,), dtype=jnp.float32).parameters()
    assert ref.dtype == np.float32 and ours.dtype == jnp.float32
    np.testing.assert_allclose(np.asarray(ours), ref, rtol=2e-7, atol=2e-7)


# ---------------------------------------------------------------------------------
# Quaternion signs are never flipped implicitly.


@pytest.mark.parametrize("G", [G for G in QUATERNION_GROUPS if G in JAXLIE_GROUPS], ids=group_name)
def test_quaternion_sign_is_kept(G):
    """A quaternion with w < 0 keeps its sign through identity products, ``normalize``, double
    inversion and the xyzw conversions, as in jaxlie; exp beyond π gives w < 0 in both."""
    T = random_element(G, 5, (4,), jnp.float64)
    p = np.array(T.parameters())
    p[..., :4] *= -np.sign(p[..., :1])  # w < 0 everywhere
    T = G(jnp.asarray(p))
    I = G.identity()
    for out in (T @ I, I @ T, T.normalize(), G(jnp.asarray(p)).inverse().inverse()):
        np.testing.assert_allclose(
            to_np(out.parameters())[..., :4], p[..., :4], rtol=1e-15, atol=1e-15
        )
    np.testing.assert_array_equal(
        to_np((T @ I).parameters()), to_np((ref_of(T) @ REF[G].identity()).parameters())
    )
    q = p[..., :4]
    xyzw = np.concatenate([q[..., 1:], q[..., :1]], axis=-1)
    R = jaxlie_geo.SO3.from_quaternion_xyzw(xyzw)
    np.testing.assert_array_equal(to_np(R.wxyz), q)
    np.testing.assert_array_equal(to_np(R.as_quaternion_xyzw()), xyzw)
    # exp beyond π gives w < 0 in both libraries
    x = np.zeros(G.tangent_dim)
    x[-1] = 4.0
    np.testing.assert_allclose(
        to_np(G.exp(x).parameters()), to_np(REF[G].exp(x).parameters()), rtol=1e-12, atol=1e-12
    )
    assert float(G.exp(x).parameters()[0]) < 0


@over_dtypes
def test_from_matrix_picks_jaxlies_quaternion_sign(dtype):
    """``SO3.from_matrix`` picks jaxlie's quaternion sign for 20 000 rotations (w = 0 and
    near-identity ties included), and ``SE3.from_matrix`` the same quaternion."""
    # Shepperd's pivot (largest of 4w², 4x², 4y², 4z²) and jaxlie's branches on the diagonal
    # chose opposite signs for 2.8% of random rotations; near-ties included here.
    q = np.random.default_rng(11).normal(size=(20000, 4))
    q[:2000, 0] = 0.0  # angle π: w = 0
    q[2000:4000, 1:] *= 1e-4  # near the identity
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    M = to_np(jaxlie_geo.SO3(jnp.asarray(q, dtype)).as_matrix())
    ours = to_np(jaxlie_geo.SO3.from_matrix(M).wxyz)
    ref = to_np(jaxlie_ref.SO3.from_matrix(jnp.asarray(M)).wxyz)
    sign = np.sign(np.sum(ours * ref, axis=-1))
    assert np.all(sign > 0), f"{np.sum(sign <= 0)} of {len(sign)} signs differ"
    H = np.broadcast_to(np.eye(4, dtype=dtype), (20000, 4, 4)).copy()
    H[:, :3, :3] = M
    se3 = to_np(jaxlie_geo.SE3.from_matrix(H).wxyz_xyz)[:, :4]
    np.testing.assert_allclose(se3, ours, rtol=0, atol=4 * np.finfo(dtype).eps)


# ---------------------------------------------------------------------------------
# Tangent orderings.


@over_dtypes
def test_tangent_orderings(dtype):
    """The tangent orderings are jaxlie's: SE2 (vx, vy, θ), SE3 (v, ω), SO3 the rotation vector."""
    L = jaxlie_geo
    th = 0.7
    # SE2: (vx, vy, theta)
    E = L.SE2.exp(np.array([1.0, 2.0, 0.0], dtype))
    assert_close_compat(E.translation(), [1.0, 2.0], dtype)
    assert_close_compat(E.rotation().as_radians(), 0.0, dtype)
    E = L.SE2.exp(np.array([0.0, 0.0, th], dtype))
    assert_close_compat(E.rotation().as_radians(), th, dtype)
    assert_close_compat(E.translation(), [0.0, 0.0], dtype)
    # SE3: (v, omega)
    E = L.SE3.exp(np.array([1.0, 2.0, 3.0, 0.0, 0.0, 0.0], dtype))
    assert_close_compat(E.translation(), [1.0, 2.0, 3.0], dtype)
    assert_close_compat(E.rotation().wxyz, [1.0, 0.0, 0.0, 0.0], dtype)
    E = L.SE3.exp(np.array([0.0, 0.0, 0.0, 0.0, 0.0, th], dtype))
    assert_close_compat(E.rotation().as_matrix(), L.SO3.from_z_radians(th).as_matrix(), dtype)
    assert_close_compat(E.log(), [0, 0, 0, 0, 0, th], dtype)
    # SO3 tangent is the rotation vector
    assert_close_compat(
        L.SO3.exp(np.array([th, 0, 0], dtype)).as_matrix(),
        L.SO3.from_x_radians(th).as_matrix(),
        dtype,
    )
    for G in JAXLIE_GROUPS:
        x = random_tangent(G, 4, (), dtype)
        assert_close_compat(G.exp(x).as_matrix(), REF[G].exp(x).as_matrix(), dtype)


# ---------------------------------------------------------------------------------
# utils (manifold: test_manifold.py).


def test_utils_side_by_side():
    """``utils.get_epsilon``, ``broadcast_leading_axes`` and ``register_lie_group`` behave as
    jaxlie's."""
    for dt in (jnp.float32, jnp.float64):
        assert jaxlie_geo.utils.get_epsilon(jnp.dtype(dt)) == jaxlie_ref.utils.get_epsilon(
            jnp.dtype(dt)
        )
    T = random_element(jaxlie_geo.SE3, 1, (3, 1), jnp.float64)
    a = np.ones((1, 4, 2))
    ours = jaxlie_geo.utils.broadcast_leading_axes((T, a))
    ref = jaxlie_ref.utils.broadcast_leading_axes((ref_of(T), a))
    assert isinstance(ours[0], jaxlie_geo.SE3)
    assert ours[0].get_batch_axes() == ref[0].get_batch_axes() == (3, 4)
    np.testing.assert_array_equal(to_np(ours[0].parameters()), to_np(ref[0].parameters()))
    np.testing.assert_array_equal(to_np(ours[1]), to_np(ref[1]))

    @jaxlie_geo.utils.register_lie_group(matrix_dim=1, parameters_dim=2, tangent_dim=3, space_dim=4)
    class Dummy:
        pass

    assert (Dummy.matrix_dim, Dummy.parameters_dim, Dummy.tangent_dim, Dummy.space_dim) == (
        1,
        2,
        3,
        4,
    )


# ---------------------------------------------------------------------------------
# Realistic user programs, unchanged, with either module.


def _readme_program(jaxlie, dtype):
    """What a jaxlie user writes: build a pose, act on points, exp/log, vmap, and fit a
    pose to noisy correspondences by gradient descent on the manifold."""
    SE3, SO3 = jaxlie.SE3, jaxlie.SO3
    T_w_b = SE3.from_rotation_and_translation(
        rotation=SO3.from_rpy_radians(0.3, -0.2, 1.1),
        translation=jnp.array([1.0, -2.0, 0.5], dtype),
    )
    p_b = jnp.array([[0.2, 0.1, -0.4], [1.0, 0.0, 0.0], [0.0, 1.0, 2.0], [-1.0, 0.5, 0.3]], dtype)
    p_w = T_w_b @ p_b
    T_b_w = T_w_b.inverse()
    twist = T_w_b.log()
    T_again = SE3.exp(twist)
    twists = jnp.stack([twist * s for s in (0.1, 0.5, 0.9)])
    batched = jax.vmap(SE3.exp)(twists)

    def cost(T):
        return jnp.sum((T @ p_b - p_w) ** 2)

    @jax.jit
    def step(T):
        g = jaxlie.manifold.grad(cost)(T)
        return jaxlie.manifold.rplus(T, -0.05 * g)

    T = SE3.from_translation(jnp.zeros(3, dtype))
    for _ in range(60):
        T = step(T)
    return {
        "p_w": p_w,
        "T_b_w": T_b_w.as_matrix(),
        "twist": twist,
        "T_again": T_again.as_matrix(),
        "batched": batched.as_matrix(),
        "fitted": T.as_matrix(),
        "final_cost": cost(T),
        "rpy": jnp.stack(T_w_b.rotation().as_rpy_radians()),
        "xyzw": T_w_b.rotation().as_quaternion_xyzw(),
    }


def _odometry_program(jaxlie, dtype):
    """A planar odometry chain: compose relative motions, then the relative pose between
    the ends and its tangent, and the interpolation-free midpoint via exp/log."""
    SE2 = jaxlie.SE2
    steps = [SE2.from_xy_theta(jnp.asarray(0.5, dtype), 0.1 * i, 0.2 - 0.05 * i) for i in range(8)]
    T = SE2.from_translation(jnp.zeros(2, dtype))
    poses = []
    for s in steps:
        T = T @ s
        poses.append(T.parameters())
    rel = poses_first = SE2(poses[0])
    rel = poses_first.inverse() @ T
    mid = poses_first @ SE2.exp(0.5 * rel.log())
    return {
        "poses": jnp.stack(poses),
        "rel": rel.log(),
        "mid": mid.as_matrix(),
        "apply": T.apply(jnp.array([1.0, 1.0], dtype)),
        "adjoint": T.adjoint(),
        "jlog": T.jlog(),
    }


def _api_tour_program(jaxlie, dtype):
    """A tour of jaxlie 1.5's API as user code (README-style), in either dtype."""
    out = {}
    T_w_b = jaxlie.SE3.from_rotation_and_translation(
        jaxlie.SO3.from_rpy_radians(0.3, -0.2, 1.1), jnp.array([1.0, 2.0, 3.0], dtype)
    )
    p_b = jnp.array([[0.5, -1.0, 2.0], [1.0, 0.0, 0.0]], dtype)
    out["apply"] = T_w_b @ p_b
    out["inverse"] = T_w_b.inverse().as_matrix()
    out["log"] = T_w_b.log()
    out["exp_log"] = jaxlie.SE3.exp(T_w_b.log()).as_matrix()
    out["adjoint"] = T_w_b.adjoint()
    out["jlog"] = T_w_b.jlog()
    out["rpy"] = jnp.stack(T_w_b.rotation().as_rpy_radians())
    out["xyzw"] = T_w_b.rotation().as_quaternion_xyzw()
    out["from_xyzw"] = jaxlie.SO3.from_quaternion_xyzw(
        jnp.array([0.1, 0.2, 0.3, 0.9], dtype)
    ).as_matrix()
    out["so2"] = jaxlie.SO2.from_radians(jnp.array(0.7, dtype)).as_matrix()
    out["so2_rad"] = jaxlie.SO2.from_radians(jnp.array(2.5, dtype)).as_radians()
    out["se2"] = jaxlie.SE2.from_xy_theta(1.0, -2.0, 0.4).as_matrix()
    out["se2_log"] = jaxlie.SE2.from_xy_theta(1.0, -2.0, 0.4).log()
    out["from_matrix"] = jaxlie.SE3.from_matrix(T_w_b.as_matrix()).as_matrix()
    out["identity"] = jaxlie.SE3.identity((2, 3)).parameters()
    out["from_translation"] = jaxlie.SE2.from_translation(jnp.array([1.0, 2.0], dtype)).as_matrix()
    out["from_rotation"] = jaxlie.SE3.from_rotation(jaxlie.SO3.from_z_radians(0.3)).as_matrix()
    out["normalize"] = jaxlie.SO3(jnp.array([2.0, 0.0, 0.0, 0.0], dtype)).normalize().wxyz
    # Optimisation on the manifold, as in jaxlie's docs.
    target = jaxlie.SE3.exp(jnp.array([0.1, 0.2, 0.3, 0.3, -0.1, 0.2], dtype))

    def loss(T):
        return jnp.sum(jaxlie.manifold.rminus(T, target) ** 2)

    T0 = jaxlie.SE3.exp(jnp.array([0.0, 0.1, 0.0, 0.2, 0.1, 0.0], dtype))
    out["grad"] = jaxlie.manifold.grad(loss)(T0)
    value, g = jaxlie.manifold.value_and_grad(loss)(T0)
    out["value"] = value
    out["rplus"] = jaxlie.manifold.rplus(T0, g).parameters()
    tree = {"pose": T0, "x": jnp.ones(2, dtype)}
    out["zero_tangents"] = jax.tree.leaves(jaxlie.manifold.zero_tangents(tree))
    out["normalize_all"] = jaxlie.manifold.normalize_all(tree)["pose"].parameters()
    out["rplus_jac"] = jaxlie.manifold.rplus_jacobian_parameters_wrt_delta(T0)
    out["eps"] = jnp.array([jaxlie.utils.get_epsilon(jnp.dtype(d)) for d in ("float32", "float64")])
    a, b = jaxlie.utils.broadcast_leading_axes((jaxlie.SO3.identity((3, 1)), jnp.zeros((1, 4, 3))))
    out["broadcast"] = jnp.array([*a.get_batch_axes(), *b.shape])
    return out


@pytest.mark.parametrize(
    "program",
    [_readme_program, _odometry_program, _api_tour_program],
    ids=["readme", "odometry", "api_tour"],
)
@over_dtypes
def test_user_program_gives_same_numbers(program, dtype):
    """Whole user programs written against jaxlie give the same numbers with either module."""
    ours = program(jaxlie_geo, dtype)
    ref = program(jaxlie_ref, dtype)
    assert ours.keys() == ref.keys()
    for k in ours:
        a, b = ours[k], ref[k]
        if isinstance(a, list):
            assert len(a) == len(b), k
            for x, y in zip(a, b):
                assert_close_compat(x, y, dtype, msg=k)
        else:
            assert_close_compat(a, b, dtype, msg=k)
    if program is _readme_program:
        assert float(ours["final_cost"]) < (1e-6 if dtype == jnp.float64 else 1e-4)
