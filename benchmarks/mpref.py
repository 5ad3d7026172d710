"""Shared accuracy harness: mpmath references, input regimes and the ulp error measure.

Used by tests/test_accuracy.py (assertions on jaxlie_geo) and benchmarks/accuracy.py
(the same measurement, jaxlie_geo next to jaxlie 1.5). Everything a number in the
accuracy table depends on lives here, so the test and the table cannot drift apart.
It needs mpmath (the ``test`` and ``bench`` extras); the library never imports it.

Inputs. For every group, dtype, angle regime and translation size we draw ``n_per``
tangents with a fixed seed: a random unit direction (SO3/SE3) or a random sign
(SO2/SE2) times an angle drawn log-uniformly inside the regime's band (the first two
samples are the band's end points), and a translation of exactly the given norm in a
random direction (SE23: the position part; its velocity part's norm cycles through SIZES
within each cell; Sim3: the log-scale σ of ``_angles_sigmas``, which also defines Sim3's
joint (θ, σ) regimes SIM3_REGIMES). The tangent is rounded to the dtype and subnormal
components are
flushed to zero (XLA on CPU flushes subnormals, so the flushed value is what the
function receives): that *stored* tangent is the input of exp and of the derivative
checks. The input of log is the group element whose parameters are the exact exp of the
stored tangent rounded to the dtype (again flushed): a stored element, identical for
every library, not a round trip through any library's exp.

References (mpmath, ``DPS`` = 60 digits, from the stored floats, which convert exactly):
  SO2 exp   (cos θ, sin θ)
  SE2 exp   (cos θ, sin θ, V v),  V = [[A, −B], [B, A]],  A = sin θ/θ,  B = (1 − cos θ)/θ
  SO3 exp   (cos(θ/2), sin(θ/2)/θ · ω),  θ = ‖ω‖ (w < 0 for θ > π, as exp gives it)
  SE3 exp   (q, v + F1 ω×v + F2 ω×(ω×v)),  F1 = (1 − cos θ)/θ²,  F2 = (θ − sin θ)/θ³
  SO2 log   atan2(s, c)
  SE2 log   θ = atan2(s, c),  v = [[h, θ/2], [−θ/2, h]] t,  h = (θ/2) cot(θ/2)
  SO3 log   principal: q ← q/‖q‖, q ← −q if w ≤ 0, θ = 2 atan2(‖q_xyz‖, w), ω = θ q_xyz/‖q_xyz‖
  SE3 log   ω as SO3, v = t − ½ ω×t + G ω×(ω×t),  G = (1 − (θ/2)cot(θ/2))/θ²
  SE23      SE3's exp and log on (ρ, ω) and on (ν, ω): (q, V ρ, V ν), (V⁻¹p, ω, V⁻¹v)
  Sim3 exp  (q, W v, σ),  W = ∫₀¹ e^{τ(ω̂ + σI)} dτ = D0 I + B ω̂ + C ωωᵀ from
            ``sim3_coefficients``: φ(z) = expm1(z)/z at z = σ + iθ, D0 = Re φ,
            B = Im φ/θ, C = (A − D0)/θ², A = (e^σ − 1)/σ (θ = 0: ∫τ e^{στ}, ½∫τ² e^{στ}),
            each at 30 + 3·(decades of θ or |σ| below 1) extra digits
  Sim3 log  ω as SO3, σ as stored, v = W⁻¹ t = t∥/A + (D0 t⊥ − B ω×t)/(D0² + θ²B²)
The stored rotation parameters are normalised in mpmath before the log (the atan2 forms
are scale invariant anyway, so this only fixes the meaning); the translation is used as
stored. F1, F2 and G, whose closed forms cancel catastrophically near 0 (1 − cos θ at 50
digits is pure noise below θ ≈ 1e-25), are evaluated from their exact power series for
θ < 1/4 (rational and Bernoulli coefficients) and from the closed form at 20 extra digits
above. ``check_references`` verifies all of this independently (mpmath.expm of the hat
matrix, series against closed form at high precision, Sim3's coefficients against mp.quad
of their integrals, exp∘log round trips).

Error measure (one for every op): per output block (EXP_BLOCKS: rotation parameters,
translation parameters, SE23 position and velocity, Sim3 translation and log-scale;
LOG_BLOCKS: the translation, rotation, velocity and log-scale parts of the tangent)

    ulp_err = ‖got − ref‖_∞ / (eps · max(1, ‖ref‖_∞)),

eps = finfo(dtype).eps (for the vectors of an exp beyond π, max(1, ‖W‖‖v‖_∞, ‖ref‖_∞) with
v the input vector and ‖W‖ = 1, Sim3 (e^σ − 1)/σ: ``Cases.exp_floor`` says why). Below π
a vector's own size is its natural scale: Sim3's W has singular values A = ‖W‖ along ω and
|φ(σ + iθ)| ≥ (2/π)A across it, so ‖W v‖ is within a factor ~3 of ‖W‖‖v‖. A case's error
is the max over its blocks; a non-finite output is an infinite error. The reference is
kept as a double-double (hi + lo) so the measure itself is exact to far below 0.01 ulp.
Derivative checks: J = d log(exp(x))/dx (jacfwd) must be I and H = d² log(exp(x))/dx²
(jax.hessian) must be 0; the error is max |J − I| / (eps · s) and max |H| / (eps · s),
with s = max(1, ‖v‖₂) on the blocks whose exact derivative pieces scale with the
translation v (output translation differentiated w.r.t. rotation only: ∂v_out/∂ω and
∂²v_out/∂ω∂ω; Sim3 also w.r.t. σ; SE23 each vector on its own norm: ``derivative_scale``),
s = 1 elsewhere. Derivatives are checked only where log is smooth (angle < π, so not in
the beyond_pi and far regimes).
Bounds (``bound``): exp and log 4 ulp, derivatives 8 and 64, except exp beyond π, where
the input's own conditioning allows 4 + |θ|/2 ulp.

Running: ``evaluate`` jits exp (on stored tangents), log (on stored parameters) and
vmap(jacfwd / hessian) of log∘exp for one library, float32 with jax_enable_x64 off (so
no silent promotion can hide float32 rounding), float64 with it on.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import jax
import jax.numpy as jnp
import mpmath as mp  # type: ignore[import-untyped]
import numpy as np

from jaxlie_geo._xla import x64

DPS = 60
GROUPS = ("SO2", "SE2", "SO3", "SE3", "Sim3", "SE23")
DTYPES = ("float32", "float64")
REGIMES = ("zero", "tiny", "small", "mid", "near_pi", "beyond_pi", "far")
# Sim(3)'s joint regimes of the rotation angle θ and the log-scale σ (on top of REGIMES).
SIM3_REGIMES = ("scale_only", "sigma_small", "joint_1e-3", "joint_1e-5", "joint_1e-8", "big_sigma")
ALL_REGIMES = REGIMES + SIM3_REGIMES
SIZES = (0.0, 1e-6, 1.0, 1e3)
OPS = ("exp", "log", "jac", "hess")
# Asserted bounds, in ulp (see module docstring for what is measured); exp's grows beyond π
# (``bound``).
BOUNDS = {"exp": 4.0, "log": 4.0, "jac": 8.0, "hess": 64.0}
# Regimes where the angle exceeds π: exp only (the principal log wraps beyond it).
EXP_ONLY = ("beyond_pi", "far")
# Ops checked in each regime: exp everywhere; log and derivatives only where the angle
# is below π.
OPS_IN_REGIME = {r: (("exp",) if r in EXP_ONLY else OPS) for r in ALL_REGIMES}


def regimes(group: str) -> Tuple[str, ...]:
    """The regimes of ``group``'s grid: REGIMES, and for Sim3 also SIM3_REGIMES."""
    return ALL_REGIMES if group == "Sim3" else REGIMES


def bound(op: str, theta) -> np.ndarray:
    """The asserted bound, in ulp, of ``op`` at rotation angles ``theta`` (any shape).

    BOUNDS[op], except exp beyond π: 4 + |θ|/2 ulp, the conditioning of the problem
    itself. The input ω is a float; moving it by one ulp moves θ by about |θ|·ε and
    the unit quaternion (cos(θ/2), sin(θ/2)·a) by about |θ|/2 ulp, so no kernel that
    receives the rounded θ (or θ²) can promise less."""
    theta = np.abs(np.asarray(theta, np.float64))
    extra = np.where(theta > math.pi, 0.5 * theta, 0.0) if op == "exp" else 0.0 * theta
    return BOUNDS[op] + extra


REGIME_TEXT = {
    "zero": "θ = 0",
    "tiny": "1e-30 ≤ θ ≤ 1e-6",
    "small": "1e-5 ≤ θ ≤ 0.1",
    "mid": "0.1 ≤ θ ≤ 3",
    "near_pi": "π−1e-2 ≤ θ ≤ π−1e-7 (f32: π−2e-6)",
    "beyond_pi": "π ≤ θ ≤ 10π (exp only)",
    "far": "10π ≤ θ ≤ 1e4 (exp only)",
    "scale_only": "θ = 0, 1e-8 ≤ |σ| ≤ 20",
    "sigma_small": "0.1 ≤ θ ≤ 3.1, σ = 0 or 1e-30 ≤ |σ| ≤ 1e-4",
    "joint_1e-3": "θ = 1e-3·√r, |σ| = 1e-3/√r, r = θ/|σ| ∈ [1e-3, 1e3]",
    "joint_1e-5": "θ = 1e-5·√r, |σ| = 1e-5/√r, r = θ/|σ| ∈ [1e-3, 1e3]",
    "joint_1e-8": "θ = 1e-8·√r, |σ| = 1e-8/√r, r = θ/|σ| ∈ [1e-3, 1e3]",
    "big_sigma": "3 ≤ |σ| ≤ 20, 1e-8 ≤ θ ≤ π−1e-3",
}
# The log-scale of Sim3's cases in the common REGIMES: 0 at θ = 0, else this band of |σ|
# (log-uniform, random sign).
SIM3_SIGMA_BAND = (1e-3, 3.0)
# The |z| = (θ² + σ²)^½ scale of each joint regime (θ = σ there at r = 1).
JOINT_SCALE = {"joint_1e-3": 1e-3, "joint_1e-5": 1e-5, "joint_1e-8": 1e-8}

TANGENT_DIM = {"SO2": 1, "SE2": 3, "SO3": 3, "SE3": 6, "Sim3": 7, "SE23": 9}
PARAM_DIM = {"SO2": 2, "SE2": 4, "SO3": 4, "SE3": 7, "Sim3": 8, "SE23": 10}
# Index sets: tangent translation / rotation parts, and output blocks of exp and log.
TAN_V = {
    "SO2": [],
    "SE2": [0, 1],
    "SO3": [],
    "SE3": [0, 1, 2],
    "Sim3": [0, 1, 2],
    "SE23": [0, 1, 2, 6, 7, 8],
}
TAN_W = {
    "SO2": [0],
    "SE2": [2],
    "SO3": [0, 1, 2],
    "SE3": [3, 4, 5],
    "Sim3": [3, 4, 5],
    "SE23": [3, 4, 5],
}
# The tangent's vectors (each moved by exp's V or W): SE23 has two, position and velocity.
TAN_VECS = {
    g: ([[0, 1, 2], [6, 7, 8]] if g == "SE23" else [TAN_V[g]] if TAN_V[g] else []) for g in TAN_V
}
# The tangent coordinates that exp's V or W depend on (rotation; Sim3 also the log-scale σ):
# derivatives of the output vectors with respect to them scale with the vectors' length.
TAN_COUPLED = {g: TAN_W[g] + ([6] if g == "Sim3" else []) for g in TAN_W}
EXP_BLOCKS = {
    "SO2": [[0, 1]],
    "SE2": [[0, 1], [2, 3]],
    "SO3": [[0, 1, 2, 3]],
    "SE3": [[0, 1, 2, 3], [4, 5, 6]],
    "Sim3": [[0, 1, 2, 3], [4, 5, 6], [7]],
    "SE23": [[0, 1, 2, 3], [4, 5, 6], [7, 8, 9]],
}
# exp's output blocks holding a vector (V v or W v), in TAN_VECS order.
EXP_VEC_BLOCKS = {g: list(range(1, 1 + len(TAN_VECS[g]))) for g in TAN_VECS}
LOG_BLOCKS = {
    "SO2": [[0]],
    "SE2": [[0, 1], [2]],
    "SO3": [[0, 1, 2]],
    "SE3": [[0, 1, 2], [3, 4, 5]],
    "Sim3": [[0, 1, 2], [3, 4, 5], [6]],
    "SE23": [[0, 1, 2], [3, 4, 5], [6, 7, 8]],
}
EXP_BLOCK_NAMES = {
    "SO2": ["rot"],
    "SE2": ["rot", "trans"],
    "SO3": ["rot"],
    "SE3": ["rot", "trans"],
    "Sim3": ["rot", "trans", "log-scale"],
    "SE23": ["rot", "pos", "vel"],
}
LOG_BLOCK_NAMES = {
    "SO2": ["ω"],
    "SE2": ["v", "ω"],
    "SO3": ["ω"],
    "SE3": ["v", "ω"],
    "Sim3": ["v", "ω", "σ"],
    "SE23": ["ρ", "ω", "ν"],
}
TANGENT_NAMES = {
    "SO2": ["θ"],
    "SE2": ["vx", "vy", "θ"],
    "SO3": ["ωx", "ωy", "ωz"],
    "SE3": ["vx", "vy", "vz", "ωx", "ωy", "ωz"],
    "Sim3": ["vx", "vy", "vz", "ωx", "ωy", "ωz", "σ"],
    "SE23": ["ρx", "ρy", "ρz", "ωx", "ωy", "ωz", "νx", "νy", "νz"],
}


def angle_band(regime: str, dtype: str) -> Tuple[float, float]:
    """(lo, hi) of the rotation angle θ in a regime (for near_pi: of π − θ)."""
    pi = math.pi
    return {
        "zero": (0.0, 0.0),
        "tiny": (1e-30, 1e-6),
        "small": (1e-5, 0.1),
        "mid": (0.1, 3.0),
        # one float32 step at π is 2.4e-7: stop at π − 2e-6 there.
        "near_pi": (2e-6 if dtype == "float32" else 1e-7, 1e-2),
        "beyond_pi": (pi, 10 * pi),
        "far": (10 * pi, 1e4),
    }[regime]


def flush(x: np.ndarray) -> np.ndarray:
    """What XLA on CPU sees: subnormals flushed to (signed) zero."""
    tiny = np.finfo(x.dtype).tiny
    return np.where(np.abs(x) < tiny, np.zeros_like(x) * np.sign(x), x).astype(x.dtype)


# --- mpmath scalar functions (exact near 0) ----------------------------------------------


def _series(coef, t2, tol) -> mp.mpf:
    s, k, p = mp.mpf(0), 0, mp.mpf(1)
    while True:
        term = coef(k) * p
        s += term
        if k > 2 and abs(term) < tol:
            return s
        k += 1
        p *= t2


_BERN: Dict[int, Any] = {}


def _bern_coef(k: int) -> mp.mpf:  # |B_{2k+2}| / (2k+2)!
    if k not in _BERN:
        _BERN[k] = abs(mp.bernoulli(2 * k + 2)) / mp.factorial(2 * k + 2)
    return _BERN[k]


SERIES_BELOW = mp.mpf("0.25")


def F1(t: mp.mpf, series: bool | None = None) -> mp.mpf:
    """(1 − cos θ)/θ² = Σ (−1)^k θ^{2k}/(2k+2)!"""
    if series if series is not None else t < SERIES_BELOW:
        return _series(lambda k: (-1) ** k / mp.factorial(2 * k + 2), t * t, mp.eps * 1e-5)
    with mp.extradps(20):
        return 2 * mp.sin(t / 2) ** 2 / t**2


def F2(t: mp.mpf, series: bool | None = None) -> mp.mpf:
    """(θ − sin θ)/θ³ = Σ (−1)^k θ^{2k}/(2k+3)!"""
    if series if series is not None else t < SERIES_BELOW:
        return _series(lambda k: (-1) ** k / mp.factorial(2 * k + 3), t * t, mp.eps * 1e-5)
    with mp.extradps(20):
        return (t - mp.sin(t)) / t**3


def G(t: mp.mpf, series: bool | None = None) -> mp.mpf:
    """(1 − (θ/2) cot(θ/2))/θ² = Σ |B_{2k+2}| θ^{2k}/(2k+2)!  (θ < 2π)"""
    if series if series is not None else t < SERIES_BELOW:
        return _series(_bern_coef, t * t, mp.eps * 1e-5)
    with mp.extradps(20):
        return (1 - (t / 2) * mp.cot(t / 2)) / t**2


def _digits_lost(t: mp.mpf) -> int:
    """Decimal digits below 1 of |t| (0 for |t| ≥ 1): how many a cancellation of size t costs."""
    return 0 if t == 0 or abs(t) >= 1 else int(mp.ceil(-mp.log10(abs(t))))


def sim3_coefficients(sigma: mp.mpf, th: mp.mpf) -> Tuple[mp.mpf, mp.mpf, mp.mpf, mp.mpf]:
    """(A, D0, B, C) of Sim(3)'s W = ∫₀¹ e^{τ(ω̂ + σI)} dτ = D0 I + B ω̂ + C ωωᵀ at
    log-scale σ and angle θ = ‖ω‖ ≥ 0:

        A  = ∫ e^{στ} dτ = (e^σ − 1)/σ,            D0 = ∫ e^{στ} cos τθ dτ = Re φ(z),
        B  = ∫ e^{στ} sin τθ/θ dτ = Im φ(z)/θ,     C  = ∫ e^{στ}(1 − cos τθ)/θ² dτ = (A − D0)/θ²,

    φ(z) = (e^z − 1)/z = expm1(z)/z, z = σ + iθ (complex expm1: no cancellation as z → 0).
    B and C then cancel 1 and 2 digits per decade of θ below 1, and the θ = 0 forms
    B = ∫ τ e^{στ} = (e^σ(σ − 1) + 1)/σ², C = ½∫ τ² e^{στ} = (e^σ(σ² − 2σ + 2) − 2)/(2σ³)
    3 per decade of |σ|: each is evaluated at DPS + 30 + that many extra digits, so the
    result keeps more than DPS digits for any θ, σ the floats can hold. At σ = θ = 0:
    (1, 1, 1/2, 1/6). ``check_references`` compares them with mp.quad of the integrals."""
    sigma, th = mp.mpf(sigma), mp.mpf(th)
    extra = 30 + 3 * max(_digits_lost(th), _digits_lost(sigma))
    with mp.extradps(extra):
        A = mp.expm1(sigma) / sigma if sigma != 0 else mp.mpf(1)
        if th == 0:
            if sigma == 0:
                return mp.mpf(1), mp.mpf(1), mp.mpf(1) / 2, mp.mpf(1) / 6
            e = mp.exp(sigma)
            B = (e * (sigma - 1) + 1) / sigma**2
            C = (e * (sigma**2 - 2 * sigma + 2) - 2) / (2 * sigma**3)
            return +A, +A, +B, +C
        z = mp.mpc(sigma, th)
        phi = mp.expm1(z) / z
        D0 = phi.real
        B = phi.imag / th
        C = (A - D0) / th**2
        return +A, +D0, +B, +C


def _sim3_quadrature(sigma: mp.mpf, th: mp.mpf) -> List[mp.mpf]:
    """(A, D0, B, C) by mp.quad of their integrals (for ``check_references``), with
    (1 − cos τθ)/θ² written 2 sin²(τθ/2)/θ², which does not cancel."""

    def integral(f):
        return mp.quad(lambda u: mp.exp(sigma * u) * f(u), [0, 0.5, 1])

    return [
        integral(lambda u: 1),
        integral(lambda u: mp.cos(u * th)),
        integral(lambda u: mp.sin(u * th) / th if th else u),
        integral(lambda u: 2 * (mp.sin(u * th / 2) / th) ** 2 if th else u * u / 2),
    ]


def _sim3_w_apply(sigma, w, v) -> List[mp.mpf]:
    """W v = D0 v + B ω×v + C (ω·v) ω."""
    _, D0, B, C = sim3_coefficients(sigma, _norm(w))
    wxv = _cross(w, v)
    wv = mp.fsum(a * b for a, b in zip(w, v))
    return [D0 * v[i] + B * wxv[i] + C * wv * w[i] for i in range(3)]


def _sim3_w_inverse_apply(sigma, w, t) -> List[mp.mpf]:
    """W⁻¹ t: W acts as A along ω and as the complex number D0 + iθB (a rotation and
    scaling about ω) on the plane across ω, so W⁻¹ t = t∥/A + (D0 t⊥ − B ω×t)/(D0² + θ²B²)."""
    th = _norm(w)
    A, D0, B, _ = sim3_coefficients(sigma, th)
    if th == 0:
        return [c / A for c in t]
    wt = mp.fsum(a * b for a, b in zip(w, t))
    par = [wt / th**2 * c for c in w]
    perp = [a - b for a, b in zip(t, par)]
    wxt = _cross(w, t)
    den = D0**2 + th**2 * B**2
    return [par[i] / A + (D0 * perp[i] - B * wxt[i]) / den for i in range(3)]


def _cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def _mpf_list(x) -> List[mp.mpf]:
    """Stored floats (any numpy float, converted exactly) or mpf values, as mpf."""
    return [c if isinstance(c, mp.mpf) else mp.mpf(float(c)) for c in x]


def _norm(a):
    return mp.sqrt(mp.fsum(x * x for x in a))


def exp_ref(group: str, x: Union[Sequence[float], np.ndarray]) -> List[mp.mpf]:
    """Exact group parameters of exp(x) (x: stored floats)."""
    x = _mpf_list(x)
    if group in ("SO2", "SE2"):
        th = x[-1]
        c, s = mp.cos(th), mp.sin(th)
        if group == "SO2":
            return [c, s]
        A = s / th if th != 0 else mp.mpf(1)
        B = th * F1(abs(th))  # (1 − cos θ)/θ, odd in θ
        vx, vy = x[0], x[1]
        return [c, s, A * vx - B * vy, B * vx + A * vy]
    if group == "SE23":
        pose = exp_ref("SE3", x[:6])
        return pose + exp_ref("SE3", x[6:9] + x[3:6])[4:]
    w = x[3:6] if group == "Sim3" else x[-3:]
    th = _norm(w)
    half_sinc = mp.sin(th / 2) / th if th != 0 else mp.mpf(0.5)
    q = [mp.cos(th / 2)] + [half_sinc * c for c in w]
    if group == "SO3":
        return q
    if group == "Sim3":
        return q + _sim3_w_apply(x[6], w, x[:3]) + [x[6]]
    v = x[:3]
    wxv = _cross(w, v)
    wwxv = _cross(w, wxv)
    f1, f2 = F1(th), F2(th)
    return q + [v[i] + f1 * wxv[i] + f2 * wwxv[i] for i in range(3)]


def log_ref(group: str, p: Sequence[float]) -> List[mp.mpf]:
    """Exact principal log of the element with (stored) parameters p."""
    p = _mpf_list(p)
    if group in ("SO2", "SE2"):
        r = mp.sqrt(p[0] ** 2 + p[1] ** 2)
        c, s = p[0] / r, p[1] / r
        th = mp.atan2(s, c)
        if group == "SO2":
            return [th]
        tx, ty = p[2], p[3]
        half = th / 2
        h = half * mp.cos(half) / mp.sin(half) if th != 0 else mp.mpf(1)
        return [h * tx + half * ty, -half * tx + h * ty, th]
    if group == "SE23":
        return log_ref("SE3", p[:7]) + log_ref("SE3", p[:4] + p[7:10])[:3]
    q = p[:4]
    r = _norm(q)
    q = [c / r for c in q]
    if q[0] <= 0:  # w = 0: −π·axis, as the library and jaxlie
        q = [-c for c in q]
    n = _norm(q[1:])
    if n == 0:
        w = [mp.mpf(0)] * 3
        th = mp.mpf(0)
    else:
        th = 2 * mp.atan2(n, q[0])
        w = [th / n * c for c in q[1:]]
    if group == "SO3":
        return w
    if group == "Sim3":
        return _sim3_w_inverse_apply(p[7], w, p[4:7]) + w + [p[7]]
    t = p[4:]
    wxt = _cross(w, t)
    wwxt = _cross(w, wxt)
    g = G(th)
    return [t[i] - wxt[i] / 2 + g * wwxt[i] for i in range(3)] + w


def compose_ref(group: str, pa: Sequence, pb: Sequence, invert_a: bool = False) -> List[mp.mpf]:
    """Exact parameters of a @ b (``invert_a``: a⁻¹ @ b) for SE2/SE3, from the (stored)
    parameters, rotation parts taken as their normalized directions."""
    pa, pb = _mpf_list(pa), _mpf_list(pb)
    k = 2 if group == "SE2" else 4
    qa = [c / _norm(pa[:k]) for c in pa[:k]]
    qb = [c / _norm(pb[:k]) for c in pb[:k]]
    R = params_to_matrix("SO2" if k == 2 else "SO3", qa)
    ta, tb = pa[k:], pb[k:]
    if invert_a:
        qa = [qa[0]] + [-c for c in qa[1:]]
        R = R.T
        tb = [y - x for x, y in zip(ta, tb)]
        ta = [mp.mpf(0)] * len(ta)
    if k == 2:
        q = [qa[0] * qb[0] - qa[1] * qb[1], qa[0] * qb[1] + qa[1] * qb[0]]
    else:
        (w1, x1, y1, z1), (w2, x2, y2, z2) = qa, qb
        q = [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ]
    t = [mp.fsum(R[i, j] * tb[j] for j in range(len(tb))) + ta[i] for i in range(len(tb))]
    return q + t


def hat(group: str, x: Union[Sequence, np.ndarray]) -> mp.matrix:
    """Lie algebra matrix of a tangent (jaxlie ordering: translation first; Sim3
    [[ω̂ + σI, v], [0, 0]], SE23 [[ω̂, ρ, ν], [0, 0, 0], [0, 0, 0]])."""
    x = _mpf_list(x)
    if group == "SO2":
        return mp.matrix([[0, -x[0]], [x[0], 0]])
    if group == "SE2":
        return mp.matrix([[0, -x[2], x[0]], [x[2], 0, x[1]], [0, 0, 0]])
    w = x[3:6] if group in ("Sim3", "SE23") else x[-3:]
    S = mp.matrix([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
    if group == "SO3":
        return S
    M = mp.zeros(5 if group == "SE23" else 4)
    for i in range(3):
        for j in range(3):
            M[i, j] = S[i, j]
        M[i, 3] = x[i]
        if group == "SE23":
            M[i, 4] = x[6 + i]
        if group == "Sim3":
            M[i, i] += x[6]
    return M


def params_to_matrix(group: str, p: Sequence) -> mp.matrix:
    """Homogeneous matrix of a parameter vector (mpf entries, quaternion assumed unit)."""
    if group in ("SO2", "SE2"):
        c, s = p[0], p[1]
        if group == "SO2":
            return mp.matrix([[c, -s], [s, c]])
        return mp.matrix([[c, -s, p[2]], [s, c, p[3]], [0, 0, 1]])
    w, x, y, z = p[:4]
    R = mp.matrix(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )
    if group == "SO3":
        return R
    M = mp.eye(5 if group == "SE23" else 4)
    scale = mp.exp(p[7]) if group == "Sim3" else 1
    for i in range(3):
        for j in range(3):
            M[i, j] = scale * R[i, j]
        M[i, 3] = p[4 + i]
        if group == "SE23":
            M[i, 4] = p[7 + i]
    return M


def _maxabs(M: mp.matrix) -> mp.mpf:
    return max(abs(M[i, j]) for i in range(M.rows) for j in range(M.cols))


def check_references(verbose: bool = False) -> float:
    """Independent checks of the references; returns the worst relative discrepancy
    (should be ~1e-45 or below). Raises AssertionError on failure."""
    worst = mp.mpf(0)
    rng = np.random.default_rng(12345)
    with mp.workdps(DPS):
        # 1. series and closed forms agree where both are accurate (closed form at +60 digits).
        for t in [mp.mpf("0.05"), mp.mpf("0.2"), mp.mpf("0.3"), mp.mpf(1), mp.mpf(3)]:
            for f in (F1, F2, G):
                a = f(t, series=True)
                with mp.extradps(60):
                    b = f(t, series=False)
                worst = max(worst, abs(a - b) / abs(b))
        # 2. exp against mpmath.expm of the hat matrix.
        angles = [0.0, 1e-30, 1e-12, 1e-6, 1e-3, 0.2, 1.0, 3.0, math.pi - 1e-7, 5.0, 31.0]
        # Sim3's log-scale, one per angle: 0, tiny, joint with θ, large of both signs.
        sigmas = [0.0, 1e-25, -1e-12, 3e-6, -2e-3, 0.7, -3.0, 20.0, -20.0, 2.5, -0.4]
        for g in GROUPS:
            for th, sg in zip(angles, sigmas):
                x = _random_tangent(g, th, 1.3, rng, sigma=sg)
                ref = params_to_matrix(g, exp_ref(g, x))
                with mp.extradps(40):
                    E = mp.expm(hat(g, x), method="taylor")
                scale = max(1, _maxabs(E))
                worst = max(worst, _maxabs(ref - E) / scale)
                # 3. log inverts exp on the principal range (exact parameters in, tangent out).
                if th < math.pi:
                    with mp.extradps(20):
                        p = exp_ref(g, x)
                    back = log_ref(g, p)
                    xs = [mp.mpf(float(c)) for c in x]
                    scale = max(1, max(abs(c) for c in xs))
                    worst = max(worst, max(abs(a - b) for a, b in zip(back, xs)) / scale)
        # 4. Sim3's coefficients against mp.quad of their integrals (at DPS + 20 digits).
        for sg, th in [
            (0, 0),
            (1e-20, 0),
            (-3e-9, 0),
            (0, 1e-20),
            (1e-8, 3e-8),
            (-1e-5, 1e-5),
            (2e-30, 1e-27),
            (-1e-3, 1e-6),
            (1e-3, 1.0),
            (-20, 0.5),
            (20, 3.1),
            (20, 1e-8),
            (-20, 1e-8),
            (2.5, 2.0),
            (0.3, 0.2),
            (-0.7, 10.0),
            (0, math.pi),
            (1.5, 6.2),
        ]:
            got = sim3_coefficients(mp.mpf(sg), mp.mpf(th))
            with mp.extradps(20):
                want = _sim3_quadrature(mp.mpf(sg), mp.mpf(th))
            for a, b in zip(got, want):
                worst = max(worst, abs(a - b) / abs(b))
        # 5. log of a quaternion at exactly π (−π times the stored axis), and of a
        # non-unit quaternion.
        p = log_ref("SO3", [0.0, 0.75, 0.0, -1.0])  # |(0.75, 0, -1)| = 1.25 exactly
        worst = max(worst, abs(p[0] + 3 * mp.pi / 5) + abs(p[2] - 4 * mp.pi / 5))
        c, s = math.cos(0.5), math.sin(0.5)
        p = log_ref("SO3", [-2.0 * c, -2.0 * s, 0.0, 0.0])  # scaled, w < 0
        worst = max(worst, abs(p[0] - 2 * mp.atan2(s, c)))
    if verbose:
        print(f"reference self-check: worst discrepancy {float(worst):.3g}")
    assert worst < mp.mpf(10) ** (-40), f"references disagree: {worst}"
    return float(worst)


# --- inputs --------------------------------------------------------------------------------


def _unit(rng, n):
    u = rng.standard_normal(n)
    return u / np.linalg.norm(u)


def _random_tangent(group, theta, size, rng, sigma=0.0, size2=None) -> np.ndarray:
    """A tangent (float64) with rotation angle theta and translation norm size (SE23: the
    position part; the velocity part has norm size2, default size; Sim3: log-scale sigma)."""
    if group in ("SO2", "SE2"):
        w = np.array([theta * (1.0 if rng.random() < 0.5 else -1.0)])
    else:
        w = theta * _unit(rng, 3)
    if group in ("SO2", "SO3"):
        return w
    v = size * _unit(rng, 2 if group == "SE2" else 3)
    if group == "Sim3":
        return np.concatenate([v, w, [sigma]])
    if group == "SE23":
        nu = (size if size2 is None else size2) * _unit(rng, 3)
        return np.concatenate([v, w, nu])
    return np.concatenate([v, w])


def _loguniform(lo, hi, n, rng, ends=(0.0, 1.0), exact_ends=False) -> np.ndarray:
    """n draws log-uniform in [lo, hi], the first ones at the fractions ``ends`` of the band
    (with exact_ends, the fractions 0 and 1 give lo and hi exactly, not through exp∘log)."""
    u = np.concatenate([ends, rng.random(max(n - len(ends), 0))])[:n]
    a = np.exp(np.log(lo) + u * (np.log(hi) - np.log(lo)))
    if exact_ends:
        k = len(ends)
        a[:k] = np.where(u[:k] == 0.0, lo, np.where(u[:k] == 1.0, hi, a[:k]))
    return a


def _angles(regime, dtype, n, rng) -> np.ndarray:
    lo, hi = angle_band(regime, dtype)
    if regime == "zero":
        return np.zeros(n)
    a = _loguniform(lo, hi, n, rng)
    if regime == "beyond_pi":
        # A quarter of the draws sit within 1e-3 of 2πk, k = 1..4, where sin(θ/2) → 0 makes
        # the SE(3) translation much shorter than v and cancellations show (random draws
        # rarely land there).
        m = n // 4
        k = rng.integers(1, 5, m)
        a[2 : 2 + m] = 2 * math.pi * k + rng.uniform(-1e-3, 1e-3, m)
    return math.pi - a if regime == "near_pi" else a


def _signs(n) -> np.ndarray:
    """+, +, −, −, +, −, +, −, … (both signs at both ends of a band first)."""
    return np.array([1.0, 1.0, -1.0, -1.0] + [(-1.0) ** k for k in range(max(n - 4, 0))])[:n]


def _angles_sigmas(group, regime, dtype, n, rng) -> Tuple[np.ndarray, np.ndarray]:
    """Nominal rotation angles and log-scales (0 but for Sim3) of one regime's draws.

    Sim3, common REGIMES: σ = 0 at θ = 0 (pure translations), elsewhere |σ| log-uniform in
    SIM3_SIGMA_BAND with a random sign. Its own regimes:
      scale_only   θ = 0, |σ| log-uniform in [1e-8, 20], both signs at both ends;
      sigma_small  θ log-uniform in [0.1, 3.1]; σ = 0 for the first two, then |σ| log-uniform
                   in [1e-30, 1e-4], alternating signs;
      joint_<r>    θ = r√ρ, |σ| = r/√ρ for ρ = θ/|σ| on a log grid of 2⌊n/4⌋ + 1 points from
                   1e-3 to 1e3 (ρ = 1 included: θ = |σ| = r), each with σ > 0 and σ < 0;
      big_sigma    |σ| ∈ {3, 20} × θ ∈ {1e-8, π − 1e-3} × both signs first, then |σ|
                   log-uniform in [3, 20] and θ in [1e-8, π − 1e-3], alternating signs."""
    if group != "Sim3" or regime in REGIMES:
        angles = _angles(regime, dtype, n, rng)
        if group != "Sim3" or regime == "zero":
            return angles, np.zeros(len(angles))
        sign = np.where(rng.random(n) < 0.5, 1.0, -1.0)
        return angles, sign * _loguniform(*SIM3_SIGMA_BAND, n, rng, exact_ends=True)
    if regime == "scale_only":
        mag = _loguniform(1e-8, 20.0, n, rng, ends=(0.0, 1.0, 0.0, 1.0), exact_ends=True)
        return np.zeros(n), _signs(n) * mag
    if regime == "sigma_small":
        th = _loguniform(0.1, 3.1, n, rng, exact_ends=True)
        mag = _loguniform(1e-30, 1e-4, n, rng, exact_ends=True)
        mag[:2] = 0.0
        return th, np.array([(-1.0) ** k for k in range(n)]) * mag + 0.0  # +0.0, not −0.0
    if regime in JOINT_SCALE:
        r = JOINT_SCALE[regime]
        ratio = np.logspace(-3.0, 3.0, 2 * (n // 4) + 1)
        th = np.repeat(r * np.sqrt(ratio), 2)
        sg = np.tile([1.0, -1.0], len(ratio)) * np.repeat(r / np.sqrt(ratio), 2)
        return th, sg
    if regime == "big_sigma":
        th_lo, th_hi = 1e-8, math.pi - 1e-3
        th = _loguniform(th_lo, th_hi, n, rng, ends=(0.0, 0.0, 1.0, 1.0) * 2, exact_ends=True)
        mag = _loguniform(3.0, 20.0, n, rng, ends=(0.0, 1.0) * 4, exact_ends=True)
        sg = np.concatenate([[1.0] * 4 + [-1.0] * 4, _signs(max(n - 8, 0))])[:n]
        return th, sg * mag
    raise ValueError(regime)


def _dd(values: Sequence[Sequence[mp.mpf]]) -> Tuple[np.ndarray, np.ndarray]:
    """Double-double (hi, lo) float64 arrays of mpf rows."""
    hi = np.array([[float(v) for v in row] for row in values], dtype=np.float64)
    lo = np.array(
        [[float(v - h) for v, h in zip(row, hrow)] for row, hrow in zip(values, hi)],
        dtype=np.float64,
    )
    return hi, lo


@dataclasses.dataclass
class Cases:
    """All inputs and references of one (group, dtype)."""

    group: str
    dtype: str
    regime: np.ndarray  # (N,) str
    size: np.ndarray  # (N,) nominal translation norm
    angle: np.ndarray  # (N,) nominal rotation angle
    tangent: np.ndarray  # (N, tangent_dim) stored (dtype, flushed): exp / derivative input
    params: np.ndarray  # (N, parameters_dim) stored exact-exp(tangent): log input
    exp_hi: np.ndarray
    exp_lo: np.ndarray
    log_hi: np.ndarray
    log_lo: np.ndarray
    vnorm: np.ndarray  # (N, n_vecs) ‖·‖₂ of each of the stored tangent's vectors (TAN_VECS)

    def mask(self, op: str) -> np.ndarray:
        return np.array([op in OPS_IN_REGIME[r] for r in self.regime])

    @property
    def theta(self) -> np.ndarray:
        """(N,) rotation angle of the stored tangent."""
        w = self.tangent[:, TAN_W[self.group]].astype(np.float64)
        return np.sqrt(np.sum(w * w, axis=-1))

    @property
    def sigma(self) -> np.ndarray:
        """(N,) log-scale of the stored tangent (Sim3; 0 for the other groups)."""
        if self.group != "Sim3":
            return np.zeros(len(self.regime))
        return self.tangent[:, 6].astype(np.float64)

    def bound(self, op: str) -> np.ndarray:
        """(N,) the asserted bound of ``op`` at each case (``bound``), except Sim3's: the
        Jacobian bound plus |σ|/16 (see below), and the log within 1e-2 of π: 5 ulp. There
        v = W⁻¹t is assembled from D0, B, C (each within an ulp) in about a dozen
        roundings, and the worst case measured is 4.7 ulp in float64 (θ = π − 2e-7,
        σ = 0.042, |v| = 1); SE3's log stays within 4 there through its (θ/2)cot(θ/2)
        form, which has no Sim(3) counterpart here yet."""
        out = bound(op, self.theta)
        if self.group == "Sim3" and op == "log":
            out = np.where(self.theta > math.pi - 1e-2, np.maximum(out, 5.0), out)
        if self.group == "Sim3" and op == "jac":
            # e^σ and the products with σ in the derivative family round σ: allowance of
            # |σ|/16 ulp at large |σ| (kept from the quadrature the family replaced).
            out = out + np.abs(self.sigma) / 16.0
        return out

    def exp_floor(self) -> np.ndarray:
        """(N, n_blocks) smallest error scale of each exp output block: 1, except the
        vectors of an exp beyond π (translation; SE23's position and velocity), each
        measured on max(1, ‖W‖‖v‖_∞) of its input v, where ‖W‖ = 1 (V of SE2, SE3, SE23)
        or A = (e^σ − 1)/σ (Sim3's W = ∫₀¹ e^{τσ} R(τω) dτ has norm ∫ e^{τσ} dτ). There
        t = W v is much shorter than ‖W‖‖v‖ near θ = 2πk, but one ulp of ω moves θ by
        about |θ|·ε and t by about ε‖W‖‖v‖ (dW/dθ has norm ~‖W‖/θ there), so t is only
        determined to ε‖W‖‖v‖ by its input."""
        floor = np.ones((len(self.regime), len(EXP_BLOCKS[self.group])))
        beyond = np.isin(self.regime, EXP_ONLY)
        sg = self.sigma
        with np.errstate(invalid="ignore", divide="ignore"):
            norm_w = np.where(sg == 0, 1.0, np.expm1(sg) / np.where(sg == 0, 1.0, sg))
        for vec, blk in zip(TAN_VECS[self.group], EXP_VEC_BLOCKS[self.group]):
            v = np.max(np.abs(self.tangent[:, vec].astype(np.float64)), axis=-1)
            floor[:, blk] = np.where(beyond, np.maximum(1.0, norm_w * v), 1.0)
        return floor


def make_cases(group: str, dtype: str, n_per: int = 16, seed: int = 0) -> Cases:
    """Every regime of ``regimes(group)`` × translation norm SIZES (groups with one) ×
    n_per draws (regime "zero": n_per/4; Sim3's joint regimes: 2(2⌊n_per/4⌋ + 1)). SE23's
    velocity norm cycles through SIZES over a cell's draws (its position norm is the
    cell's), so every cell holds pure positions, pure velocities and both."""
    dt = np.dtype(dtype)
    rng = np.random.default_rng([seed, GROUPS.index(group), DTYPES.index(dtype)])
    sizes = SIZES if TAN_V[group] else (0.0,)
    regime, size, angle, tangents = [], [], [], []
    for r in regimes(group):
        for s in sizes:
            n = n_per if r != "zero" else max(2, n_per // 4)
            ths, sgs = _angles_sigmas(group, r, dtype, n, rng)
            for k, (th, sg) in enumerate(zip(ths, sgs)):
                size2 = SIZES[k % len(SIZES)] if group == "SE23" else None
                tangents.append(_random_tangent(group, th, s, rng, sigma=sg, size2=size2))
                regime.append(r)
                size.append(s)
                angle.append(th)
    tangent = flush(np.array(tangents).astype(dt))
    with mp.workdps(DPS):
        exps = [exp_ref(group, x) for x in tangent]
        params = flush(np.array([[float(c) for c in e] for e in exps]).astype(dt))
        logs = [
            log_ref(group, p) if rg not in EXP_ONLY else [mp.mpf(0)] * len(x)
            for p, rg, x in zip(params, regime, tangent)
        ]
        exp_hi, exp_lo = _dd(exps)
        log_hi, log_lo = _dd(logs)
    vnorm = np.zeros((len(tangent), max(1, len(TAN_VECS[group]))))
    for i, vec in enumerate(TAN_VECS[group]):
        tv = tangent[:, vec].astype(np.float64)
        vnorm[:, i] = np.sqrt(np.sum(tv * tv, axis=-1))
    return Cases(
        group,
        dtype,
        np.array(regime),
        np.array(size),
        np.array(angle),
        tangent,
        params,
        exp_hi,
        exp_lo,
        log_hi,
        log_lo,
        vnorm,
    )


# --- error measure ---------------------------------------------------------------------------


def ulp_errors(got, ref_hi, ref_lo, blocks, dtype, per_block=False, floor=None):
    """Per case: max over blocks of ‖got − ref‖_∞ / (eps · max(floor, ‖ref‖_∞)), shape (N,),
    floor 1 unless given per case and block, ``(N, n_blocks)``; with per_block, also the
    (N, n_blocks) errors of the blocks."""
    eps = float(np.finfo(dtype).eps)
    got = np.asarray(got, dtype=np.float64)
    with np.errstate(invalid="ignore", over="ignore"):
        d = np.abs((got - ref_hi) - ref_lo)
    d = np.where(np.isfinite(got), d, np.inf)
    each = np.stack(
        [
            np.max(d[:, b], axis=-1) / (eps * np.maximum(fl, np.max(np.abs(ref_hi[:, b]), axis=-1)))
            for b, fl in zip(blocks, np.ones((len(d), len(blocks))).T if floor is None else floor.T)
        ],
        axis=-1,
    )
    out = np.max(each, axis=-1)
    return (out, each) if per_block else out


def derivative_scale(group: str, vnorm: np.ndarray, order: int) -> np.ndarray:
    """s per entry of J (order 1, (N, n, n)) or H (order 2, (N, n, n, n)): max(1, ‖v‖₂) on
    the entries of an output vector v (TAN_VECS) differentiated only with respect to the
    coordinates its V or W depends on (TAN_COUPLED: ω, and Sim3's σ), 1 elsewhere.
    ``vnorm``: (N,) or (N, n_vecs), the norm of each input vector."""
    n = TANGENT_DIM[group]
    vnorm = np.asarray(vnorm, np.float64)
    vnorm = vnorm[:, None] if vnorm.ndim == 1 else vnorm
    s = np.ones((len(vnorm),) + (n,) * (order + 1))
    C = TAN_COUPLED[group]
    for b, vec in enumerate(TAN_VECS[group]):
        big = np.maximum(1.0, vnorm[:, b])
        for i in vec:
            for j in C:
                if order == 1:
                    s[:, i, j] = big
                else:
                    for k in C:
                        s[:, i, j, k] = big
    return s


def derivative_errors(got, group, vnorm, order, dtype, with_argmax=False):
    """max |J − I| / (eps s) (order 1) or max |H| / (eps s) (order 2), per case; with
    with_argmax, also the flat index of the worst entry."""
    eps = float(np.finfo(dtype).eps)
    got = np.asarray(got, dtype=np.float64)
    n = TANGENT_DIM[group]
    ref = np.eye(n) if order == 1 else np.zeros((n, n, n))
    with np.errstate(invalid="ignore", over="ignore"):
        d = np.abs(got - ref)
    d = np.where(np.isfinite(got), d, np.inf) / (eps * derivative_scale(group, vnorm, order))
    d = d.reshape(d.shape[0], -1)
    out = np.max(d, axis=-1)
    return (out, np.argmax(d, axis=-1)) if with_argmax else out


# --- running a library -----------------------------------------------------------------------


@contextlib.contextmanager
def x64_for(dtype: str):
    """float32 runs with x64 off (what a float32 user has: no silent promotion can hide
    float32 rounding), float64 with x64 on."""
    with x64(dtype == "float64"):
        yield


_FN_CACHE: Dict[Tuple, object] = {}


def _functions(lib, group: str, dtype: str):
    key = (lib.__name__, group, dtype)
    if key not in _FN_CACHE:
        G = getattr(lib, group)

        def roundtrip(x):
            return G.exp(x).log()

        _FN_CACHE[key] = {
            "exp": jax.jit(lambda x: G.exp(x).parameters()),
            "log": jax.jit(lambda p: G(p).log()),
            "jac": jax.jit(jax.vmap(jax.jacfwd(roundtrip))),
            "hess": jax.jit(jax.vmap(jax.hessian(roundtrip))),
        }
    return _FN_CACHE[key]


def evaluate(lib, cases: Cases, ops: Sequence[str] = OPS) -> Dict[str, Any]:
    """Per-case ulp errors of `lib` (a module with SO2/SE2/SO3/SE3) for each op, NaN
    where an op is not checked in the case's regime; also '<op>_dtype' (the output
    dtype), '<op>_blocks' (exp/log: per-block errors) and '<op>_argmax' (jac/hess: flat
    index of the worst entry)."""
    g, dt = cases.group, cases.dtype
    out: Dict[str, Any] = {}
    with x64_for(dt):
        fns = _functions(lib, g, dt)
        for op in ops:
            m = cases.mask(op)
            err = np.full(len(m), np.nan)
            arg = cases.params[m] if op == "log" else cases.tangent[m]
            got = fns[op](jnp.asarray(arg))
            out[op + "_dtype"] = str(got.dtype)
            got = np.asarray(got)
            if op in ("exp", "log"):
                hi, lo = (
                    (cases.exp_hi, cases.exp_lo) if op == "exp" else (cases.log_hi, cases.log_lo)
                )
                blocks = EXP_BLOCKS[g] if op == "exp" else LOG_BLOCKS[g]
                floor = cases.exp_floor()[m] if op == "exp" else None
                e, each = ulp_errors(got, hi[m], lo[m], blocks, dt, per_block=True, floor=floor)
                extra = np.full((len(m), len(blocks)), np.nan)
                extra[m] = each
                out[op + "_blocks"] = extra
            else:
                e, where = derivative_errors(
                    got, g, cases.vnorm[m], 1 if op == "jac" else 2, dt, with_argmax=True
                )
                argmax = np.zeros(len(m), dtype=np.int64)
                argmax[m] = where
                out[op + "_argmax"] = argmax
            err[m] = e
            out[op] = err
    return out


def worst_by_regime(cases: Cases, errors: np.ndarray) -> Dict[str, Tuple[float, int]]:
    """regime -> (worst error, case index) over the cases where the op was checked."""
    res = {}
    for r in regimes(cases.group):
        idx = np.nonzero((cases.regime == r) & ~np.isnan(errors))[0]
        if len(idx):
            e = np.where(np.isnan(errors[idx]), -1, errors[idx])
            k = idx[int(np.argmax(e))]
            res[r] = (float(errors[k]), int(k))
    return res


def block_errors(cases: Cases, k: int, op: str, errors: Dict[str, np.ndarray]) -> str:
    """Where case k's error sits: per-block errors (exp, log) or the worst entry (jac, hess)."""
    g = cases.group
    if op in ("exp", "log"):
        names = EXP_BLOCK_NAMES[g] if op == "exp" else LOG_BLOCK_NAMES[g]
        b = errors[op + "_blocks"][k]
        return "(" + ", ".join(f"{n} {fmt_ulp(float(e))}" for n, e in zip(names, b)) + ")"
    n = TANGENT_DIM[g]
    idx = np.unravel_index(int(errors[op + "_argmax"][k]), (n,) * (2 if op == "jac" else 3))
    c = TANGENT_NAMES[g]
    if op == "jac":
        return f"(at d{c[idx[0]]}/d{c[idx[1]]})"
    return f"(at d²{c[idx[0]]}/d{c[idx[1]]}d{c[idx[2]]})"


def describe_case(cases: Cases, k: int, op: str) -> str:
    x = cases.params[k] if op == "log" else cases.tangent[k]
    vals = ", ".join(f"{float(c):.17g}" for c in x)
    what = "params" if op == "log" else "tangent"
    sg = f" σ={cases.sigma[k]:.6g}" if cases.group == "Sim3" else ""
    return f"angle≈{cases.angle[k]:.6g}{sg} |v|={cases.size[k]:g} {what}=[{vals}]"


def fmt_ulp(e: Optional[float]) -> str:
    """An error in ulp as the accuracy tables print it: "–" for none, 3 significant digits."""
    if e is None or (isinstance(e, float) and math.isnan(e)):
        return "–"
    if not math.isfinite(e):
        return "non-finite"
    if e < 10:
        return f"{e:.2f}"
    if e < 1000:
        return f"{e:.0f}"
    return f"{e:.1e}"
