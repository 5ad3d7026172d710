"""Worst error in ulp of exp, log and the derivatives of log∘exp, jaxlie_geo beside jaxlie
1.5, against mpmath; the measurement ``tests/test_accuracy.py`` asserts (``mpref.py`` holds
the references, the regimes and the measure). Sim3 also gets its joint (θ, σ) regimes and a
comparison of its exp translation with the textbook closed form of W
(``textbook_sim3_coefficients``). The method is on the results page (``methods.md``).

Usage:
  python -m benchmarks.accuracy [--save]        # Markdown tables (float32, float64, Sim3)
  python -m benchmarks.accuracy --worst         # also the worst input of each failing cell
  python -m benchmarks.accuracy --samples 16 --groups SE3 --json out.json
"""

from __future__ import annotations

import sys
import time

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import jaxlie  # noqa: E402
import mpmath as mp  # noqa: E402

import jaxlie_geo  # noqa: E402
from benchmarks import common  # noqa: E402
from benchmarks import mpref as M  # noqa: E402
from benchmarks.report import accuracy_table, save  # noqa: E402
from jaxlie_geo import _scalar_sim3  # noqa: E402

OP_TEXT = {"exp": "exp", "log": "log", "jac": "d/dx", "hess": "d²/dx²"}
REGIME_HEAD = {
    "zero": "θ = 0",
    "tiny": "1e-30…1e-6",
    "small": "1e-5…0.1",
    "mid": "0.1…3",
    "near_pi": "π−1e-2…π−1e-7 ¹",
    "beyond_pi": "π…10π ²",
    "far": "10π…1e4 ²",
    "scale_only": "θ = 0, σ ≠ 0",
    "sigma_small": "σ → 0",
    "joint_1e-3": "θ, σ ~ 1e-3",
    "joint_1e-5": "θ, σ ~ 1e-5",
    "joint_1e-8": "θ, σ ~ 1e-8",
    "big_sigma": "3 ≤ \\|σ\\| ≤ 20",
}
NOTES = [
    "¹ float32: π−1e-2…π−2e-6 (one float32 step at π is 2.4e-7).",
    "² exp only. Bound 4 + |θ|/2 ulp, the error one ulp of the input ω already causes (19.7 "
    "at 10π, 5004 at 1e4), checked per case; the translation on the scale max(1, ‖W‖‖v‖∞, "
    "‖t‖∞), ‖W‖ = 1 but for Sim3 ((e^σ − 1)/σ).",
    "θ is the rotation angle; each regime is crossed with |v| ∈ {0, 1e-6, 1, 1e3} for SE2, SE3, "
    "Sim3 and SE23 (SE23: the position; the velocity norm cycles through the same four). Sim3's "
    "log-scale: σ = 0 at θ = 0, 1e-3 ≤ |σ| ≤ 3 (random sign) elsewhere.",
]
SIM3_NOTES = [
    "θ = 0, σ ≠ 0: 1e-8 ≤ |σ| ≤ 20. σ → 0: σ = 0 or 1e-30 ≤ |σ| ≤ 1e-4 at 0.1 ≤ θ ≤ 3.1. "
    "θ, σ ~ r: θ = r√ρ, |σ| = r/√ρ for θ/|σ| = ρ on a log grid from 1e-3 to 1e3 (ρ = 1: "
    "θ = |σ| = r), each with σ > 0 and σ < 0. 3 ≤ |σ| ≤ 20: 1e-8 ≤ θ ≤ π − 1e-3, both signs, "
    "the corners (θ, |σ|) ∈ {1e-8, π − 1e-3} × {3, 20} included. Each crossed with "
    "|v| ∈ {0, 1e-6, 1, 1e3}.",
]

# -- the textbook closed form of Sim(3)'s W ---------------------------------------------
#
# W = ∫₀¹ e^{τ(ω̂ + σI)} dτ = A I + B ω̂ + C ω̂², θ = ‖ω‖, in the form the common C++
# implementations evaluate it (Sophus's Sim3 among them): the closed forms as they stand,
#
#     A = (e^σ − 1)/σ,
#     B = (σ e^σ sin θ + θ (1 − e^σ cos θ)) / (θ (σ² + θ²)),
#     C = (A − (σ (e^σ cos θ − 1) + θ e^σ sin θ)/(σ² + θ²)) / θ²,
#
# with a special case only where a denominator vanishes on its own: |σ| < ε (SE(3)'s
# A = 1, B = (1 − cos θ)/θ², C = (θ − sin θ)/θ³), θ < ε (the σ-only limits
# B = ((σ − 1)e^σ + 1)/σ², C = (e^σ(σ²/2 − σ + 1) − 1)/σ³), or both (1, 1/2, 1/6).
# ε = 1e-10 in float64 and 1e-5 in float32, the thresholds those libraries use. Written
# here from the mathematics; (A, B, C) relate to jaxlie_geo's (D0, B, C) of
# W = D0 I + B ω̂ + C ωωᵀ by ω̂² = ωωᵀ − θ² I: the same B and C, D0 = A − θ² C.

TEXTBOOK_EPS = {"float32": 1e-5, "float64": 1e-10}


def textbook_sim3_coefficients(sigma, theta, dtype: str, eps: float | None = None):
    """(A, B, C) of W = A I + B ω̂ + C ω̂² by the closed forms above, in numpy, every
    operation in ``dtype`` (arrays of one shape)."""
    dt = np.dtype(dtype)
    s = np.asarray(sigma, dt)
    th = np.asarray(theta, dt)
    eps = dt.type(TEXTBOOK_EPS[dtype] if eps is None else eps)
    one, half = dt.type(1), dt.type(0.5)
    with np.errstate(all="ignore"):
        e = np.exp(s)
        A = (e - one) / s
        th2, s2 = th * th, s * s
        a, b, c = e * np.sin(th), e * np.cos(th), th2 + s2
        B_gen = (a * s + (one - b) * th) / (th * c)
        C_gen = (A - ((b - one) * s + a * th) / c) / th2
        B_se3 = (one - np.cos(th)) / th2
        C_se3 = (th - np.sin(th)) / (th2 * th)
        B_sig = ((s - one) * e + one) / s2
        C_sig = (e * (half * s2 - s + one) - one) / (s2 * s)
    small_s, small_t = np.abs(s) < eps, th < eps
    A = np.where(small_s, one, A)
    B = np.where(
        small_s,
        np.where(small_t, half, B_se3),
        np.where(small_t, B_sig, B_gen),
    )
    C = np.where(
        small_s,
        np.where(small_t, dt.type(1.0 / 6.0), C_se3),
        np.where(small_t, C_sig, C_gen),
    )
    return A.astype(dt), B.astype(dt), C.astype(dt)


def textbook_sim3_translation(tangent, dtype: str, eps: float | None = None) -> np.ndarray:
    """t = W v of Sim3 tangents (v, ω, σ), ``(N, 7)``, with W = A I + B ω̂ + C ω̂² formed as a
    matrix from ``textbook_sim3_coefficients``, all in ``dtype``."""
    dt = np.dtype(dtype)
    x = np.asarray(tangent, dt)
    v, w, sigma = x[:, :3], x[:, 3:6], x[:, 6]
    theta = np.sqrt(np.sum(w * w, axis=-1))
    A, B, C = textbook_sim3_coefficients(sigma, theta, dtype, eps)
    z = np.zeros_like(w[:, 0])
    rows = [[z, -w[:, 2], w[:, 1]], [w[:, 2], z, -w[:, 0]], [-w[:, 1], w[:, 0], z]]
    Om = np.stack([np.stack(r, -1) for r in rows], -2)
    W = (
        A[:, None, None] * np.eye(3, dtype=dt)
        + B[:, None, None] * Om
        + C[:, None, None] * (Om @ Om)
    )
    return np.matmul(W, v[:, :, None])[:, :, 0].astype(dt)


# Rows of the comparison: (label, case selector).
def _comparison_rows():
    def reg(*names):
        return lambda c: np.isin(c.regime, names)

    def ratio_one(name):
        def sel(c):
            with np.errstate(divide="ignore", invalid="ignore"):
                r = c.theta / np.abs(c.sigma)
            return (c.regime == name) & (np.abs(r - 1.0) < 1e-3)

        return sel

    rows = [("θ = σ = 0 (pure translation)", reg("zero"))]
    for name in M.JOINT_SCALE:
        r = name.split("_")[1]  # "1e-3"
        rows.append((f"θ = \\|σ\\| = {r}", ratio_one(name)))
        rows.append((f"θ = {r}·√ρ, \\|σ\\| = {r}/√ρ, ρ = θ/\\|σ\\| ∈ [1e-3, 1e3]", reg(name)))
    rows += [
        ("σ → 0: σ = 0 or 1e-30…1e-4, θ 0.1…3.1", reg("sigma_small")),
        ("θ = 0, 1e-8 ≤ \\|σ\\| ≤ 20", reg("scale_only")),
        ("θ → 0: 1e-30…1e-6, 1e-3 ≤ \\|σ\\| ≤ 3", reg("tiny")),
        ("θ 1e-5…0.1, 1e-3 ≤ \\|σ\\| ≤ 3", reg("small")),
        ("θ 0.1…3, 1e-3 ≤ \\|σ\\| ≤ 3", reg("mid")),
        ("θ near π (π−1e-2…π−1e-7 ¹), 1e-3 ≤ \\|σ\\| ≤ 3", reg("near_pi")),
        ("3 ≤ \\|σ\\| ≤ 20, θ 1e-8…π−1e-3", reg("big_sigma")),
        ("\\|σ\\| = 20 (θ = 0, 1e-8, π−1e-3, …)", lambda c: np.abs(c.sigma) == 20.0),
    ]
    return rows


def sim3_comparison(samples: int, seed: int, sim3_runs=None) -> list:
    """Markdown lines: worst ulp of Sim3's exp translation, jaxlie_geo vs the textbook closed
    form, per row of ``_comparison_rows`` and dtype; then B and C at θ = σ → 0.
    ``sim3_runs``: {dtype: (cases, jaxlie_geo's evaluate result)} to reuse."""
    per_dtype = {}
    for dt in M.DTYPES:
        if sim3_runs and dt in sim3_runs:
            cases, res = sim3_runs[dt]
        else:
            cases = M.make_cases("Sim3", dt, n_per=samples, seed=seed)
            res = M.evaluate(jaxlie_geo, cases, ops=("exp",))
        ours = res["exp_blocks"][:, 1]
        got = textbook_sim3_translation(cases.tangent, dt)
        floor = cases.exp_floor()[:, [1]]
        theirs = M.ulp_errors(
            got, cases.exp_hi[:, 4:7], cases.exp_lo[:, 4:7], [[0, 1, 2]], dt, floor=floor
        )
        per_dtype[dt] = (cases, ours, theirs)
    lines = [
        "| inputs | ours float32 | closed form float32 | ours float64 | closed form float64 |",
        "|---|--:|--:|--:|--:|",
    ]
    for label, sel in _comparison_rows():
        cells = []
        for dt in M.DTYPES:
            cases, ours, theirs = per_dtype[dt]
            m = sel(cases)
            for e in (ours, theirs):
                bad = np.any(~(e[m] <= M.BOUNDS["exp"]))
                text = M.fmt_ulp(float(np.max(e[m]))) if m.any() else "–"
                cells.append(f"**{text}**" if bad else text)
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    lines += ["", *coefficient_lines()]
    return lines


def _sci(x: float) -> str:
    """1e-05 -> "1e-5", -1e-05 -> "−1e-5"."""
    return f"{x:.0e}".replace("e-0", "e-").replace("-", "−", 1 if x < 0 else 0)


def coefficient_lines() -> list:
    """Markdown lines: B and C (W = A I + B ω̂ + C ω̂²) at θ = |σ| = r from mpmath, and the
    relative errors of jaxlie_geo's ``_scalar_sim3.sim3_coefficients`` and of the textbook closed
    form there."""
    rows = [("float64", 1e-5), ("float64", 1e-6), ("float32", 1e-3), ("float32", 1e-4)]
    lines = [
        "| dtype | θ | σ | B | B: ours | B: closed form | C | C: ours | C: closed form |",
        "|---|--:|--:|--:|--:|--:|--:|--:|--:|",
    ]
    for dt, r in rows:
        for sigma in (r, -r):
            th, sg = np.dtype(dt).type(r), np.dtype(dt).type(sigma)
            with mp.workdps(M.DPS):
                _, _, b_ref, c_ref = M.sim3_coefficients(mp.mpf(float(sg)), mp.mpf(float(th)))
            with M.x64_for(dt):
                _, _, b_ours, c_ours = _scalar_sim3.sim3_coefficients(
                    jnp.asarray(sg), jnp.asarray(th) * jnp.asarray(th)
                )
            _, b_cf, c_cf = textbook_sim3_coefficients(sg, th, dt)

            def rel(got, ref):
                return f"{float(abs((mp.mpf(float(got)) - ref) / ref)):.1e}"

            lines.append(
                f"| {dt} | {_sci(r)} | {_sci(sigma)} | {float(b_ref):.6f} | {rel(b_ours, b_ref)} | "
                f"{rel(b_cf, b_ref)} | {float(c_ref):.6f} | {rel(c_ours, c_ref)} | "
                f"{rel(c_cf, c_ref)} |"
            )
    return lines


def _cell(value, over) -> str:
    if value is None:
        return "–"
    text = M.fmt_ulp(value)
    return f"**{text}**" if over else text


def sim3_regime_table(worst: dict, dtypes) -> list:
    """Markdown lines: jaxlie_geo's worst Sim3 errors in its own regimes, rows (op, dtype)."""
    lines = [
        "| op | dtype | " + " | ".join(REGIME_HEAD[r] for r in M.SIM3_REGIMES) + " |",
        "|---|---|" + "--:|" * len(M.SIM3_REGIMES),
    ]
    for op in M.OPS:
        for dt in dtypes:
            cells = []
            for r in M.SIM3_REGIMES:
                v = worst.get(("jaxlie_geo", "Sim3", op, dt, r))
                cells.append("–" if v is None else _cell(v[0], v[3]))
            lines.append(f"| {OP_TEXT[op]} | {dt} | " + " | ".join(cells) + " |")
    return lines


def main(argv=None) -> int:
    p = common.parser(__doc__, groups=M.GROUPS, dtypes=M.DTYPES)
    p.add_argument("--samples", type=int, default=64, help="draws per (regime, |v|) cell")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--worst", action="store_true", help="print the worst input of failing cells")
    p.add_argument("--no-jaxlie", action="store_true")
    args = common.parse(p, argv)
    groups, dtypes = args.groups, args.dtypes

    libs = (
        {"jaxlie_geo": jaxlie_geo}
        if args.no_jaxlie
        else {"jaxlie_geo": jaxlie_geo, "jaxlie": jaxlie}
    )

    t0 = time.perf_counter()
    M.check_references()
    # worst[(lib, group, op, dtype, regime)] = (ulp, case description, where, over its bound)
    worst = {}
    sim3_runs = {}  # dtype -> (cases, jaxlie_geo's result), for the closed-form comparison
    for g in groups:
        for dt in dtypes:
            cases = M.make_cases(g, dt, n_per=args.samples, seed=args.seed)
            for name, lib in libs.items():
                if not hasattr(lib, g):
                    continue
                res = M.evaluate(lib, cases)
                if g == "Sim3" and name == "jaxlie_geo":
                    sim3_runs[dt] = (cases, res)
                for op in M.OPS:
                    over = ~(res[op] <= cases.bound(op)) & cases.mask(op)
                    for r, (e, k) in M.worst_by_regime(cases, res[op]).items():
                        where = M.block_errors(cases, k, op, res)
                        bad = bool(np.any(over[cases.regime == r]))
                        worst[(name, g, op, dt, r)] = (e, M.describe_case(cases, k, op), where, bad)
            print(f"  {g} {dt}: {len(cases.regime)} inputs", file=sys.stderr)
    elapsed = time.perf_counter() - t0

    names = list(libs)

    sections = []
    if "Sim3" in groups:
        title = "Sim(3), joint (θ, σ) regimes (jaxlie_geo)"
        sections.append(
            {"title": title, "lines": sim3_regime_table(worst, dtypes) + [""] + SIM3_NOTES}
        )
        if set(dtypes) == set(M.DTYPES):
            title = "Sim(3) exp translation: jaxlie_geo vs the textbook closed form"
            sections.append(
                {"title": title, "lines": sim3_comparison(args.samples, args.seed, sim3_runs)}
            )
    if args.worst:
        print("\nWorst inputs of the cells over the bound:\n")
        for (name, g, op, dt, r), (e, desc, where, over) in worst.items():
            if over:
                print(f"- {name} {g}.{OP_TEXT[op]} {dt} {r}: {M.fmt_ulp(e)} ulp {where} {desc}")
    cells = [
        {"lib": n, "group": g, "op": op, "dtype": dt, "regime": r, "ulp": e, "over": over}
        for (n, g, op, dt, r), (e, _, _, over) in worst.items()
        if op in M.OPS_IN_REGIME[r]
    ]
    data = {
        "machine": common.machine_info("benchmarks.accuracy"),
        "samples": args.samples,
        "libs": names,
        "bounds": M.BOUNDS,
        "ops": OP_TEXT,
        "groups": groups,
        "regimes": [{"key": r, "label": REGIME_HEAD[r]} for r in M.REGIMES],
        "notes": NOTES,
        "sections": sections,
        "cells": cells,
        "elapsed_s": elapsed,
    }
    print("\n".join(accuracy_table(data)))
    print(f"{elapsed:.0f} s")
    save("accuracy", data, args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
