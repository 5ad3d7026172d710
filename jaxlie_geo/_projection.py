"""Rotations from matrices: the fast conversion behind ``from_matrix`` and the exact
projection behind ``from_matrix(..., project=True)``.

**The conversion** (``rotation_quaternion``, ``rotation_unit_complex``) is for matrices that
are rotations up to rounding or small drift. SO(3): S. W. Shepperd's formulas (*Quaternion
from rotation matrix*, J. Guidance and Control 1(3), 1978) on J. Day's branches (*Converting
a rotation matrix to a quaternion*, Insomniac Games, 2015), as jaxlie computes them: the
branch is chosen on the diagonal (x if m22 < 0 and m00 > m11, y if m22 < 0 otherwise, z if
m00 < −m11, else w), and the chosen component t = 1 ± m00 ± m11 ± m22 (≥ 1 for a rotation)
with the three sums and differences of off-diagonal entries is 4·q_j·q. Read that way the
four candidates are the columns of K + I (K below): for a rotation, K + I = 4qqᵀ. A matrix
M = R(I + E) a little off the rotations gives K + I = 4qqᵀ + δK, and a column of it is q
only to first order in E, off the nearest rotation by O(E) in directions where δK's column
differs from δK q. One step of the power iteration on K + I, q ← (K + I) q₀ / ‖·‖, removes
that term: (K + I) q₀ = 4q(qᵀq₀) + δK q + O(E²), whose direction is the nearest rotation's
to first order (its dominant eigenvector, K + I having gap 4 at a rotation), so the result
is within O(E²) of the projection, and on a rotation within a few ulp of Shepperd's
quaternion. Derivatives are those of the formula, which at a rotation are the projection's
(they agree to second order): exact, also at half turns and on the branch switches, where
the only square root is of the chosen t ≥ 1 (a square root of every candidate, selected
afterwards, gives 0·∞ = NaN in the gradient of the ones not chosen). Planar: the unit
vector along (m00 + m11, m10 − m01), which is the projection itself.

**The projection.** ``from_matrix(..., project=True)`` of every group returns the rotation
R nearest to the given matrix block M in the Frobenius norm. Since
‖R − M‖² = ‖R‖² + ‖M‖² − 2 tr(RᵀM) and ‖R‖² is fixed, that is the rotation that maximises
tr(RᵀM).

SO(2): tr(R(θ)ᵀM) = (m00 + m11) cos θ + (m10 − m01) sin θ, maximised by
θ = atan2(m10 − m01, m00 + m11).

SO(3): for R = R(q), tr(RᵀM) = qᵀKq is a quadratic form in the quaternion, with the
symmetric, traceless 4×4 matrix (order w, x, y, z)

    K = [[m00+m11+m22, m21−m12,      m02−m20,      m10−m01    ],
         [m21−m12,     m00−m11−m22,  m01+m10,      m02+m20    ],
         [m02−m20,     m01+m10,      m11−m00−m22,  m12+m21    ],
         [m10−m01,     m02+m20,      m12+m21,      m22−m00−m11]],

three times the matrix of I. Y. Bar-Itzhack, *New method for extracting the quaternion from a
rotation matrix* (J. Guidance, Control, and Dynamics 23(6), 2000), the same construction as
B. K. P. Horn's N in *Closed-form solution of absolute orientation using unit quaternions*
(JOSA A 4(4), 1987, §4). The nearest rotation is the quaternion of K's largest eigenvalue.
With M = U diag(d1, d2, d3) Vᵀ, U and V rotations and d1 ≥ d2 ≥ |d3| (d3 < 0 iff det M < 0),
the eigenvalues of K are d1+d2+d3 ≥ d1−d2−d3 ≥ d2−d1−d3 ≥ d3−d1−d2, and the nearest rotation
is U Vᵀ (with an ordinary SVD, orthogonal factors and singular values ≥ 0:
U diag(1, 1, det UVᵀ) Vᵀ). It is unique iff d2 + d3 > 0, the gap between K's two largest
eigenvalues being 2(d2 + d3). For a rotation, K = 4qqᵀ − I (eigenvalues 3, −1, −1, −1).

The eigenvector is computed by one elementwise computation, the same for every input;
the matrix is first scaled by a power of two (exact) so that its largest entry is in [1, 2).
The cyclic Jacobi method (G. H. Golub and C. F. Van Loan, *Matrix Computations*, 4th ed.,
2013, §8.5) runs a fixed number of sweeps: each sweep applies the plane rotations (0,1),
(2,3), (0,2), (1,3), (0,3), (1,2), each zeroing one off-diagonal entry, and accumulates them
in V; K → VᵀKV becomes diagonal, and the column of V at its largest diagonal entry is the
eigenvector. Jacobi converges quadratically whatever the spectrum, to an eigenvector as
accurate as its conditioning allows (error about ε/gap), also for repeated eigenvalues,
where any vector of the top eigenspace is a nearest rotation. Sweeps: 4 (float32 and
narrower), 5 (float64). A last multiplication by K + cI, c = max(λ₁/3, −(λ₁ + λ_min)/2)
from Jacobi's eigenvalues, leaves the top eigenvector, amplifies no other component, and
brings a near-rotation back to rounding. There is no data-dependent branch and no loop with
a data-dependent count: each element's result depends on that element alone, and a batch
sharded over several devices is computed without communication.

Accuracy (the largest entry error of the rotation matrix against a long-double reference,
float32 and float64): at most 2 ulp for rotations and rotations with noise up to 0.1, and at
most 1.3 ulp · κ for any matrix, κ = (d1 + d2 + d3)/(d2 + d3) the conditioning of the nearest
rotation; the quaternion of a rotation is within 2 ulp of Shepperd's formulas (jaxlie's),
and within 4 ulp of mpmath's at and near π (``tests/test_from_matrix.py``). The
measurements, the sweep counts and the alternatives measured (``jnp.linalg.eigh``, power
iteration, a Shepperd start, Horn's characteristic polynomial) are in
``docs/design/nearest-rotation.md``.

Derivative (a custom JVP, exact whatever the iteration): with R the result, S = RᵀM is
symmetric at the optimum, so M = RS, Ṁ = ṘS + RṠ and Ṙ = R ω̂ give RᵀṀ − ṀᵀR = ω̂S + Sω̂,
whose vee is ((tr S) I − S) ω; ω is solved for by the adjugate, and q̇ = ½ q ⊗ (0, ω).
(tr S) I − S has eigenvalues d2 + d3, d1 + d3, d1 + d2: it is singular exactly where the
nearest rotation is not unique, where the derivative does not exist; the JVP is then 0 if
the matrix is exactly singular, and of size 1/(d2 + d3) near it.
"""

from __future__ import annotations

from typing import Dict, Iterable, List, Tuple

import jax
import jax.numpy as jnp

from ._scalar import pow2_inverse

__all__ = [
    "nearest_quaternion",
    "nearest_unit_complex",
    "rotation_quaternion",
    "rotation_unit_complex",
]

_PAIRS = ((0, 1), (2, 3), (0, 2), (1, 3), (0, 3), (1, 2))
_SYM = tuple((i, j) for i in range(4) for j in range(i, 4))
_FULL = tuple((i, j) for i in range(4) for j in range(4))


def _sweeps(dtype: jnp.dtype) -> int:
    """Jacobi sweeps for ``dtype`` (measured: see the module docstring)."""
    return 5 if jnp.finfo(dtype).nmant > 23 else 4


def _pow2_scale(m: jax.Array) -> jax.Array:
    """2^k per matrix (the last two axes of ``m``), shape ``m.shape[:-2]``, with the largest
    |entry| · 2^k in [1, 2) (``_scalar.pow2_inverse``)."""
    return pow2_inverse(jnp.max(jnp.abs(m), axis=(-2, -1)))


def _entries(m: jax.Array) -> List[List[jax.Array]]:
    """The nine entries of ``(*batch, 3, 3)``, each of shape ``batch``, read from one
    transposed copy: XLA:CPU reads contiguous rows at a fraction of the cost of nine
    strided slices (docs/design/nearest-rotation.md)."""
    flat = jnp.moveaxis(m.reshape((*m.shape[:-2], 9)), -1, 0)
    return [[flat[3 * i + j] for j in range(3)] for i in range(3)]


def _k_matrix(r: List[List[jax.Array]]) -> Dict[Tuple[int, int], jax.Array]:
    """The upper triangle of K (module docstring), keyed by (i, j), i ≤ j."""
    return {
        (0, 0): r[0][0] + r[1][1] + r[2][2],
        (0, 1): r[2][1] - r[1][2],
        (0, 2): r[0][2] - r[2][0],
        (0, 3): r[1][0] - r[0][1],
        (1, 1): r[0][0] - r[1][1] - r[2][2],
        (1, 2): r[0][1] + r[1][0],
        (1, 3): r[0][2] + r[2][0],
        (2, 2): r[1][1] - r[0][0] - r[2][2],
        (2, 3): r[1][2] + r[2][1],
        (3, 3): r[2][2] - r[0][0] - r[1][1],
    }


def _sym(a: Dict[Tuple[int, int], jax.Array], i: int, j: int) -> jax.Array:
    return a[(i, j) if i <= j else (j, i)]


def _sum(xs: Iterable[jax.Array]) -> jax.Array:
    """Σ xs, written out as additions (no reduction: it stays in its neighbours' fused loop)."""
    it = iter(xs)
    out = next(it)
    for x in it:
        out = out + x
    return out


def _jacobi_sweep(state: List[jax.Array]) -> List[jax.Array]:
    """One cyclic sweep on (the upper triangle of K, the 16 entries of V)."""
    a = dict(zip(_SYM, state[:10]))
    v = dict(zip(_FULL, state[10:]))
    for p, q in _PAIRS:
        apq, d = a[(p, q)], a[(q, q)] - a[(p, p)]
        # t = tan of the angle that zeroes a_pq: sign(d)·2a_pq/(|d| + √(d² + 4a_pq²)), the
        # smaller root (Golub and Van Loan §8.5.1), 0 where a_pq = d = 0.
        den = jnp.abs(d) + jnp.sqrt(d * d + 4.0 * apq * apq)
        ok = den > 0
        t = jnp.where(ok, 2.0 * apq / jnp.where(ok, den, 1.0), 0.0)
        t = jnp.where(d < 0, -t, t)
        c = 1.0 / jnp.sqrt(1.0 + t * t)
        s = t * c
        new = dict(a)
        new[(p, p)] = a[(p, p)] - t * apq
        new[(q, q)] = a[(q, q)] + t * apq
        new[(p, q)] = jnp.zeros_like(apq)
        for k in range(4):
            if k not in (p, q):
                akp, akq = _sym(a, k, p), _sym(a, k, q)
                new[(min(k, p), max(k, p))] = c * akp - s * akq
                new[(min(k, q), max(k, q))] = s * akp + c * akq
        a = new
        for k in range(4):
            vp, vq = v[(k, p)], v[(k, q)]
            v[(k, p)] = c * vp - s * vq
            v[(k, q)] = s * vp + c * vq
    return [a[key] for key in _SYM] + [v[key] for key in _FULL]


def _rotation(q: jax.Array) -> List[List[jax.Array]]:
    """Entries of R(q) for a unit quaternion ``(*batch, 4)``."""
    w, x, y, z = (q[..., i] for i in range(4))
    return [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]


def _times(
    k: Dict[Tuple[int, int], jax.Array], c: jax.Array, v: List[jax.Array]
) -> List[jax.Array]:
    """(K + cI) v."""
    return [_sum(_sym(k, i, j) * v[j] for j in range(4)) + c * v[i] for i in range(4)]


def _jacobi(
    k: Dict[Tuple[int, int], jax.Array], dtype: jnp.dtype
) -> Tuple[List[jax.Array], jax.Array, jax.Array]:
    """Cyclic Jacobi on K (module docstring): (the column of V at the largest diagonal
    entry of VᵀKV, that entry, the smallest)."""
    one, zero = jnp.ones_like(k[(0, 0)]), jnp.zeros_like(k[(0, 0)])
    v0 = [one if i == j else zero for i, j in _FULL]
    state = [k[key] for key in _SYM] + v0
    state = jax.lax.fori_loop(0, _sweeps(dtype), lambda _, s: _jacobi_sweep(s), state)
    lam = [state[_SYM.index((i, i))] for i in range(4)]
    vecs = dict(zip(_FULL, state[10:]))
    top, low, col = lam[0], lam[0], [vecs[(i, 0)] for i in range(4)]
    for j in range(1, 4):
        better = lam[j] > top
        top = jnp.where(better, lam[j], top)
        low = jnp.minimum(low, lam[j])
        col = [jnp.where(better, vecs[(i, j)], col[i]) for i in range(4)]
    return col, top, low


@jax.custom_jvp
def nearest_quaternion(m: jax.Array) -> jax.Array:
    """Unit quaternion (w, x, y, z) of the rotation nearest to ``m`` in the Frobenius norm:
    the dominant eigenvector of K (module docstring), signed as jaxlie signs
    ``SO3.from_matrix`` (after J. Day's branches on the diagonal: the component that jaxlie
    computes, x if m22 < 0 and m00 > m11, y if m22 < 0 otherwise, z if m00 < −m11, else w,
    is ≥ 0). Where the nearest rotation is not unique (d2 + d3 = 0: the zero matrix, rank 1,
    orthogonal reflections), one of the nearest; for a diagonal ``m``, the basis vector at
    the first largest diagonal entry of K (the identity for 0, diag(1, 0, 0) and
    diag(1, 1, −1); the half turn about x for −I). A NaN or inf entry gives NaN.

    Args:
        m: ``(*batch, 3, 3)``, floating; any matrix.

    Returns:
        ``(*batch, 4)``, in ``m``'s dtype.
    """
    scale = _pow2_scale(m)
    r = _entries(m * scale[..., None, None])
    k = _k_matrix(r)
    v, top, low = _jacobi(k, m.dtype)
    # One multiplication by K + cI (module docstring); skipped for K = 0 (top = 0).
    c = jnp.maximum(top / 3.0, -0.5 * (top + low))
    col = [jnp.where(top > 0, x, y) for x, y in zip(_times(k, c, v), v)]
    norm = jnp.sqrt(_sum(x * x for x in col))
    d0, d1, d2 = r[0][0], r[1][1], r[2][2]
    day = jnp.where(d2 < 0, jnp.where(d0 > d1, col[1], col[2]),
                    jnp.where(d0 < -d1, col[3], col[0]))  # fmt: skip
    sign = jnp.where(day < 0, -1.0, 1.0).astype(m.dtype)
    # A NaN or inf entry gives NaN (the guards above would otherwise return a rotation).
    sign = jnp.where(jnp.isfinite(_sum(x for row in r for x in row)), sign, jnp.nan)
    return jnp.moveaxis(jnp.stack([sign * (x / norm) for x in col]), 0, -1)


@nearest_quaternion.defjvp
def _nearest_quaternion_jvp(primals, tangents):  # type: ignore[no-untyped-def]
    (m,), (dm,) = primals, tangents
    q = nearest_quaternion(m)
    scale = _pow2_scale(m)[..., None, None]
    a, da = _entries(m * scale), _entries(dm * scale)
    rot = _rotation(q)
    # S = RᵀA (symmetrised), X = RᵀȦ, H = (tr S) I − S, ω = H⁻¹ vee(X − Xᵀ).
    s = [[_sum(rot[k][i] * a[k][j] for k in range(3)) for j in range(3)] for i in range(3)]
    x = [[_sum(rot[k][i] * da[k][j] for k in range(3)) for j in range(3)] for i in range(3)]
    tr = s[0][0] + s[1][1] + s[2][2]
    h = [[(tr if i == j else 0.0) - 0.5 * (s[i][j] + s[j][i]) for j in range(3)] for i in range(3)]
    rhs = [x[2][1] - x[1][2], x[0][2] - x[2][0], x[1][0] - x[0][1]]
    adj = [
        [h[(j + 1) % 3][(i + 1) % 3] * h[(j + 2) % 3][(i + 2) % 3]
         - h[(j + 1) % 3][(i + 2) % 3] * h[(j + 2) % 3][(i + 1) % 3] for j in range(3)]
        for i in range(3)
    ]  # fmt: skip
    det = _sum(h[0][j] * adj[j][0] for j in range(3))
    ok = det != 0
    inv = jnp.where(ok, 1.0 / jnp.where(ok, det, 1.0), 0.0)
    w = [inv * _sum(adj[i][j] * rhs[j] for j in range(3)) for i in range(3)]
    qw, qx, qy, qz = (q[..., i] for i in range(4))
    dq = [
        -0.5 * (qx * w[0] + qy * w[1] + qz * w[2]),
        0.5 * (qw * w[0] + qy * w[2] - qz * w[1]),
        0.5 * (qw * w[1] + qz * w[0] - qx * w[2]),
        0.5 * (qw * w[2] + qx * w[1] - qy * w[0]),
    ]
    return q, jnp.stack(dq, axis=-1)


def nearest_unit_complex(m: jax.Array) -> jax.Array:
    """(cos θ, sin θ) of the planar rotation nearest to ``m`` in the Frobenius norm,
    θ = atan2(m10 − m01, m00 + m11) (module docstring), computed without trigonometry as
    the unit vector along (m00 + m11, m10 − m01). Where m00 + m11 = m10 − m01 = 0 (the zero
    matrix, every reflection [[a, b], [b, −a]]) every rotation is equally near: (1, 0), the
    identity. Derivatives are those of the formula (0 on that set).

    Args:
        m: ``(*batch, 2, 2)``, floating; any matrix.

    Returns:
        ``(*batch, 2)``, in ``m``'s dtype.
    """
    cos = m[..., 0, 0] + m[..., 1, 1]
    sin = m[..., 1, 0] - m[..., 0, 1]
    ok = (cos != 0) | (sin != 0)
    v = jnp.stack([jnp.where(ok, cos, 1.0), jnp.where(ok, sin, 0.0)], axis=-1)
    scale = _pow2_scale(v[..., None])[..., None]
    v = v * scale
    return v / jnp.sqrt(v[..., :1] * v[..., :1] + v[..., 1:] * v[..., 1:])


def rotation_quaternion(m: jax.Array) -> jax.Array:
    """Unit quaternion (w, x, y, z) of a rotation matrix ``m``: Shepperd's formulas on Day's
    branches, with jaxlie's sign (the chosen component > 0), then one power step on K + I
    (module docstring). For a rotation, within a few ulp of jaxlie's ``from_matrix``; for
    M = R(I + E), a unit quaternion within O(‖E‖²) of the nearest rotation's; for a matrix
    far from every rotation, a unit quaternion that need not be the nearest (the identity
    for the zero matrix). Day's branch makes the chosen component t ≥ 1 for every matrix,
    so nothing divides by zero; a NaN or inf entry gives NaN. The power step's entries
    grow as ‖M‖^(3/2) (as ‖M‖² where t stays near 1), and their squares overflow for
    entries beyond about 1e9 in float32 (1e76 in float64): the result is then NaN
    (``nearest_quaternion`` scales first).

    Args:
        m: ``(*batch, 3, 3)``, floating.

    Returns:
        ``(*batch, 4)``, in ``m``'s dtype.
    """
    r = _entries(m)
    (m00, m01, m02), (m10, m11, m12), (m20, m21, m22) = r
    k = _k_matrix(r)
    x_or_y, z_or_w = m00 > m11, m00 < -m11
    # The candidates (t, column of K + I), selected before the one square root.
    cases = [
        (1 + m00 - m11 - m22, 1),  # x
        (1 - m00 + m11 - m22, 2),  # y
        (1 - m00 - m11 + m22, 3),  # z
        (1 + m00 + m11 + m22, 0),  # w
    ]

    def column(j: int, t: jax.Array) -> List[jax.Array]:
        return [t if i == j else _sym(k, i, j) for i in range(4)]

    def pick(a: Tuple[jax.Array, ...], b: Tuple[jax.Array, ...], c: jax.Array) -> Tuple:
        return tuple(jnp.where(c, x, y) for x, y in zip(a, b))

    x, y, z, w = ((t, *column(j, t)) for t, j in cases)
    t, *col = pick(pick(x, y, x_or_y), pick(z, w, z_or_w), m22 < 0)
    half = 0.5 / jnp.sqrt(t)  # t ≥ 1 on Day's branch
    q1 = _times(k, jnp.ones_like(t), [c * half for c in col])  # (K + I) q₀
    inv = 1.0 / jnp.sqrt(_sum(v * v for v in q1))  # ≥ q1_j ≥ ½: never 0
    return jnp.moveaxis(jnp.stack([v * inv for v in q1]), 0, -1)


def rotation_unit_complex(m: jax.Array) -> jax.Array:
    """(cos θ, sin θ) of a planar rotation matrix: the unit vector along
    (m00 + m11, m10 − m01), the nearest rotation to any ``m`` (``nearest_unit_complex``
    without its power-of-two scaling, so entries beyond about 1e19 overflow in float32),
    the sine's zero signed as m10's so that a rotation gives jaxlie's first column
    (−I with a −0.0 below the diagonal: angle −π). The identity where both sums are 0.

    Args:
        m: ``(*batch, 2, 2)``, floating.

    Returns:
        ``(*batch, 2)``, in ``m``'s dtype.
    """
    cos = m[..., 0, 0] + m[..., 1, 1]
    sin = m[..., 1, 0] - m[..., 0, 1]
    sin = jnp.where(sin == 0, jnp.copysign(sin, m[..., 1, 0]), sin)
    n2 = cos * cos + sin * sin
    ok = n2 > 0
    inv = 1.0 / jnp.sqrt(jnp.where(ok, n2, 1.0))
    return jnp.stack([jnp.where(ok, cos * inv, 1.0), sin * inv], axis=-1)
