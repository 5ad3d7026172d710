"""Wrong inputs raise at trace time, with messages that name the function, the expected
and the received shape; constructors do not validate."""

from __future__ import annotations

import re
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import GROUPS, is_se, over_groups, over_se_groups, random_element

import jaxlie_geo
from jaxlie_geo import SE2, SE3, SO2, SO3
from jaxlie_geo._xla import at_least, parse_version


def _shape_cases():
    """(id, function of one array, bad input shape, expected trailing shape, name in message)."""
    cases = []
    for G in GROUPS:
        k, n, d = G.tangent_dim, G.matrix_dim, G.space_dim
        g = G.__name__
        # identity built from its parameters: nothing is computed at collection time
        T = G(np.eye(1, G.parameters_dim)[0])
        cases += [
            (f"{g}.exp-extra", G.exp, (k + 1,), (k,), "exp"),
            (f"{g}.exp-batched", G.exp, (5, k + 2), (k,), "exp"),
            (f"{g}.exp-scalar", G.exp, (), (k,), "exp"),
            (f"{g}.from_matrix-square", G.from_matrix, (n + 1, n + 1), (n, n), "from_matrix"),
            (f"{g}.from_matrix-rect", G.from_matrix, (5, n, n + 1), (n, n), "from_matrix"),
            (f"{g}.from_matrix-flat", G.from_matrix, (n * n,), (n, n), "from_matrix"),
            (f"{g}.apply-homogeneous", T.apply, (d + 1,), (d,), "apply"),
            (f"{g}.apply-batched", T.apply, (4, d - 1), (d,), "apply"),
            (f"{g}.hat", G.hat, (k + 1,), (k,), "hat"),
            (f"{g}.vee-rect", G.vee, (n, n + 1), (n, n), "vee"),
            (f"{g}.vee-square", G.vee, (3, n + 1, n + 1), (n, n), "vee"),
            (f"{g}.jac_right", G.jac_right, (k + 1,), (k,), "jac_right"),
            (f"{g}.jac_right_inv", G.jac_right_inv, (2, k + 1), (k,), "jac_right_inv"),
            (
                f"{g}.rplus_jacobian_parameters_wrt_delta",  # once read the first entries
                lambda p, G=G: jaxlie_geo.manifold.rplus_jacobian_parameters_wrt_delta(G(p)),
                (G.parameters_dim + 1,),
                (G.parameters_dim,),
                "rplus_jacobian_parameters_wrt_delta",
            ),
        ]
        if is_se(G):
            Rot = {SE2: SO2, SE3: SO3}[G]
            R = Rot(np.eye(1, Rot.parameters_dim)[0])
            cases += [
                (f"{g}.from_translation", G.from_translation, (d + 1,), (d,), "from_translation"),
                (
                    f"{g}.from_rotation_and_translation",
                    lambda t, G=G, R=R: G.from_rotation_and_translation(R, t),
                    (3, d + 1),
                    (d,),
                    "from_rotation_and_translation",
                ),
            ]
    cases += [
        (
            "SO3.from_quaternion_xyzw-3",
            SO3.from_quaternion_xyzw,
            (3,),
            (4,),
            "from_quaternion_xyzw",
        ),
        (
            "SO3.from_quaternion_xyzw-batched",
            SO3.from_quaternion_xyzw,
            (2, 5),
            (4,),
            "from_quaternion_xyzw",
        ),
    ]
    return cases


_CASES = _shape_cases()


def _check_message(msg, bad, trailing, name):
    assert re.search(r"\b" + re.escape(name) + r"\b", msg), f"{name!r} not named in: {msg}"
    assert str(tuple(bad)) in msg, f"received shape {tuple(bad)} not in: {msg}"
    expected = ", ".join(map(str, trailing)) + ")"
    assert expected in msg, f"expected trailing shape {trailing} not in: {msg}"


@pytest.mark.parametrize(
    ("fn", "bad", "trailing", "name"), [c[1:] for c in _CASES], ids=[c[0] for c in _CASES]
)
def test_wrong_trailing_shape_raises_value_error(fn, bad, trailing, name):
    """An input of the wrong trailing shape raises ValueError at trace time, naming the function,
    the argument, the expected shape and the received one."""
    with pytest.raises(ValueError) as info:
        fn(np.zeros(bad))
    _check_message(str(info.value), bad, trailing, name)


@pytest.mark.parametrize(
    ("fn", "bad", "trailing", "name"), [c[1:] for c in _CASES], ids=[c[0] for c in _CASES]
)
def test_wrong_trailing_shape_raises_at_trace_time(fn, bad, trailing, name):
    """The same error comes out of abstract evaluation (no computation runs) and under jit,
    as a ValueError, not as a runtime failure."""
    spec = jax.ShapeDtypeStruct(bad, jnp.float32)
    with pytest.raises(ValueError) as info:
        jax.eval_shape(fn, spec)
    _check_message(str(info.value), bad, trailing, name)
    with pytest.raises(ValueError) as info:
        jax.jit(lambda a: fn(a))(np.zeros(bad, np.float32))
    _check_message(str(info.value), bad, trailing, name)


@over_groups
def test_generator_action_checks_points(G):
    """``jacobians.generator_action`` returns (*batch, space_dim, tangent_dim) for valid points and
    refuses points of the wrong size or complex points, naming the argument."""
    from jaxlie_geo import jacobians

    assert jacobians.generator_action(G, np.ones((4, G.space_dim))).shape == (
        4,
        G.space_dim,
        G.tangent_dim,
    )
    with pytest.raises(ValueError, match=r"generator_action: `points` must have shape"):
        jacobians.generator_action(G, np.ones(G.space_dim + 1))
    with pytest.raises(ValueError, match="must be real"):
        jacobians.generator_action(G, np.ones(G.space_dim) * 1j)


@over_groups
def test_methods_check_the_elements_parameter_shape(G):
    """Elements built with the wrong number of parameters (e.g. ``SO3(tangent)`` for
    ``SO3.exp(tangent)``, where a 3-vector was read as a quaternion) make every method raise
    ValueError naming the method, the expected and the received shape, also under jit."""
    for size in (G.parameters_dim - 1, G.parameters_dim + 1):
        T = G(np.full((2, size), 0.5, np.float32))
        for call, name in (
            (lambda T=T: T.log(), "log"),
            (lambda T=T: T.inverse(), "inverse"),
            (lambda T=T: T.as_matrix(), "as_matrix"),
            (lambda T=T: T.adjoint(), "adjoint"),
            (lambda T=T: T.apply(np.ones(G.space_dim, np.float32)), "apply"),
            (lambda T=T: G.identity().multiply(T), "multiply"),
            (lambda T=T: T @ G.identity(), "multiply"),
            (lambda T=T: jax.jit(lambda p: G(p).log())(T.parameters()), "log"),
        ):
            msg = (
                rf"{G.__name__}\.{name}: {G.__name__} parameters must have shape "
                rf"\(\*batch, {G.parameters_dim}\), got shape \(2, {size}\)"
            )
            with pytest.raises(ValueError, match=msg):
                call()
    with pytest.raises(ValueError, match="got shape \\(\\)"):
        G(np.float32(1.0)).inverse()


@over_groups
def test_constructor_does_not_validate(G):
    """The constructor accepts any leaf: JAX rebuilds pytrees with shapes, axis specs, tracers
    and None in place of arrays."""
    spec = jax.ShapeDtypeStruct((1,), jnp.float32)
    for leaf in (np.zeros(G.parameters_dim + 3), 0, None, (2, 3), spec):
        G(leaf)


@over_groups
def test_wrong_shapes_inside_manifold_and_geodesic(G):
    """``manifold.rplus`` with a delta of the wrong tangent size raises ValueError naming the
    expected size."""
    T = random_element(G, 0, (3,), jnp.float64)
    with pytest.raises(ValueError, match=re.escape(f"{G.tangent_dim})")):
        jaxlie_geo.manifold.rplus(T, np.zeros((3, G.tangent_dim + 1)))


@over_groups
def test_mixing_groups_raises_type_error(G):
    """Two elements of different groups raise TypeError in ``@``, ``geodesic`` and ``stack``, and
    the methods and module functions that take a second element name both groups (they
    raised AttributeError from inside the kernel); ``stack([])`` raises ValueError."""
    other = GROUPS[(GROUPS.index(G) + 1) % len(GROUPS)]
    T = G.identity()
    U = other.identity()
    with pytest.raises(TypeError):
        T @ U
    with pytest.raises(TypeError):
        jaxlie_geo.geodesic(T, U)
    with pytest.raises(TypeError):
        jaxlie_geo.stack([T, U])
    with pytest.raises(ValueError):
        jaxlie_geo.stack([])
    # the methods and functions that take a second element name both groups (they raised
    # AttributeError from inside the kernel: "'SE3' object has no attribute 'wxyz'")
    from jaxlie_geo import jacobians, manifold, uncertainty

    msg = f"expected {G.__name__}, got {other.__name__}"
    for call in (
        lambda: T.multiply(U),
        lambda: T.interpolate(U, 0.5),
        lambda: jax.jit(lambda: T.multiply(U))(),
        lambda: jacobians.compose(T, U),
        lambda: jacobians.between(T, U),
        lambda: jacobians.rminus(T, U),
        lambda: manifold.rminus(T, U),
        lambda: uncertainty.mean(G.identity((2,)), init=U),
    ):
        with pytest.raises(TypeError, match=msg):
            call()


@over_groups
def test_batch_axes_that_do_not_broadcast_raise_value_error(G):
    """Batch mismatches name the operation and both shapes (jax.numpy's own error named
    neither the operation nor the group), at trace time; broadcastable ones still work."""
    a, b = G.identity((3,)), G.identity((4,))
    bad = {
        "multiply": lambda: a @ b,
        "apply": lambda: a.apply(jnp.zeros((4, G.space_dim))),
        "interpolate": lambda: a.interpolate(b, 0.5),
        "geodesic": lambda: jaxlie_geo.geodesic(a, a)(jnp.zeros(4)),
        "jacobians.compose": lambda: jaxlie_geo.jacobians.compose(a, b),
        "jacobians.rminus": lambda: jaxlie_geo.jacobians.rminus(a, b),
        "manifold.rminus": lambda: jaxlie_geo.manifold.rminus(a, b),
        "eval_shape": lambda: jax.eval_shape(lambda a, b: a @ b, a, b),
    }
    for fn in bad.values():
        with pytest.raises(ValueError, match=r"\(3,\) and \(4,\) do not broadcast"):
            fn()
        with pytest.raises(ValueError, match="do not broadcast"):
            jax.jit(fn)()
    assert (a @ G.identity((2, 3))).get_batch_axes() == (2, 3)
    assert (a @ G.identity((3, 1))).get_batch_axes() == (3, 3)
    assert a.apply(jnp.zeros((2, 3, G.space_dim))).shape == (2, 3, G.space_dim)
    assert jaxlie_geo.jacobians.compose(a, G.identity((2, 1)))[0].shape[:2] == (2, 3)


@over_se_groups
def test_from_rotation_and_translation_checks_rotation_type(G):
    """A rotation of another group's type raises TypeError naming the rotation."""
    right = type(G.identity().rotation())
    wrong = next(H for H in GROUPS if not is_se(H) and H is not right).identity()
    with pytest.raises(TypeError, match="rotation"):
        G.from_rotation_and_translation(wrong, np.zeros(G.space_dim))


@over_groups
def test_non_float_dtypes_rejected(G):
    """Integer dtypes for ``identity`` and ``sample_uniform`` and complex tangents raise
    ValueError naming the dtype."""
    with pytest.raises(ValueError, match="dtype"):
        G.identity(dtype=jnp.int32)
    with pytest.raises(ValueError, match="dtype"):
        G.sample_uniform(jax.random.PRNGKey(0), dtype=jnp.int32)
    with pytest.raises(ValueError, match="real"):
        G.exp(np.zeros(G.tangent_dim, np.complex64))


def test_from_xy_theta_incompatible_shapes():
    """``SE2.from_xy_theta`` with coordinates that do not broadcast raises ValueError."""
    with pytest.raises(ValueError):
        SE2.from_xy_theta(np.zeros(2), np.zeros(3), 0.0)


def test_jax_older_than_the_minimum_is_refused_at_import():
    """jax < 0.5.3 cannot differentiate ``optimization_barrier`` (< 0.4.38 cannot vmap it):
    importing jaxlie_geo there raises at once, naming both versions, instead of failing on a
    user's first ``grad``. Runs a fresh interpreter whose jax reports 0.4.36."""
    code = "import jax; jax.__version__ = '0.4.36'; import jaxlie_geo"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode != 0
    assert "ImportError: jaxlie_geo needs jax >= 0.5.3" in out.stderr
    assert "found jax 0.4.36" in out.stderr


@pytest.mark.parametrize(
    ("text", "want"),
    [
        ("0.12.0.1", (0, 12, 0, 1)),
        ("0.5.3", (0, 5, 3)),
        ("0.6.0rc1", (0, 6, 0, -1)),
        ("0.7.0.dev20250601", (0, 7, 0, -1)),
        ("1.0", (1, 0)),
        ("0.5.3+cuda12", (0, 5, 3)),
        ("0.5.3.post1", (0, 5, 3)),
    ],
)
def test_version_parsing(text, want):
    """Release, pre-release (as −1), local and post-release version strings."""
    assert parse_version(text) == want


@pytest.mark.parametrize(
    ("text", "ok"),
    [
        ("0.5.3", True),
        ("0.5.3.post1", True),
        ("0.5.3+cuda12", True),
        ("0.6", True),
        ("0.12.0.1", True),
        ("0.5.3rc1", False),
        ("0.5.3.dev20250101", False),
        ("0.5.2", False),
        ("0.4.38", False),
    ],
)
def test_pre_releases_precede_their_release(text, ok):
    """A nightly or release candidate of 0.5.3 predates the release's features."""
    assert at_least(text, (0, 5, 3)) is ok


def test_batch_mismatches_name_the_function():
    """Batch axes that cannot broadcast raise ``ValueError`` naming the function and the
    shapes (they raised jax.numpy's "Incompatible shapes for broadcasting" or matmul's
    "Incompatible types", naming neither)."""
    from jaxlie_geo import jacobians, motion, uncertainty, utils

    T3 = SE3.exp(np.zeros((3, 6), np.float32))
    S3 = SE2.exp(np.zeros((3, 3), np.float32))
    cov4 = np.broadcast_to(np.eye(6, dtype=np.float32), (4, 6, 6))
    cases = {
        "SE3.from_rotation_and_translation": lambda: SE3.from_rotation_and_translation(
            T3.rotation(), np.zeros((4, 3), np.float32)
        ),
        "SE2.from_xy_theta": lambda: SE2.from_xy_theta(np.zeros(3), np.zeros(4), 0.0),
        "propagate_compose": lambda: uncertainty.propagate_compose(T3, cov4, T3, np.eye(6)),
        "propagate_inverse": lambda: uncertainty.propagate_inverse(T3, cov4),
        "propagate_apply": lambda: uncertainty.propagate_apply(
            T3, np.eye(6), np.zeros(3), np.ones((4, 3, 3))
        ),
        "sample": lambda: uncertainty.sample(jax.random.PRNGKey(0), T3, cov4),
        "velocity_between": lambda: motion.velocity_between(T3, T3, np.ones(4)),
        "jacobians.rplus": lambda: jacobians.rplus(T3, np.zeros((4, 6))),
        "broadcast_leading_axes": lambda: utils.broadcast_leading_axes((T3, np.zeros((4, 3)))),
        "arc": lambda: motion.arc(S3, np.zeros((4, 3))),
        "mean": lambda: uncertainty.mean(
            SE3.exp(np.zeros((5, 3, 6), np.float32)), init=SE3.identity((5, 3))
        ),
    }
    for name, call in cases.items():
        with pytest.raises(
            ValueError,
            match=re.escape(name) + r".*do not broadcast|" + re.escape(name) + r".*must broadcast",
        ) as info:
            call()
        assert "(3" in str(info.value), (name, str(info.value))


def test_se_constructors_name_what_they_got():
    """``from_rotation`` given an array, or another library's SO3, says so (it raised
    AttributeError on a tracer, and "must be SO3, got SO3")."""
    import jaxlie

    with pytest.raises(TypeError, match=r"SE3.from_rotation: .*array of shape \(4,\)"):
        SE3.from_rotation(jnp.zeros(4))
    with pytest.raises(TypeError, match=r"must be jaxlie_geo\.\S*SO3, got jaxlie\.\S*SO3"):
        SE3.from_rotation_and_translation(jaxlie.SO3.identity(), jnp.zeros(3))


def test_integer_inputs_take_the_elements_dtype():
    """Integer covariances, velocities and tangent increments combined with a float32 element
    give float32 under x64, as integer points and translations do (they were promoted to the
    default float, float64). Without x64 the default float is float32: nothing to tell."""
    from benchmarks.mpref import x64_for
    from jaxlie_geo import jacobians, motion, uncertainty

    with x64_for("float64"):
        T = SE3.exp(jnp.zeros(6, jnp.float32))
        S = SE2.exp(jnp.zeros(3, jnp.float32))
        eye = np.eye(6, dtype=np.int32)
        outs = [
            uncertainty.propagate_compose(T, eye, T, eye, eye),
            uncertainty.propagate_inverse(T, eye),
            uncertainty.propagate_apply(T, eye, np.zeros(3, np.int32), np.eye(3, dtype=np.int32)),
            uncertainty.sample(jax.random.PRNGKey(0), T, eye).parameters(),
            motion.pose_at(T, np.ones(6, np.int32), 2.0).parameters(),
            motion.arc(S, np.ones(3, np.int32)).centre,
            *jacobians.rplus(T, np.ones(6, np.int32)),
            jaxlie_geo.manifold.rplus(T, np.ones(6, np.int32)).parameters(),  # was float64
        ]
        assert [o.dtype for o in outs] == [jnp.float32] * len(outs)


@pytest.mark.parametrize(
    ("call", "bad", "named"),
    [
        (lambda x: jaxlie_geo.jacobians.rplus(SO3.identity(), x), (4,), "jacobians.rplus: `delta`"),
        (
            lambda x: jaxlie_geo.jacobians.apply(SE3.identity(), x),
            (4,),
            "jacobians.apply: `points`",
        ),
        (
            lambda x: jaxlie_geo.uncertainty.propagate_apply(SE3.identity(), np.eye(6), x),
            (2,),
            "propagate_apply: `points`",
        ),
        (
            lambda x: jaxlie_geo.motion.pose_at(SE3.identity(), x, 1.0),
            (3,),
            "motion.pose_at: `velocity`",
        ),
        (lambda x: jaxlie_geo.motion.arc(SE2.identity(), x), (2,), "motion.arc: `velocity`"),
        (lambda x: jaxlie_geo.manifold.rplus(SE2.identity(), x), (6,), "manifold.rplus: `delta`"),
    ],
    ids=[
        "jacobians.rplus",
        "jacobians.apply",
        "propagate_apply",
        "pose_at",
        "arc",
        "manifold.rplus",
    ],
)
def test_module_functions_name_themselves_and_the_argument(call, bad, named):
    """Errors from module functions name that function and its argument (they named the
    method underneath, e.g. "SO3.rplus: `tangent`" or "SE3.apply: `target`")."""
    with pytest.raises(ValueError) as info:
        call(np.zeros(bad))
    assert str(info.value).startswith(named), str(info.value)
    assert str(tuple(bad)) in str(info.value)


def test_odd_parameter_dtypes_and_reshape_sizes():
    """Complex parameters are refused by the operations (they returned complex silently);
    integer parameters normalize to the default float (they raised "not inexact"), as
    jaxlie's do; NumPy integers are sizes for reshape; float16 poses can be sampled
    (XLA has no half-precision Cholesky)."""
    from jaxlie_geo import uncertainty

    msg = r"SO3.log: SO3 parameters must be real, got dtype complex64"
    with pytest.raises(ValueError, match=msg):
        SO3(jnp.array([1j, 0, 0, 0], jnp.complex64)).log()
    with pytest.raises(ValueError, match="must be real"):
        SE2(jnp.zeros(4, jnp.complex64)).as_matrix()
    N = SO3(jnp.array([2, 0, 0, 0])).normalize()
    assert jnp.issubdtype(N.wxyz.dtype, jnp.floating)
    np.testing.assert_array_equal(np.asarray(N.wxyz), [1.0, 0.0, 0.0, 0.0])
    assert SE3.identity((6,)).reshape(np.int64(2), 3).get_batch_axes() == (2, 3)
    assert SE3.identity((6,)).reshape(np.int64(6)).get_batch_axes() == (6,)
    T = uncertainty.sample(
        jax.random.PRNGKey(0),
        SE3.identity(dtype=jnp.float16),
        0.01 * jnp.eye(6, dtype=jnp.float16),
        batch_axes=(64,),
    )
    p = T.parameters()
    assert p.dtype == jnp.float16 and bool(jnp.all(jnp.isfinite(p)))
    assert 0.03 < float(jnp.std(p[:, 4:].astype(jnp.float32))) < 0.2  # σ = 0.1


def test_broadcast_leading_axes_names_a_scalar_input():
    """A scalar among the inputs has no trailing axis: a named ValueError, not IndexError."""
    with pytest.raises(ValueError, match=r"broadcast_leading_axes: input 1 .*got \(\)"):
        jaxlie_geo.utils.broadcast_leading_axes((SE3.identity((3,)), 1.0))
