"""Uniform cumulative B-splines on every group, with exact time derivatives and Jacobians
with respect to the control points.

A spline of degree ``k − 1`` (order ``k``, 2 ≤ k ≤ 6) with control points T₀ … Tₙ₋₁ and
knot spacing Δt is, on segment ``s`` (time ``t = t0 + (s + u)·Δt``, ``u ∈ [0, 1]``),

    T(t) = T_s · A₁ · … · Aₖ₋₁,    A_j = exp(λ_j(u) d_j),    d_j = log(Tₛ₊ⱼ₋₁⁻¹ Tₛ₊ⱼ),

the cumulative form of Kim, Kim and Shin, "A General Construction Scheme for Unit
Quaternion Curves with Simple High Order Derivatives" (SIGGRAPH 1995), written for any Lie
group. λ(u) = M̃ (1, u, …, uᵏ⁻¹)ᵀ with M̃ the cumulative blending matrix of the uniform
B-spline (Qin, "General matrix representations for B-splines", The Visual Computer 2000,
eq. 5; ``cumulative_basis``). Segment ``s`` depends on the ``k`` control points
``T_s … Tₛ₊ₖ₋₁`` only. The valid times are ``[t0, t0 + (n − k + 1)·Δt]``.

Derivatives are the recursions of Sommer, Usenko, Schubert, Demmel, Cremers, "Efficient
Derivative Computation for Cumulative B-Splines on Lie Groups" (CVPR 2020), not autodiff:
with ω⁽⁰⁾ = 0 and Ad_j = Ad(A_j⁻¹),

    ω⁽ʲ⁾ = Ad_j ω⁽ʲ⁻¹⁾ + λ̇_j d_j
    ω̇⁽ʲ⁾ = Ad_j ω̇⁽ʲ⁻¹⁾ + λ̇_j [ω⁽ʲ⁾, d_j] + λ̈_j d_j
    ω̈⁽ʲ⁾ = Ad_j ω̈⁽ʲ⁻¹⁾ + 2 λ̇_j [ω̇⁽ʲ⁾, d_j] + λ̈_j [ω⁽ʲ⁾, d_j] − λ̇_j² [[ω⁽ʲ⁾, d_j], d_j] + λ⃛_j d_j,

derivatives in u (dots), divided by Δt, Δt², Δt³ for time. The third line is this module's
derivation, by differentiating the second once more. [a, b] = vee(â b̂ − b̂ â) = ``ad(a) b``.
ω = ω⁽ᵏ⁻¹⁾/Δt is the body velocity: T⁻¹ Ṫ = hat(ω).

Control-point Jacobians come from the same products, as one forward recursion (derived
here). A right perturbation T_m → T_m exp(δ_m) moves d_j by
Δd_j = J_r⁻¹(d_j)(δₛ₊ⱼ − Ad(exp(−d_j)) δₛ₊ⱼ₋₁) and A_j to A_j exp(η_j), with
η_j = λ_j J_r(λ_j d_j) Δd_j; the value moves to T exp(P δ), with P⁽⁰⁾ = [I, 0, …] and
P⁽ʲ⁾ = Ad_j P⁽ʲ⁻¹⁾ + η_j; the velocity and acceleration follow by perturbing their
recursions, with Ad(exp(−η)) w ≈ w + ad(w) η.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time
from fractions import Fraction
from typing import Any, Generic, Literal, NamedTuple, Optional, Tuple, Union

import jax
import jax.numpy as jnp
import numpy as onp

from . import _sparse, hints, least_squares
from ._base import GroupT, MatrixLieGroup
from ._batch import in_chunks
from ._pytree import pytree_dataclass
from ._record import Record, callback, check_options, recording
from ._xla import matmul

MAX_DEGREE = 5
"""The highest degree supported (order 6)."""


@functools.lru_cache(maxsize=None)
def cumulative_basis(order: int) -> Tuple[Tuple[Fraction, ...], ...]:
    """The cumulative blending matrix M̃ of the uniform B-spline of ``order`` k (degree
    k − 1), exact: ``λ_j(u) = Σ_n M̃[j][n] uⁿ``, ``j, n = 0 … k−1``.

    ``M̃[j][n] = Σ_{s ≥ j} M[s][n]``, with Qin (2000), eq. 5:
    ``M[s][n] = C(k−1, n)/(k−1)! · Σ_{l=s}^{k−1} (−1)^{l−s} C(k, l−s) (k−1−l)^{k−1−n}``.
    Row 0 is (1, 0, …, 0) (the basis functions sum to one)."""
    k = order
    fact = math.factorial(k - 1)
    m = [
        [
            Fraction(math.comb(k - 1, n), fact)
            * sum(
                (-1) ** (l_ - s) * math.comb(k, l_ - s) * (k - 1 - l_) ** (k - 1 - n)
                for l_ in range(s, k)
            )
            for n in range(k)
        ]
        for s in range(k)
    ]
    return tuple(
        tuple(sum((m[r][n] for r in range(j, k)), Fraction(0)) for n in range(k)) for j in range(k)
    )


def _blending(order: int, u: jax.Array, derivatives: int) -> jax.Array:
    """λ_j(u) and its first ``derivatives`` u-derivatives: ``(derivatives + 1, *u.shape, k)``.
    Horner's rule with the exact coefficients as constants (elementwise: no small matrix
    product, and exact in any matmul precision mode)."""
    k = order
    M = cumulative_basis(k)
    out = []
    for r in range(derivatives + 1):
        rows = []
        for j in range(k):
            # d^r/du^r Σ_n M[j][n] uⁿ = Σ_{n ≥ r} M[j][n] n!/(n−r)! u^{n−r}
            coeffs = [
                float(M[j][n] * (math.factorial(n) // math.factorial(n - r))) for n in range(r, k)
            ]
            acc = jnp.full_like(u, coeffs[-1]) if coeffs else jnp.zeros_like(u)
            for c in reversed(coeffs[:-1]):
                acc = acc * u + c
            rows.append(acc)
        out.append(jnp.stack(rows, axis=-1))
    return jnp.stack(out)


class SplineTime(NamedTuple):
    """A time on a spline as a segment index and the fraction of the segment:
    ``t = t0 + (segment + fraction)·dt``.

    The exact form of a time: a float32 time near t0 + 10⁵ is only known to 2⁻⁷ ≈ 0.008,
    while the fraction of a segment of length 0.01 is kept to 10⁻⁷. ``Spline.locate``
    computes it (on the host in float64 or exact integer arithmetic for concrete times);
    under ``jit`` pass it directly where a time stamp would lose digits in the working
    dtype."""

    segment: jax.Array
    """Integer array, ``0 ≤ segment < num_segments``."""
    fraction: jax.Array
    """Floating array, ``0 ≤ fraction ≤ 1``, broadcasting with ``segment``."""


class SplineEvaluation(NamedTuple):
    """Value and body-frame derivatives at the same times, batch ``S``."""

    value: Any
    """Group element, batch ``S``."""
    velocity: jax.Array
    """Body velocity ω, ``T⁻¹ dT/dt = hat(ω)``: ``(*S, tangent_dim)``."""
    acceleration: jax.Array
    """dω/dt, ``(*S, tangent_dim)``; zeros when not requested."""
    jerk: jax.Array
    """d²ω/dt², ``(*S, tangent_dim)``; zeros when not requested."""


class ControlPointJacobians(NamedTuple):
    """Jacobians with respect to the ``order`` control points a time depends on (local
    support; the layout of basalt's ``JacobianStruct``): control point ``first + i``'s
    block is ``[..., i, :, :]``. Perturbations are right ones, T_m → T_m exp(δ_m); the
    value's Jacobian is that of log(T(t)⁻¹ T'(t))."""

    first: jax.Array
    """Index of the first control point, integer, shape ``S``."""
    value: jax.Array
    """``(*S, order, tangent_dim, tangent_dim)``."""
    velocity: jax.Array
    """Of the body velocity, ``(*S, order, tangent_dim, tangent_dim)``."""
    acceleration: jax.Array
    """Of dω/dt, ``(*S, order, tangent_dim, tangent_dim)``."""


def _static_field(**kwargs: Any) -> Any:
    return dataclasses.field(metadata={"static": True}, **kwargs)


@pytree_dataclass
class Spline(Generic[GroupT]):
    """Uniform cumulative B-spline on a group (module docstring for the formulas).

    A pytree: the control points are its leaves (optimise them with ``jax.grad``, optax or
    ``fit``); ``degree``, ``t0`` and ``dt`` are static (a change recompiles).

    Times ``t`` accepted by every method: a float or integer array of any shape, or a
    ``SplineTime``. A concrete time outside ``[t0, t_end]`` raises ``ValueError``; a
    traced one (under ``jit``) is clamped to the interval. Results have batch
    ``S = broadcast(t.shape, B)``, ``B`` the control points' batch after the knot axis
    (independent splines of the same length).
    """

    control_points: GroupT
    """Group element of batch ``(n, *B)``: the knot axis first."""
    degree: int = _static_field(default=3)
    """1 (piecewise geodesic) to 5."""
    t0: Union[int, float] = _static_field(default=0.0)
    """Start of the valid interval (the start of segment 0)."""
    dt: Union[int, float] = _static_field(default=1.0)
    """Knot spacing, > 0. Integers ``t0`` and ``dt`` with integer time stamps (e.g.
    nanoseconds) locate times exactly."""

    def __post_init__(self) -> None:
        if not isinstance(self.degree, (int, onp.integer)) or not 1 <= self.degree <= MAX_DEGREE:
            raise ValueError(
                f"Spline: degree must be an integer in [1, {MAX_DEGREE}], got {self.degree!r}."
            )
        for name in ("t0", "dt"):
            v = getattr(self, name)
            if not isinstance(v, (int, float, onp.integer, onp.floating)) or not math.isfinite(v):
                raise ValueError(f"Spline: `{name}` must be a finite Python number, got {v!r}.")
        if not self.dt > 0:
            raise ValueError(f"Spline: `dt` must be positive, got {self.dt!r}.")
        cp = self.control_points
        if not isinstance(cp, MatrixLieGroup):
            raise TypeError(
                f"Spline: `control_points` must be a group element, got {type(cp).__name__}."
            )
        batch = cp.get_batch_axes()
        if len(batch) == 0 or batch[0] < self.order:
            raise ValueError(
                f"Spline: a degree-{self.degree} spline needs at least {self.order} control "
                f"points on the first batch axis, got batch axes {batch}."
            )

    # -- shape and time ---------------------------------------------------------------

    @property
    def order(self) -> int:
        """``degree + 1``: the number of control points each time depends on."""
        return int(self.degree) + 1

    @property
    def num_segments(self) -> int:
        """``n − degree``: segments of length ``dt`` in the valid interval."""
        return int(self.control_points.get_batch_axes()[0]) - int(self.degree)

    @property
    def interval(self) -> Tuple[float, float]:
        """The valid times ``(t0, t0 + num_segments·dt)``."""
        return (self.t0, self.t0 + self.num_segments * self.dt)

    def locate(self, t: Union[hints.Array, SplineTime]) -> SplineTime:
        """Segment index and fraction of times ``t``.

        Concrete times are located on the host, in float64 (exact for integer time stamps
        with integer ``t0`` and ``dt``), so a float32 spline keeps its fraction at any
        distance from ``t0``. Outside the interval (by more than a few float64 ulp of the
        time, the rounding of ``t0 + i·dt``) they raise ``ValueError``. Traced times are
        located in their own dtype (at least the control points') and clamped to the
        interval. The last time of the interval is the end (fraction 1) of the last
        segment."""
        dtype = self.control_points.parameters().dtype
        last = self.num_segments - 1
        if isinstance(t, SplineTime):
            seg, frac = t
            if not isinstance(seg, jax.core.Tracer) and not isinstance(frac, jax.core.Tracer):
                s_np, f_np = onp.asarray(seg), onp.asarray(frac)
                if not onp.issubdtype(s_np.dtype, onp.integer):
                    raise ValueError(
                        f"Spline: SplineTime.segment must be integer, got {s_np.dtype}."
                    )
                if s_np.size and (s_np.min() < 0 or s_np.max() > last):
                    raise ValueError(
                        f"Spline: segment outside [0, {last}]: {s_np.min()} … {s_np.max()}."
                    )
                if f_np.size and not (f_np.min() >= 0 and f_np.max() <= 1):
                    raise ValueError("Spline: SplineTime.fraction must lie in [0, 1].")
            seg = jnp.clip(jnp.asarray(seg), 0, last).astype(jnp.int32)
            frac = jnp.clip(jnp.asarray(frac).astype(dtype), 0, 1)
            return SplineTime(seg, frac)
        if not isinstance(t, jax.core.Tracer):
            return self._locate_concrete(onp.asarray(t), dtype)
        t = jnp.asarray(t)
        exact_ints = jnp.issubdtype(t.dtype, jnp.integer) and _is_int(self.t0) and _is_int(self.dt)
        if exact_ints:
            rel = t - int(self.t0)
            seg = jnp.floor_divide(rel, int(self.dt))
            frac = (rel - seg * int(self.dt)).astype(dtype) / jnp.asarray(self.dt, dtype)
        else:
            work = (
                jnp.promote_types(t.dtype, dtype)
                if jnp.issubdtype(t.dtype, jnp.floating)
                else dtype
            )
            rel = (t.astype(work) - jnp.asarray(self.t0, work)) / jnp.asarray(self.dt, work)
            seg = jnp.floor(rel)
            frac = rel - seg
        seg_c = jnp.clip(seg, 0, last)
        frac = jnp.where(seg < 0, 0, jnp.where(seg > last, 1, frac))
        return SplineTime(seg_c.astype(jnp.int32), jnp.clip(frac, 0, 1).astype(dtype))

    def _locate_concrete(self, t: onp.ndarray, dtype: Any) -> SplineTime:
        if onp.issubdtype(t.dtype, onp.complexfloating) or t.dtype == onp.bool_:
            raise ValueError(f"Spline: times must be real numbers, got dtype {t.dtype}.")
        n_seg = self.num_segments
        if onp.issubdtype(t.dtype, onp.integer) and _is_int(self.t0) and _is_int(self.dt):
            rel_i = t.astype(onp.int64) - int(self.t0)
            seg = rel_i // int(self.dt)
            frac = (rel_i - seg * int(self.dt)) / float(self.dt)
            outside = (rel_i < 0) | (rel_i > n_seg * int(self.dt))
        else:
            rel = (t.astype(onp.float64) - float(self.t0)) / float(self.dt)
            seg = onp.floor(rel)
            frac = rel - seg
            # a time computed as t0 + i·dt may round past either end: a few ulp are allowed
            slack = 4 * onp.finfo(onp.float64).eps * (onp.abs(t) + abs(self.t0)) / self.dt
            outside = ~((rel >= -slack) & (rel <= n_seg + slack))
            seg = onp.where(rel < 0, 0, seg)
            frac = onp.where(rel < 0, 0.0, frac)
        if onp.any(outside):
            lo, hi = self.interval
            bad = t[outside].ravel()[0]
            raise ValueError(
                f"Spline: time {bad} outside the valid interval [{lo}, {hi}] (t0 = {self.t0}, "
                f"dt = {self.dt}, {n_seg} segments)."
            )
        at_end = seg >= n_seg
        seg = onp.where(at_end, n_seg - 1, seg)
        frac = onp.where(at_end, 1.0, frac)
        return SplineTime(jnp.asarray(seg.astype(onp.int32)), jnp.asarray(frac, dtype))

    # -- evaluation -------------------------------------------------------------------

    def __call__(self, t: Union[hints.Array, SplineTime]) -> GroupT:
        """The element at times ``t``, batch ``S``."""
        return _evaluate(self, self.locate(t), 0).value

    def velocity(self, t: Union[hints.Array, SplineTime], frame: str = "body") -> jax.Array:
        """Velocity at ``t``, ``(*S, tangent_dim)``: in the body frame (default) ω with
        ``T⁻¹ Ṫ = hat(ω)``; in the world frame (``frame="world"``) ``Ad(T) ω``, with
        ``Ṫ T⁻¹ = hat(Ad(T) ω)``. For SE(3) with body velocity (v, ω_b) the world
        angular velocity is R ω_b and the position moves as ṗ = R v."""
        ev = _evaluate(self, self.locate(t), 1)
        return _in_frame(ev, ev.velocity, frame)

    def acceleration(self, t: Union[hints.Array, SplineTime], frame: str = "body") -> jax.Array:
        """dω/dt at ``t`` (ω the body velocity), ``(*S, tangent_dim)``. In the world frame,
        the derivative of the world velocity: ``d/dt (Ad(T) ω) = Ad(T) dω/dt``. For SE(3)
        the position's acceleration is p̈ = R (v̇ + ω × v)."""
        ev = _evaluate(self, self.locate(t), 2)
        return _in_frame(ev, ev.acceleration, frame)

    def jerk(self, t: Union[hints.Array, SplineTime], frame: str = "body") -> jax.Array:
        """d²ω/dt² at ``t``, ``(*S, tangent_dim)``; zero for degree < 3 inside a segment.
        In the world frame ``Ad(T)(ω̈ + [ω, ω̇])``, the second derivative of the world
        velocity."""
        ev = _evaluate(self, self.locate(t), 3)
        if frame == "world":
            G = type(ev.value)
            fix = G._bracket(ev.velocity, ev.acceleration)
            return _in_frame(ev, ev.jerk + fix, frame)
        return _in_frame(ev, ev.jerk, frame)

    def evaluate(self, t: Union[hints.Array, SplineTime], derivatives: int = 2) -> SplineEvaluation:
        """Value and body-frame derivatives up to ``derivatives`` (0 … 3) in one pass; the
        derivatives not requested are zeros."""
        if derivatives not in (0, 1, 2, 3):
            raise ValueError(
                f"Spline.evaluate: derivatives must be 0, 1, 2 or 3, got {derivatives!r}."
            )
        return _evaluate(self, self.locate(t), derivatives)

    def jacobians(self, t: Union[hints.Array, SplineTime]) -> ControlPointJacobians:
        """Jacobians of the value, the body velocity and dω/dt with respect to right
        perturbations of the ``order`` control points that ``t`` depends on."""
        return _jacobians(self, self.locate(t))


def _is_int(x: Any) -> bool:
    return isinstance(x, (int, onp.integer)) and not isinstance(x, bool)


def _in_frame(ev: SplineEvaluation, x: jax.Array, frame: str) -> jax.Array:
    if frame == "body":
        return x
    if frame == "world":
        return ev.value._adjoint_apply(x)
    raise ValueError(f"Spline: frame must be 'body' or 'world', got {frame!r}.")


def _gather(x: jax.Array, index: jax.Array, batch: Tuple[int, ...]) -> jax.Array:
    """``x[index[…], b…]`` for ``x`` of shape ``(n, *batch, *rest)`` and ``index`` of shape
    ``S`` (which ends with ``batch``, broadcast): one gather, nothing of size n·|S|."""
    n = x.shape[0]
    m = math.prod(batch)
    rest = x.shape[1 + len(batch) :]
    flat = x.reshape(n * m, *rest)
    if m == 1:
        return flat[index]
    b = jnp.broadcast_to(jnp.arange(m).reshape(batch), index.shape)
    return flat[index * m + b]


def _deltas(spline: Spline[Any]) -> jax.Array:
    """d_i = log(T_i⁻¹ T_{i+1}) for every pair of neighbouring control points,
    ``(n − 1, *B, tangent_dim)``."""
    cp = spline.control_points
    return cp[:-1]._between(cp[1:]).log()


def _gathered(
    spline: Spline[Any], where: SplineTime
) -> Tuple[jax.Array, jax.Array, jax.Array, Tuple[int, ...]]:
    """Per time: the parameters of the first control point T_s ``(*S, P)``, the k − 1
    deltas d_j ``(*S, k−1, dim)`` and the fraction ``S``."""
    cp = spline.control_points
    batch = cp.get_batch_axes()[1:]
    seg, frac = where
    S = tuple(jnp.broadcast_shapes(jnp.shape(seg), jnp.shape(frac), batch))
    seg = jnp.broadcast_to(seg, S)
    D = _deltas(spline)
    d = jnp.stack([_gather(D, seg + j - 1, batch) for j in range(1, spline.order)], axis=-2)
    return _gather(cp.parameters(), seg, batch), d, jnp.broadcast_to(frac, S), S


def _segment(G: Any, order: int, p: jax.Array, d: jax.Array, u: jax.Array) -> Tuple[Any, ...]:
    """T_s, the deltas ``(k−1, *S, dim)`` and the blending derivatives ``(4, k, *S)``."""
    lam = jnp.moveaxis(_blending(order, u, 3), -1, 1)
    return G(p), jnp.moveaxis(d, -2, 0), lam, u.shape


def _steps(T: Any, d: jax.Array, lam: jax.Array) -> Tuple[Any, Any]:
    """The inverses of the k − 1 factors A_j = exp(λ_j d_j), as one batch ``(k−1, *S)``
    (one exp in the program whatever the degree), and T(t)."""
    A = type(T).exp(lam[0, 1:][..., None] * d)
    for j in range(d.shape[0]):
        T = T @ A[j]
    return A.inverse(), T


def _Ad_blocks(g: Any, X: jax.Array) -> jax.Array:
    """Ad(g) X on every block of ``X`` ``(*S, b, n, n)``, g of batch ``S``."""
    h = type(g)(g.parameters()[..., None, None, :])
    return jnp.swapaxes(h._adjoint_apply(jnp.swapaxes(X, -1, -2)), -1, -2)


def _ad_blocks(G: Any, a: jax.Array, X: jax.Array) -> jax.Array:
    """ad(a) X on every block of ``X`` ``(*S, b, n, n)``, a ``(*S, n)``."""
    return jnp.swapaxes(G._bracket(a[..., None, None, :], jnp.swapaxes(X, -1, -2)), -1, -2)


@functools.partial(jax.jit, static_argnums=2)
def _evaluate(spline: Spline[Any], where: SplineTime, derivatives: int) -> SplineEvaluation:
    G = type(spline.control_points)
    p, d, u, S = _gathered(spline, where)
    # Elementwise in the times: large batches run in chunks on CPU (``_batch.in_chunks``),
    # so the recursions' temporaries stay in cache.
    out = in_chunks(
        functools.partial(_recursions, G, spline.order, spline.dt, derivatives), S, p, d, u
    )
    return SplineEvaluation(G(out[0]), *out[1:])


def _recursions(
    G: Any, order: int, dt: float, derivatives: int, p: jax.Array, d: jax.Array, u: jax.Array
) -> Tuple[jax.Array, ...]:
    """Value and derivatives from the gathered inputs (``_gathered``), per time."""
    T, d, lam, S = _segment(G, order, p, d, u)
    Ainv, T = _steps(T, d, lam)
    zero = jnp.zeros((*S, G.tangent_dim), d.dtype)
    w, dw, ddw = zero, zero, zero
    if derivatives:
        for j in range(1, order):
            dj, Ad = d[j - 1], Ainv[j - 1]._adjoint_apply
            l1, l2, l3 = (lam[r, j][..., None] for r in range(1, 4))
            w = Ad(w) + l1 * dj
            if derivatives >= 2:
                wd = G._bracket(w, dj)
                dw_new = Ad(dw) + l1 * wd + l2 * dj
                if derivatives >= 3:
                    ddw = (
                        Ad(ddw)
                        + 2 * l1 * G._bracket(dw_new, dj)
                        + l2 * wd
                        - l1 * l1 * G._bracket(wd, dj)
                        + l3 * dj
                    )
                dw = dw_new
    h = jnp.asarray(dt, d.dtype)
    return T.parameters(), w / h, dw / h**2, ddw / h**3


@jax.jit
def _jacobians(spline: Spline[Any], where: SplineTime) -> ControlPointJacobians:
    G = type(spline.control_points)
    p, d, u, S = _gathered(spline, where)
    blocks = in_chunks(
        functools.partial(_jacobian_recursions, G, spline.order, spline.dt), S, p, d, u
    )
    return ControlPointJacobians(jnp.broadcast_to(where.segment, S), *blocks)


def _jacobian_recursions(
    G: Any, order: int, dt: float, p: jax.Array, d: jax.Array, u: jax.Array
) -> Tuple[jax.Array, ...]:
    """The three Jacobians' blocks from the gathered inputs (``_gathered``), per time."""
    T, d, lam, S = _segment(G, order, p, d, u)
    k, n = order, G.tangent_dim
    dtype = d.dtype
    Ainv, T = _steps(T, d, lam)
    # One batched call each over the k − 1 factors.
    Jinv = G.jac_right_inv(d)
    back = G.exp(-d).adjoint()  # Ad(exp(−d_j)) = Ad(T_{s+j}⁻¹ T_{s+j−1})
    l0 = lam[0, 1:]
    Jstep = l0[..., None, None] * G.jac_right(l0[..., None] * d)
    # Δd_j is non-zero on control points j − 1 and j only: the blocks (−J⁻¹ Ad, J⁻¹).
    Dd = jnp.stack([-matmul(Jinv, back), Jinv], axis=-3)
    eta = matmul(Jstep[..., None, :, :], Dd)  # (k−1, *S, 2, n, n)
    P = jnp.zeros((*S, k, n, n), dtype)
    P = P.at[..., 0, :, :].set(jnp.eye(n, dtype=dtype))  # value
    V, Acc = jnp.zeros_like(P), jnp.zeros_like(P)  # velocity, acceleration
    w, dw = jnp.zeros((*S, n), dtype), jnp.zeros((*S, n), dtype)
    for j in range(1, k):
        dj, inv, Dj, ej = d[j - 1], Ainv[j - 1], Dd[j - 1], eta[j - 1]
        c1, c2 = lam[1, j][..., None, None, None], lam[2, j][..., None, None, None]
        pair = slice(j - 1, j + 1)  # the blocks of control points j − 1 and j
        w_rot, dw_rot = inv._adjoint_apply(w), inv._adjoint_apply(dw)  # Ad_j ω⁽ʲ⁻¹⁾, …
        w = w_rot + lam[1, j][..., None] * dj
        dw = dw_rot + lam[1, j][..., None] * G._bracket(w, dj) + lam[2, j][..., None] * dj
        P = _Ad_blocks(inv, P).at[..., pair, :, :].add(ej)
        V = _Ad_blocks(inv, V).at[..., pair, :, :].add(_ad_blocks(G, w_rot, ej) + c1 * Dj)
        Acc = _Ad_blocks(inv, Acc) - c1 * _ad_blocks(G, dj, V)
        Acc = Acc.at[..., pair, :, :].add(
            _ad_blocks(G, dw_rot, ej) + c1 * _ad_blocks(G, w, Dj) + c2 * Dj
        )
    h = jnp.asarray(dt, dtype)
    return P, V / h, Acc / h**2


@dataclasses.dataclass(frozen=True)
class SplineFit:
    """What ``fit`` returns: the record of the least-squares loop, and the spline.

    Attributes:
        costs: ``(iterations + 1,)``, ½ Σ wᵢ ‖rᵢ‖² before the first step and after each
            accepted one.
        times: ``(iterations + 1,)``, for each cost the wall-clock seconds from the start
            of the call to its evaluation (the first includes compiling, for a new size).
        iterations: accepted steps.
        time: wall-clock seconds of the whole call.
        stop_reason: why it stopped, in words (``least_squares.StopReason.description``).
        converged: whether it stopped on the tolerance or with no step lowering the cost.
        spline: the fitted ``Spline``.
    """

    costs: onp.ndarray
    times: onp.ndarray
    iterations: int
    time: float
    stop_reason: str
    converged: bool
    spline: Any


@dataclasses.dataclass(frozen=True)
class _Sample:
    """One sample's residual √w ⊙ log(Z⁻¹ T(t)) as a ``least_squares`` residual of the
    ``degree + 1`` control points that shape it (the sample's segment as the first of a
    spline of those points), its data ``(fraction, Z, √w)``; and its closed-form Jacobian,
    ``Spline.jacobians`` composed with J_r⁻¹ of the residual."""

    degree: int
    dt: Union[int, float]

    def _local(self, points: Tuple[Any, ...], fraction: jax.Array):
        cp = jax.tree_util.tree_map(lambda *p: jnp.stack(p), *points)
        spline = Spline(cp, degree=self.degree, t0=0, dt=self.dt)
        return spline, SplineTime(jnp.zeros((), jnp.int32), fraction)

    def __call__(self, *args: Any) -> jax.Array:
        *points, (fraction, Z, s) = args
        spline, where = self._local(tuple(points), fraction)
        return s * Z._between(_evaluate(spline, where, 0).value).log()

    def jacobian(self, *args: Any) -> Tuple[jax.Array, jax.Array]:
        *points, (fraction, Z, s) = args
        spline, where = self._local(tuple(points), fraction)
        r = Z._between(_evaluate(spline, where, 0).value).log()
        J = matmul(type(Z).jac_right_inv(r), _jacobians(spline, where).value)  # (order, k, k)
        return s * r, s[:, None] * jnp.concatenate(list(J), axis=-1)


@functools.lru_cache(maxsize=None)
def _sample(degree: int, dt: Union[int, float]) -> _Sample:
    """One ``_Sample`` per degree and knot spacing: ``jit`` keys the loop on the residual
    and on its bound ``jacobian``, which compare by the instance's identity."""
    return _Sample(degree, dt)


def fit(
    times: hints.Array,
    poses: GroupT,
    *,
    dt: Union[int, float],
    degree: int = 3,
    t0: Optional[Union[int, float]] = None,
    weights: Optional[hints.Array] = None,
    initial: Optional[Spline[GroupT]] = None,
    method: Literal["lm", "gn"] = "lm",
    linear_solver: Literal[
        "auto", "cholesky", "cholmod", "qdldl", "banded", "dense", "pcg"
    ] = "auto",
    max_iterations: int = 50,
    tolerance: float = 1e-12,
    initial_damping: float = 1e-6,
    progress: bool = False,
) -> SplineFit:
    """Least-squares fit of a spline to time-stamped elements, on the group.

    Minimises ½ Σᵢ ‖ √wᵢ ⊙ log(Zᵢ⁻¹ T(tᵢ)) ‖² over the control points by
    Levenberg–Marquardt (or Gauss–Newton), with the exact Jacobians (``Spline.jacobians``
    composed with J_r⁻¹ of the residual) and steps T_m → T_m exp(δ_m); the loop, damping
    and stopping rules are those of ``pose_graph.solve``. Each sample's residual depends on
    ``degree + 1`` consecutive control points, so the normal equations are block-banded:
    time and memory grow linearly with the number of control points (docs/splines.md times
    a fit of 10⁴ control points).

    Args:
        times: concrete ``(N,)`` time stamps (float or integer, on the host).
        poses: the elements Zᵢ, batch ``(N,)``.
        dt: knot spacing.
        degree: 1 to 5.
        t0: start of the spline (default: the earliest time); the spline covers every
            time, with ``ceil((max(times) − t0)/dt) + degree`` control points.
        weights: ``(N,)`` (per sample) or ``(N, tangent_dim)`` (per residual coordinate),
            ≥ 0, default 1: inverse variances.
        initial: starting spline (same ``degree``, ``t0`` and ``dt``); default: each
            control point the sample nearest in time to its centre t0 + (i − (degree−1)/2)·dt.
        method: ``"lm"`` Levenberg–Marquardt or ``"gn"`` Gauss–Newton.
        linear_solver: as ``pose_graph.solve``'s; ``"auto"`` is CHOLMOD or QDLDL when
            installed, else the banded Cholesky (LAPACK, always available).
        max_iterations: the most accepted steps.
        tolerance: stop when a step lowers the cost by less than this fraction of it, or
            the linear model predicts less.
        initial_damping: Levenberg–Marquardt's first λ (damping λ diag(H)).
        progress: draw a progress line on stderr.

    Returns:
        ``SplineFit``: the spline and the loop's record.

    Raises:
        ValueError: inconsistent shapes, negative weights, an ``initial`` spline of other
            knots, or an option out of range.
    """
    clock = time.perf_counter()
    check_options(
        "splines.fit", method, linear_solver, max_iterations,
        tolerance=tolerance, initial_damping=initial_damping,
    )  # fmt: skip
    t_np = onp.asarray(times)
    if t_np.ndim != 1 or t_np.size == 0:
        raise ValueError(f"splines.fit: `times` must have shape (N,), got {t_np.shape}.")
    if not isinstance(poses, MatrixLieGroup) or poses.get_batch_axes() != t_np.shape:
        raise ValueError(
            f"splines.fit: `poses` must be a group element of batch {t_np.shape}, got "
            f"{getattr(poses, 'get_batch_axes', lambda: type(poses).__name__)()}."
        )
    G = type(poses)
    dtype = poses.parameters().dtype
    start = t_np.min() if t0 is None else t0
    start = start.item() if isinstance(start, onp.generic) else start
    span = (t_np.max() - start) / dt
    n = max(int(onp.ceil(span - 1e-9)), 1) + degree
    if initial is None:
        centres = start + (onp.arange(n) - (degree - 1) / 2) * dt
        order = onp.argsort(t_np, kind="stable")
        ts = t_np[order]
        right = onp.clip(onp.searchsorted(ts, centres), 1, len(ts) - 1) if len(ts) > 1 else 0
        left = right - 1 if len(ts) > 1 else 0
        closer_left = onp.abs(centres - ts[left]) <= onp.abs(ts[right] - centres)
        nearest = order[onp.where(closer_left, left, right)]
        initial = Spline(poses[jnp.asarray(nearest)], degree=degree, t0=start, dt=dt)
    elif (initial.degree, initial.t0, initial.dt) != (degree, start, dt):
        raise ValueError("splines.fit: `initial` must have the requested degree, t0 and dt.")
    where = initial.locate(t_np)
    N, k = t_np.size, G.tangent_dim
    w_np = onp.ones((N, k)) if weights is None else onp.asarray(weights, dtype=onp.float64)
    if w_np.shape not in ((N,), (N, k)) or not onp.all(w_np >= 0):
        raise ValueError(
            f"splines.fit: `weights` must be ≥ 0 of shape ({N},) or ({N}, {k}), got shape "
            f"{w_np.shape}."
        )
    w = jnp.asarray(onp.broadcast_to(w_np.reshape(N, -1), (N, k)), dtype)
    sample = _sample(degree, dt)
    first = onp.asarray(where.segment)
    factor = least_squares.Factor(
        sample,
        (0,) * (degree + 1),
        tuple(jnp.asarray(first + m) for m in range(degree + 1)),
        (jnp.broadcast_to(where.fraction, (N,)), poses, jnp.sqrt(w)),
        jacobian=sample.jacobian,
    )
    if linear_solver in ("auto", "cholesky"):
        installed = [b for b in ("cholmod", "qdldl") if _sparse.installed(b)]
        fallback = "banded" if linear_solver == "auto" else "qdldl"
        linear_solver = installed[0] if installed else fallback
    record = Record(clock, progress, max_iterations)
    with recording(record):
        sol = least_squares.solve(
            [factor], (initial.control_points,), method=method,
            max_iterations=max_iterations, tolerance=tolerance,
            initial_damping=initial_damping, diagonal_damping=True,
            linear_solver=linear_solver, callback=callback,
        )  # fmt: skip
        sol = jax.block_until_ready(sol)  # every callback has run
    iterations = int(sol.iterations)
    reason = least_squares.StopReason(int(sol.stop_reason)).description
    record.close(reason)
    costs, times = record.arrays(iterations)
    spline = Spline(sol.variables[0], degree=degree, t0=start, dt=dt)
    return SplineFit(
        costs=costs, times=times, iterations=iterations, time=time.perf_counter() - clock,
        stop_reason=reason, converged=bool(sol.converged), spline=spline,
    )  # fmt: skip


__all__ = [
    "MAX_DEGREE",
    "Spline",
    "SplineTime",
    "SplineEvaluation",
    "ControlPointJacobians",
    "cumulative_basis",
    "fit",
    "SplineFit",
]
