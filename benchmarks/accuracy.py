#!/usr/bin/env python
"""Accuracy benchmark: worst error in ulp of exp, log and the derivatives of log∘exp,
jaxlie_geo next to jaxlie 1.5, against mpmath references.

The measurement is the one tests/test_accuracy.py asserts (shared code: tests/_mpref.py):
per output block, ulp_err = ‖got − ref‖_∞ / (eps · max(1, ‖ref‖_∞)), the reference computed
in mpmath at 60 digits from the float each function actually received (subnormals flushed,
as XLA on CPU does). log's input is a stored group element (the exact exp of the stored
tangent, rounded to the dtype), its reference the principal log of exactly that element.
"d/dx" is max |d log(exp(x))/dx − I| and "d²/dx²" max |d² log(exp(x))/dx²| in ulp, the
∂v/∂ω (and ∂²v/∂ω²) entries divided by max(1, ‖v‖); derivatives are checked only below π.
Both libraries get the same inputs: for every group × dtype × angle regime × translation
norm {0, 1e-6, 1, 1e3} (SE groups), --samples random draws with a fixed seed (the band's
end points included). float32 runs with jax_enable_x64 off, float64 with it on.

With --save the worst errors replace raw/<machine>/accuracy.json and the results page
(RESULTS.md) is regenerated (report.py).

Usage:
  python benchmarks/accuracy.py                 # two markdown tables (float32, float64)
  python benchmarks/accuracy.py --save          # ... saved to raw/<machine>/, page regenerated
  python benchmarks/accuracy.py --long          # one row per (group, op, dtype, regime)
  python benchmarks/accuracy.py --worst         # also list the worst input of each failing cell
  python benchmarks/accuracy.py --samples 16 --groups SE3 --json out.json
"""

from __future__ import annotations

import argparse
import importlib.metadata
import json
import os
import platform
import sys
import time

import numpy as np

_REPO_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(_REPO_ROOT, "tests"))  # the shared harness, _mpref
if os.path.exists(os.path.join(_REPO_ROOT, "jaxlie_geo", "__init__.py")):
    sys.path.insert(0, _REPO_ROOT)  # measure the checkout's jaxlie_geo

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import _mpref as M  # noqa: E402
import run as _run  # noqa: E402  (benchmarks/run.py: machine_info)
from report import add_save_arguments, save  # noqa: E402

OP_TEXT = {"exp": "exp", "log": "log", "jac": "d/dx", "hess": "d²/dx²"}
REGIME_HEAD = {
    "zero": "θ = 0",
    "tiny": "1e-30…1e-6",
    "small": "1e-5…0.1",
    "mid": "0.1…3",
    "near_pi": "π−1e-2…π−1e-7 ¹",
    "beyond_pi": "π…10π ²",
    "far": "10π…1e4 ²",
}
NOTES = [
    "¹ float32: π−1e-2…π−2e-6 (one float32 step at π is 2.4e-7).",
    "² exp only. Bound 4 + |θ|/2 ulp, the error one ulp of the input ω already causes (19.7 "
    "at 10π, 5004 at 1e4), checked per case; the translation on the scale max(1, ‖v‖∞, ‖t‖∞).",
    "θ is the rotation angle; each regime is crossed with |v| ∈ {0, 1e-6, 1, 1e3} for SE2 and SE3.",
]


def _version(name: str) -> str:
    try:
        return importlib.metadata.version(name)
    except importlib.metadata.PackageNotFoundError:
        return "?"


def _cell(value, over) -> str:
    if value is None:
        return "–"
    text = M.fmt_ulp(value)
    return f"**{text}**" if over else text


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--samples", type=int, default=64, help="draws per (regime, |v|) cell")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--groups", default=",".join(M.GROUPS))
    ap.add_argument("--dtypes", default=",".join(M.DTYPES))
    ap.add_argument("--long", action="store_true", help="one row per (group, op, dtype, regime)")
    ap.add_argument("--worst", action="store_true", help="print the worst input of failing cells")
    ap.add_argument("--no-jaxlie", action="store_true")
    ap.add_argument("--json", help="write all worst errors (and their inputs) here")
    add_save_arguments(ap)
    args = ap.parse_args()
    groups = [g for g in args.groups.split(",") if g]
    dtypes = [d for d in args.dtypes.split(",") if d]

    import jaxlie_geo

    libs = {"jaxlie_geo": jaxlie_geo}
    if not args.no_jaxlie:
        try:
            import jaxlie

            libs["jaxlie"] = jaxlie
        except ImportError:
            print("jaxlie not installed: reporting jaxlie_geo only", file=sys.stderr)

    t0 = time.perf_counter()
    M.check_references()
    # worst[(lib, group, op, dtype, regime)] = (ulp, case description, where, over its bound)
    worst = {}
    for g in groups:
        for dt in dtypes:
            cases = M.make_cases(g, dt, n_per=args.samples, seed=args.seed)
            for name, lib in libs.items():
                res = M.evaluate(lib, cases)
                for op in M.OPS:
                    over = ~(res[op] <= cases.bound(op)) & cases.mask(op)
                    for r, (e, k) in M.worst_by_regime(cases, res[op]).items():
                        worst[(name, g, op, dt, r)] = (
                            e,
                            M.describe_case(cases, k, op),
                            M.block_errors(cases, k, op, res),
                            bool(np.any(over[cases.regime == r])),
                        )
            print(f"  {g} {dt}: {len(cases.regime)} inputs", file=sys.stderr)
    elapsed = time.perf_counter() - t0

    names = list(libs)
    print(
        f"Worst error in ulp, {' / '.join(names)} "
        f"(jaxlie_geo {_version('jaxlie_geo')}, jaxlie {_version('jaxlie')}, "
        f"jax {jax.__version__}, {platform.machine()}, backend {jax.default_backend()} "
        f"({jax.devices()[0].device_kind}), {args.samples} samples per "
        f"regime and |v|, {elapsed:.0f} s). Bounds: exp, log {M.BOUNDS['exp']:g}; "
        f"d/dx {M.BOUNDS['jac']:g}; d²/dx² {M.BOUNDS['hess']:g}; "
        f"**bold** = a case over its bound.\n"
    )

    def get(name, g, op, dt, r):
        v = worst.get((name, g, op, dt, r))
        return (None, False) if v is None else (v[0], v[3])

    if args.long:
        head = " | ".join(names)
        print(f"| group | op | dtype | regime | {head} |")
        print("|---|---|---|---|" + "---|" * len(names))
        for g in groups:
            for op in M.OPS:
                for dt in dtypes:
                    for r in M.REGIMES:
                        if op not in M.OPS_IN_REGIME[r]:
                            continue
                        cells = " | ".join(_cell(*get(n, g, op, dt, r)) for n in names)
                        print(f"| {g} | {OP_TEXT[op]} | {dt} | {M.REGIME_TEXT[r]} | {cells} |")
    else:
        for dt in dtypes:
            print(f"**{dt}** (cells: {' / '.join(names)})\n")
            print("| group | op | " + " | ".join(REGIME_HEAD[r] for r in M.REGIMES) + " |")
            print("|---|---|" + "---|" * len(M.REGIMES))
            for g in groups:
                for op in M.OPS:
                    cells = []
                    for r in M.REGIMES:
                        if op not in M.OPS_IN_REGIME[r]:
                            cells.append("")
                            continue
                        cells.append(" / ".join(_cell(*get(n, g, op, dt, r)) for n in names))
                    print(f"| {g} | {OP_TEXT[op]} | " + " | ".join(cells) + " |")
            print()
        print(NOTES[0])
    print(NOTES[1])

    if args.worst:
        print("\nWorst inputs of the cells over the bound:\n")
        for (name, g, op, dt, r), (e, desc, where, over) in worst.items():
            if over:
                print(f"- {name} {g}.{OP_TEXT[op]} {dt} {r}: {M.fmt_ulp(e)} ulp {where} {desc}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(
                [
                    {
                        "lib": n,
                        "group": g,
                        "op": op,
                        "dtype": dt,
                        "regime": r,
                        "ulp": e,
                        "where": where,
                        "input": desc,
                    }
                    for (n, g, op, dt, r), (e, desc, where, _) in worst.items()
                ],
                f,
                indent=1,
            )
    if args.save:
        info = _run.machine_info("benchmarks/accuracy.py")
        cells = [
            {"lib": n, "group": g, "op": op, "dtype": dt, "regime": r, "ulp": e, "over": over}
            for (n, g, op, dt, r), (e, _, _, over) in worst.items()
            if op in M.OPS_IN_REGIME[r]
        ]
        data = {
            "machine": info,
            "samples": args.samples,
            "libs": names,
            "bounds": M.BOUNDS,
            "ops": OP_TEXT,
            "regimes": [{"key": r, "label": REGIME_HEAD[r]} for r in M.REGIMES],
            "notes": NOTES,
            "cells": cells,
            "elapsed_s": elapsed,
        }
        save("accuracy", data, args)
    return 0


if __name__ == "__main__":
    sys.exit(main())
