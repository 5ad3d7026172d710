"""SO(3): 3D rotations as unit quaternions, with closed-form vector kernels."""

from __future__ import annotations

from typing import Any, Optional, Tuple

import jax
import jax.numpy as jnp
import numpy as onp
from typing_extensions import override

from . import _scalar, hints
from ._base import SOBase
from ._checks import as_float_array, resolve_dtype
from ._projection import nearest_quaternion, rotation_quaternion
from ._pytree import pytree_dataclass
from ._scalar import components, sq_norm
from ._xla import Entries, Schedule, constant, from_entries


def cross(a: jax.Array, b: jax.Array) -> jax.Array:
    """Cross product over the last axis (broadcasting), written out: no (..., 3, 3)."""
    a0, a1, a2 = components(a)
    b0, b1, b2 = components(b)
    return jnp.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def skew(w: jax.Array) -> jax.Array:
    """The matrix ŵ with ŵ v = w × v (Eberly 2024, eq. 26): ``(*batch, 3) -> (*batch, 3, 3)``."""
    x, y, z = components(w)
    o = jnp.zeros_like(x)
    return jnp.stack(
        [jnp.stack([o, -z, y], -1), jnp.stack([z, o, -x], -1), jnp.stack([-y, x, o], -1)],
        axis=-2,
    )


def exp_quaternion(
    omega: jax.Array, half: Optional[Tuple[jax.Array, jax.Array]] = None
) -> jax.Array:
    """Unit quaternion ``(cos(θ/2), sin(θ/2)/θ · ω)``, θ = ‖ω‖: ``(*batch, 3) -> (*batch, 4)``.

    ``half`` = (cos(θ/2), sin(θ/2)/(θ/2)) from ``exp_half_angle`` (pass it to share one
    sincos with the SE(3) translation)."""
    c, k = exp_half_angle(omega) if half is None else half
    return jnp.concatenate([c[..., None], (0.5 * k)[..., None] * omega], axis=-1)


def exp_half_angle(omega: jax.Array) -> Tuple[jax.Array, jax.Array]:
    """(cos(θ/2), sin(θ/2)/(θ/2)), θ = ‖ω‖, each of shape ``batch`` for ω of ``(*batch, 3)``
    (``_scalar.half_angle`` of the plain θ²)."""
    return _scalar.half_angle(sq_norm(omega))


def log_quaternion(wxyz: jax.Array) -> jax.Array:
    """Principal log of a quaternion ``(*batch, 4) -> (*batch, 3)``: ω = 2 atan2(‖v‖, w)/‖v‖ · v
    after the sign choice w ≥ 0, so the angle is in [0, π]. The quaternion need not be
    unit (see ``_scalar.atan2_over`` for the range of norms). The atan2 form is accurate up
    to and at π (no acos, no snapping); at w = 0 exactly (angle π) the sign is flipped, as
    for w < 0 and as in jaxlie: ω = −π times the stored vector part's direction."""
    u, s, _ = log_quaternion_parts(wxyz)
    return s[..., None] * u


def log_quaternion_parts(wxyz: jax.Array) -> Tuple[jax.Array, jax.Array, jax.Array]:
    """(u, s, h) with ω = log(q) = s·u: u the stored vector part (sign-flipped where
    w ≤ 0, exact), s = θ/‖u‖ = 2 atan2(‖u‖, |w|)/‖u‖, and h = (θ/2)cot(θ/2) read off the same
    quaternion as |w| · atan2(‖u‖, |w|)/‖u‖ — no cancellation anywhere on [0, π], unlike
    1 − θ² G, which cancels as h → 0 near π. All three depend on q's direction only, as the
    rotation does (a drifted, non-unit q). Formulas built on (u, s) rather than the rounded
    ω avoid propagating ω's rounding through products with long translations."""
    w = wxyz[..., 0]
    sign = jnp.where(w <= 0, -1.0, 1.0).astype(wxyz.dtype)  # w = ±0: −1, as jaxlie
    u = sign[..., None] * wxyz[..., 1:]
    n2, aw = sq_norm(u), sign * w
    ratio = _scalar.atan2_over(n2, aw)
    h = aw * ratio  # (θ/2)|w|/‖u‖, scale-invariant (dividing by ‖q‖ broke SE3.log off ‖q‖ = 1)
    return u, 2.0 * ratio, h


def _euler_zyx(wxyz: jax.Array) -> Tuple[jax.Array, jax.Array, jax.Array]:
    """(roll φ, pitch θ, yaw ψ) of ``Rz(ψ) Ry(θ) Rx(φ)`` from a quaternion of any norm.

    With half angles, q = qz(ψ) qy(θ) qx(φ) gives (up to q's sign and norm)

        A = (w + y) + i(z − x) = (cos θ/2 + sin θ/2) e^{i(ψ − φ)/2},
        B = (w − y) + i(z + x) = (cos θ/2 − sin θ/2) e^{i(ψ + φ)/2},

    so ψ = arg(A B), φ = arg(B Ā), and θ = atan(2(wy − zx) / (|A| |B|)) (|A|² − |B|² =
    4(wy − zx) = 2|q|² sin θ, |A| |B| = |q|² cos θ). A B and B Ā expand to the usual
    (w² + x² − y² − z²) + 2i(wz + xy) and (w² + z² − x² − y²) + 2i(wx + yz), but the
    sums forming A and B are single roundings (exact where they cancel, by Sterbenz), so at
    and near gimbal lock (θ → ±π/2, B or A → 0) the small factor keeps full relative
    accuracy: ψ and φ, each ill-conditioned there, come out with ψ − φ (or ψ + φ) correct
    to a few ulp, the same in every compiled context, and ``from_rpy_radians`` of the three
    angles gives the rotation back to a few ulp. The expanded sums cancel there into
    rounding noise that differs between fusions (FMA contraction): reads of roll and yaw
    from separately jitted calls gave O(1) round-trip errors at lock, and the asin of
    2(wy − zx) loses half the digits of θ (NaN past ±1). Where B (or A) is exactly 0, it
    is read as 1: ψ = −φ = arg A (or ψ = φ = arg B). A zero quaternion gives (0, 0, 0)."""
    w, x, y, z = components(wxyz)
    a_re, a_im, b_re, b_im = w + y, z - x, w - y, z + x

    def one_if_zero(re: jax.Array, im: jax.Array) -> jax.Array:
        return jnp.where((re == 0) & (im == 0), jnp.ones_like(re), re)

    sin_ = 2.0 * (w * y - z * x)
    a2, b2 = a_re * a_re + a_im * a_im, b_re * b_re + b_im * b_im
    # atan of sin/cos (cos ≥ 0) costs 2/3 of atan2; where A or B is 0 (exactly at lock),
    # ±π/2 with a zero derivative (the square roots are kept off 0, whose derivative is inf)
    pos = (a2 > 0) & (b2 > 0)
    one = jnp.ones_like(a2)
    cos_ = jnp.sqrt(jnp.where(pos, a2, one)) * jnp.sqrt(jnp.where(pos, b2, one))
    lock = ~pos & (sin_ != 0)
    pitch = jnp.where(
        lock, jnp.copysign(jnp.asarray(jnp.pi / 2, wxyz.dtype), sin_), jnp.arctan(sin_ / cos_)
    )
    a_re, b_re = one_if_zero(a_re, a_im), one_if_zero(b_re, b_im)
    yaw = jnp.arctan2(a_re * b_im + a_im * b_re, a_re * b_re - a_im * b_im)
    roll = jnp.arctan2(a_re * b_im - a_im * b_re, a_re * b_re + a_im * b_im)
    return roll, pitch, yaw


def quaternion_product(p: jax.Array, q: jax.Array) -> jax.Array:
    """Hamilton product of ``(w, x, y, z)`` quaternions (batch axes broadcast)."""
    w1, x1, y1, z1 = components(p)
    w2, x2, y2, z2 = components(q)
    return jnp.stack(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ],
        axis=-1,
    )


def rotate(wxyz: jax.Array, p: jax.Array) -> jax.Array:
    """The sandwich q p q* = p + d p + 2w (u × p) + 2 u × (u × p), u = (x, y, z) and
    d = |q|² − 1: R(q) p for a unit quaternion, and for any other |q|² R(q/|q|) p, as
    jaxlie's ``apply`` (so ``jax.grad`` with respect to raw parameters, radial part
    included, is jaxlie's too; with ``p`` in place of |q|² p, jaxlie's projected-gradient
    example took another path). d = (w − 1)(w + 1) + |u|² cancels without error near the
    identity: for float32 unit quaternions and rotations of ~10⁻³, at most 0.49 eps·|p| from
    the exact sandwich (|q|² p computed directly: 1.59); generic rotations 3.1."""
    w = wxyz[..., :1]
    u = wxyz[..., 1:]
    uxp = cross(u, p)
    d = (w - 1.0) * (w + 1.0) + sq_norm(u)[..., None]
    return p + (d * p + 2.0 * (w * uxp + cross(u, uxp)))


def skew_sq(w: jax.Array) -> jax.Array:
    """ŵ² = w wᵀ − ‖w‖² I, without a matrix product."""
    outer = w[..., :, None] * w[..., None, :]
    return outer - sq_norm(w)[..., None, None] * constant(onp.eye(3), outer)


def jac_right_so3(omega: jax.Array) -> jax.Array:
    """Right Jacobian of SO(3), J_r(ω) = I − F1(θ²) ω̂ + F2(θ²) ω̂² (Solà et al. 2018,
    eq. 143; F1, F2 as in Eberly 2024, eq. 42): ``(*batch, 3) -> (*batch, 3, 3)``."""
    x = sq_norm(omega)
    eye = constant(onp.eye(3), omega[..., None])
    return (
        eye
        - _scalar.F1(x)[..., None, None] * skew(omega)
        + _scalar.F2(x)[..., None, None] * skew_sq(omega)
    )


def jac_right_inv_so3(omega: jax.Array) -> jax.Array:
    """Inverse right Jacobian of SO(3), J_r⁻¹(ω) = I + ½ ω̂ + G(θ²) ω̂²
    (Solà et al. 2018, eq. 144; G from _scalar): ``(*batch, 3) -> (*batch, 3, 3)``."""
    eye = constant(onp.eye(3), omega[..., None])
    return eye + 0.5 * skew(omega) + _scalar.G(sq_norm(omega))[..., None, None] * skew_sq(omega)


def rodrigues_entries(w: jax.Array, a: jax.Array, b: Any, c: jax.Array) -> Entries:
    """The entries of a I + b ŵ + c w wᵀ for ``w`` ``(*batch, 3)`` and coefficients
    ``(*batch,)`` (``b`` may be a number): the form of every SO(3) Jacobian."""
    w0, w1, w2 = components(w)
    cw0, cw1, cw2 = c * w0, c * w1, c * w2
    bw0, bw1, bw2 = b * w0, b * w1, b * w2
    return [
        [a + cw0 * w0, cw0 * w1 - bw2, cw0 * w2 + bw1],
        [cw1 * w0 + bw2, a + cw1 * w1, cw1 * w2 - bw0],
        [cw2 * w0 - bw1, cw2 * w1 + bw0, a + cw2 * w2],
    ]


def jlog_so3(omega: jax.Array) -> jax.Array:
    """J_r⁻¹(ω) for a principal ω (θ ≤ π, a log's output): ``(*batch, 3) -> (*batch, 3, 3)``.

    Evaluated as h I + ½ ω̂ + G ω ωᵀ, with G = ``G_principal``(θ²) and h = 1 − θ² G
    (ω̂² = ω ωᵀ − θ² I), written entry by entry; the same matrix as
    ``jac_right_inv_so3(omega)`` (Solà et al. 2018, eq. 144) on the principal range. Speed
    against ``jax.jacfwd``: ``benchmarks/jacobians.py``."""
    x = sq_norm(omega)
    g = _scalar.G_principal(x)
    return from_entries(rodrigues_entries(omega, 1.0 - x * g, 0.5, g))


@pytree_dataclass
class SO3(SOBase):
    """Special orthogonal group of 3D rotations.

    Parameters: ``wxyz``, a unit quaternion ``(qw, qx, qy, qz)``, shape ``(*batch, 4)``
    (Hamilton convention; q and −q are the same rotation, and no operation flips the
    sign implicitly). Tangent: ``(ωx, ωy, ωz)``, the rotation vector (axis times angle),
    shape ``(*batch, 3)``. Matrix: the 3×3 rotation R(q), acting on column vectors.
    """

    wxyz: jax.Array
    """Unit quaternion ``(w, x, y, z)``, shape ``(*batch, 4)``."""

    matrix_dim = 3
    parameters_dim = 4
    tangent_dim = 3
    space_dim = 3
    _schedule = Schedule(reread=True, interpolate_in_memory=True)

    # -- factories ------------------------------------------------------------------

    @staticmethod
    def _about_axis(theta: hints.Scalar, axis: int, where: str) -> SO3:
        theta = as_float_array(theta, "theta", (), where)
        half = 0.5 * theta
        parts = [jnp.cos(half)] + [jnp.zeros_like(half)] * 3
        parts[axis + 1] = jnp.sin(half)
        return SO3(jnp.stack(parts, axis=-1))

    @staticmethod
    def from_x_radians(theta: hints.Scalar) -> SO3:
        """Rotation by ``theta`` radians about the x axis.

        Args:
            theta: angle, scalar or array of shape ``batch``.

        Returns:
            SO3 with batch axes ``batch``.
        """
        return SO3._about_axis(theta, 0, "SO3.from_x_radians")

    @staticmethod
    def from_y_radians(theta: hints.Scalar) -> SO3:
        """Rotation by ``theta`` radians about the y axis (``theta`` as in
        ``from_x_radians``)."""
        return SO3._about_axis(theta, 1, "SO3.from_y_radians")

    @staticmethod
    def from_z_radians(theta: hints.Scalar) -> SO3:
        """Rotation by ``theta`` radians about the z axis (``theta`` as in
        ``from_x_radians``)."""
        return SO3._about_axis(theta, 2, "SO3.from_z_radians")

    @staticmethod
    def from_rpy_radians(roll: hints.Scalar, pitch: hints.Scalar, yaw: hints.Scalar) -> SO3:
        """Rotation from ZYX Euler angles (mobile-robot convention):
        ``Rz(yaw) @ Ry(pitch) @ Rx(roll)``, roll applied first.

        Args:
            roll: rotation about x, radians.
            pitch: rotation about y, radians.
            yaw: rotation about z, radians. The three are scalars or arrays that broadcast
                to a common batch shape.

        Returns:
            SO3 with that batch shape.
        """
        return SO3.from_z_radians(yaw) @ SO3.from_y_radians(pitch) @ SO3.from_x_radians(roll)

    @staticmethod
    def from_quaternion_xyzw(xyzw: hints.Array) -> SO3:
        """Rotation from a quaternion stored scalar-last.

        Args:
            xyzw: ``(*batch, 4)``, ``(x, y, z, w)``; reordered to ``wxyz``, sign and norm
                kept.

        Returns:
            SO3 with batch axes ``batch``.
        """
        xyzw = as_float_array(xyzw, "xyzw", (4,), "SO3.from_quaternion_xyzw")
        return SO3(jnp.roll(xyzw, shift=1, axis=-1))

    def as_quaternion_xyzw(self) -> jax.Array:
        """The quaternion as ``(x, y, z, w)``, shape ``(*batch, 4)``."""
        return jnp.roll(self.wxyz, shift=-1, axis=-1)

    def as_rpy_radians(self) -> hints.RollPitchYaw:
        """ZYX Euler angles (roll, pitch, yaw), each of shape ``batch``."""
        roll, pitch, yaw = _euler_zyx(self.wxyz)
        return hints.RollPitchYaw(roll=roll, pitch=pitch, yaw=yaw)

    def compute_roll_radians(self) -> jax.Array:
        """Roll (rotation about x) of the ZYX convention, shape ``batch``, in [-π, π].
        Read so that ``from_rpy_radians`` of the three angles gives the rotation back to a
        few ulp also at and near gimbal lock (pitch ±π/2), where roll and yaw alone are
        undefined or ill-conditioned: see ``_euler_zyx``. Like ``as_matrix``, it depends on
        the quaternion's direction only."""
        return _euler_zyx(self.wxyz)[0]

    def compute_pitch_radians(self) -> jax.Array:
        """Pitch (rotation about y) of the ZYX convention, shape ``batch``, in [-π/2, π/2]:
        atan(sin/cos) with both read off the quaternion, accurate to a few ulp at gimbal
        lock too (jaxlie's asin of the sine loses half the digits there, and rounding past
        ±1 gives NaN); direction only (see ``_euler_zyx``). A zero quaternion gives 0."""
        return _euler_zyx(self.wxyz)[1]

    def compute_yaw_radians(self) -> jax.Array:
        """Yaw (rotation about z) of the ZYX convention, shape ``batch``, in [-π, π];
        direction only: the angle of (w² + x² − y² − z², 2(wz + xy)), computed as a product
        that stays accurate at gimbal lock (see ``_euler_zyx``)."""
        return _euler_zyx(self.wxyz)[2]

    @classmethod
    @override
    def identity(cls, batch_axes: Tuple[int, ...] = (), dtype: Any = None) -> SO3:
        dtype = resolve_dtype(dtype)
        return SO3(jnp.broadcast_to(jnp.array([1.0, 0.0, 0.0, 0.0], dtype), (*batch_axes, 4)))

    @classmethod
    @override
    def from_matrix(cls, matrix: hints.Array, project: bool = False) -> SO3:
        """The rotation of a rotation matrix, or with ``project=True`` the rotation nearest
        to any matrix in the Frobenius norm.

        ``project=False`` (the default): Shepperd's formulas on J. Day's branches, as
        jaxlie computes them, then one power step on Bar-Itzhack's K + I
        (``jaxlie_geo/_projection.py``). For a rotation matrix, its quaternion within
        3 ulp of jaxlie's, with jaxlie's sign (the component of Day's branch, x if
        m22 < 0 and m00 > m11, y if m22 < 0 otherwise, z if m00 < −m11, else w, is > 0).
        For a matrix R(I + E) off the rotations (drift, rounding, a noisy estimate), a
        unit quaternion within O(‖E‖²) of the nearest rotation's (Shepperd's formulas
        alone are O(‖E‖) off); for a matrix far from every rotation a valid rotation that
        need not be the nearest. Derivatives are the formula's: at a rotation, those of
        the projection, exact (half turns and branch switches included: the only square
        root is of the chosen component, ≥ 1 for a rotation).

        ``project=True``: the projection onto SO(3) for any matrix. The quaternion is the
        eigenvector of the largest eigenvalue of the symmetric 4×4 matrix K with
        qᵀKq = tr(R(q)ᵀM) (Bar-Itzhack, *New method for extracting the quaternion from a
        rotation matrix*, 2000; Horn, *Closed-form solution of absolute orientation using
        unit quaternions*, 1987), by a fixed number of cyclic Jacobi sweeps, elementwise
        (no choice depends on other elements of a batch). The same rotation as the SVD
        projection U diag(1, 1, det UVᵀ) Vᵀ of M = U Σ Vᵀ, within 1.3 ulp · κ (measured,
        largest entry), κ = (d1 + d2 + d3)/(d2 + d3) with d the singular values, the
        last one carrying the sign of det M: in float32, at most 2.1 ulp for rotations
        with noise up to 0.1, and 2.6 with noise 0.3. A reflection (det M < 0) gives
        U diag(1, 1, −1) Vᵀ. Where the nearest rotation is not unique (d2 + d3 = 0: the
        zero matrix, rank 1, orthogonal reflections), one of the nearest, never NaN: the
        identity for 0, diag(1, 0, 0) and diag(1, 1, −1), the half turn about x for −I.
        The derivative is that of the projection (a custom JVP); where the projection is
        not unique it does not exist and is returned finite (0 where the linear system
        behind it is exactly singular). It costs many times the default (the results page
        has both).

        Args:
            matrix: ``(*batch, 3, 3)``: a rotation matrix, or any real matrix with
                ``project=True``.
            project: static; whether to project an arbitrary matrix (above).

        Returns:
            SO3 with batch axes ``batch``, in the matrix's dtype.
        """
        m = cls._check_matrix(matrix, "from_matrix")
        return SO3(nearest_quaternion(m) if project else rotation_quaternion(m))

    @classmethod
    @override
    def sample_uniform(
        cls, key: jax.Array, batch_axes: Tuple[int, ...] = (), dtype: Any = None
    ) -> SO3:
        # Uniform on S³ (Shoemake 1992; LaValle, Planning Algorithms §5.2.2), drawing
        # the same numbers as jaxlie for the same key.
        dtype = resolve_dtype(dtype)
        u = jax.random.uniform(
            key,
            (*batch_axes, 3),
            dtype=dtype,
            minval=jnp.zeros(3, dtype),
            maxval=jnp.array([1.0, 2.0 * jnp.pi, 2.0 * jnp.pi], dtype),
        )
        u1, u2, u3 = u[..., 0], u[..., 1], u[..., 2]
        a, b = jnp.sqrt(1.0 - u1), jnp.sqrt(u1)
        return SO3(
            jnp.stack([a * jnp.sin(u2), a * jnp.cos(u2), b * jnp.sin(u3), b * jnp.cos(u3)], -1)
        )

    # -- Lie algebra ----------------------------------------------------------------

    @classmethod
    @override
    def exp(cls, tangent: hints.Array) -> SO3:
        """Exponential map of the rotation vector ω.

        q = (cos(θ/2), sin(θ/2)/θ · ω), θ = ‖ω‖: Rodrigues' formula
        R = I + F0 ω̂ + F1 ω̂² (Eberly 2024, eq. 27) in quaternion form. Both coefficients
        come from ``_scalar.half_angle`` (closed forms with an exact custom JVP).

        Args:
            tangent: ``(*batch, 3)``, ``(ωx, ωy, ωz)``.

        Returns:
            SO3 with batch axes ``batch``. Any angle whose square is finite is accepted
            (θ < 1.8e19 in float32, 1.3e154 in float64; beyond, θ² overflows and the result
            is NaN, as jaxlie's is). For θ > π the result has w < 0 (it is not re-signed).
        """
        return SO3(exp_quaternion(cls._check_tangent(tangent)))

    @override
    def log(self) -> jax.Array:
        """Principal logarithm: the rotation vector ω, ``(*batch, 3)``, with ‖ω‖ in [0, π].

        With the sign of q chosen so that w ≥ 0 and u its vector part,
        ω = 2 atan2(‖u‖, w)/‖u‖ · u (``log_quaternion``). Unlike the trace/acos form
        (Eberly 2024, §9.2), which loses about √ε in the angle near π, it is accurate up to
        and at π; at exactly π (w = 0) ω is −π times the stored vector part's direction, as
        in jaxlie. It depends on q's direction only (a drifted, non-unit q gives the log of
        q/|q|)."""
        return log_quaternion(self.wxyz)

    @override
    def jlog(self) -> jax.Array:
        return jlog_so3(self.log())

    @classmethod
    @override
    def hat(cls, tangent: hints.Array) -> jax.Array:
        return skew(as_float_array(tangent, "tangent", (3,), "SO3.hat"))

    @classmethod
    @override
    def vee(cls, matrix: hints.Array) -> jax.Array:
        m = as_float_array(matrix, "matrix", (3, 3), "SO3.vee")
        return 0.5 * jnp.stack(
            [m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]],
            axis=-1,
        )

    @override
    def adjoint(self) -> jax.Array:
        return self.as_matrix()

    @classmethod
    @override
    def jac_right(cls, tangent: hints.Array) -> jax.Array:
        return jac_right_so3(cls._check_tangent(tangent, "jac_right"))

    @classmethod
    @override
    def jac_right_inv(cls, tangent: hints.Array) -> jax.Array:
        return jac_right_inv_so3(cls._check_tangent(tangent, "jac_right_inv"))

    @classmethod
    @override
    def ad(cls, tangent: hints.Array) -> jax.Array:
        return skew(cls._check_tangent(tangent, "ad"))

    @classmethod
    @override
    def _bracket(cls, a: jax.Array, b: jax.Array) -> jax.Array:
        """[a, b] = a × b."""
        return jnp.cross(a, b)

    # -- operations -----------------------------------------------------------------

    @override
    def as_matrix(self) -> jax.Array:
        """Rotation matrix of q/|q| (as jaxlie: a non-unit quaternion still gives a
        rotation), ``(*batch, 3, 3)``."""
        q = self.wxyz
        w, x, y, z = components(q)
        s = 2.0 / (w * w + x * x + y * y + z * z)  # sq_norm(q)
        xx, yy, zz = s * x * x, s * y * y, s * z * z
        xy, xz, yz = s * x * y, s * x * z, s * y * z
        wx, wy, wz = s * w * x, s * w * y, s * w * z
        rows = [
            [1.0 - (yy + zz), xy - wz, xz + wy],
            [xy + wz, 1.0 - (xx + zz), yz - wx],
            [xz - wy, yz + wx, 1.0 - (xx + yy)],
        ]
        return jnp.stack([jnp.stack(row, -1) for row in rows], -2)

    @override
    def _apply_kernel(self, points: jax.Array) -> jax.Array:
        """Rotate points, shape ``(*batch, 3)``: R(q) p, and for a non-unit q the sandwich
        q p q* = |q|² R(q/|q|) p, as jaxlie (``rotate``)."""
        return rotate(self.wxyz, points)

    @override
    def _multiply_kernel(self, other: SO3) -> SO3:
        return SO3(quaternion_product(self.wxyz, other.wxyz))

    @override
    def inverse(self) -> SO3:
        q = self.wxyz
        return SO3(q * constant([1.0, -1.0, -1.0, -1.0], q))

    @override
    def normalize(self) -> SO3:
        return SO3(_scalar.unit(self.wxyz))

    @override
    def _rplus_jacobian(self) -> jax.Array:
        # d/dδ of q ⊗ (1, δ/2) at δ = 0.
        w, x, y, z = components(self.wxyz)
        rows = [[-x, -y, -z], [w, -z, y], [z, w, -x], [-y, x, w]]
        return 0.5 * jnp.stack([jnp.stack(r, -1) for r in rows], -2)
