#!/usr/bin/env python
"""Render ``benchmarks/RESULTS.md`` and ``benchmarks/results.png`` from the raw results.

The raw results are JSON files, one per machine and table::

    benchmarks/raw/<machine>/speed-float32.json      run.py --save
    benchmarks/raw/<machine>/speed-float64.json      run.py --dtype float64 --save
    benchmarks/raw/<machine>/jacobians-float32.json  jacobians.py --save
    benchmarks/raw/<machine>/accuracy.json           accuracy.py --save
    benchmarks/raw/<machine>/extended-groups-<dtype>.json
                                                     extended_groups.py --save
    benchmarks/raw/<machine>/splines-<dtype>.json   splines.py --save
    benchmarks/raw/<machine>/pose-graphs.json       pose_graphs.py --save
    benchmarks/raw/<machine>/spline-fit.json        spline_fit.py --save
    benchmarks/raw/<machine>/baseline-speed-<dtype>.json
                                                     run.py --json of an earlier commit,
                                                     with a "change" entry: the page shows
                                                     it beside today's run, before/after

Each benchmark script, given ``--save``, replaces its file for the machine it runs on and
calls ``write_page``; ``python benchmarks/report.py`` re-renders the page alone. The page
depends on the raw files only (no clock, no environment), so rendering twice gives the same
bytes; ``--check`` exits with status 1 when the committed page is out of date.

Usage:
  python benchmarks/report.py                  # raw/ -> RESULTS.md and results.png
  python benchmarks/report.py --check          # is RESULTS.md what raw/ renders to?
  python benchmarks/report.py --raw-dir /tmp/raw --page /tmp/RESULTS.md
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
from pathlib import Path

from jaxlie_geo._mpref import fmt_ulp

HERE = Path(__file__).resolve().parent
RAW_DIR = HERE / "raw"
PAGE = HERE / "RESULTS.md"
PLOT_NAME = "results.png"
POSE_GRAPH_PLOT = "pose_graphs.png"

GROUPS = ("SO2", "SE2", "SO3", "SE3")
OPS = ("exp", "log", "compose", "apply", "inverse", "interpolate", "grad")
SUPERSCRIPT = str.maketrans("0123456789-", "⁰¹²³⁴⁵⁶⁷⁸⁹⁻")


# --------------------------------------------------------------------------------------
# Formatting (shared with run.py)
# --------------------------------------------------------------------------------------


def fmt_ns(x: float) -> str:
    """A time in ns with its unit, three significant digits."""
    if x >= 1e6:
        return f"{x / 1e6:.2f} ms"
    if x >= 1e3:
        return f"{x / 1e3:.2f} µs"
    if x >= 100:
        return f"{x:.0f} ns"
    if x >= 10:
        return f"{x:.1f} ns"
    if x >= 1:
        return f"{x:.2f} ns"
    return f"{x:.3g} ns"  # a GPU at 10^6: 0.1 ns/element needs three significant digits


def fmt_n(n: int) -> str:
    """A batch size as ``10^k`` when it is a power of ten from 1000 up."""
    e = math.log10(n) if n > 0 else 0
    if n >= 1000 and abs(e - round(e)) < 1e-9:
        return f"10^{int(round(e))}"
    return str(n)


def pretty_n(n: int) -> str:
    """``fmt_n`` with a superscript exponent (10³)."""
    text = fmt_n(n)
    if "^" in text:
        base, exp = text.split("^")
        return base + exp.translate(SUPERSCRIPT)
    return text


def geomean(xs) -> float:
    xs = [x for x in xs if x > 0]
    return math.exp(sum(math.log(x) for x in xs) / len(xs)) if xs else float("nan")


def table(header, rows, align) -> list:
    """Markdown table lines; ``align`` is one of "l"/"r" per column."""
    out = [
        "| " + " | ".join(header) + " |",
        "|" + "|".join("---" if a == "l" else "--:" for a in align) + "|",
    ]
    return out + ["| " + " | ".join(r) + " |" for r in rows]


# --------------------------------------------------------------------------------------
# Raw files
# --------------------------------------------------------------------------------------


def _slug(text: str) -> str:
    text = re.sub(r"\((r|tm)\)", "", text.lower())
    text = re.sub(r"\b(processor|cpu)\b|@.*$", "", text)
    return re.sub(r"[^a-z0-9]+", "-", text).strip("-")


def machine_name(info: dict) -> str:
    """A stable name for the machine of a run: ``cpu-<model>-<k>core``, or
    ``cpu-<model>-<k>of<n>core`` for a run pinned to k of n cores, or ``gpu-<device kind>``."""
    if info.get("backend", "cpu") != "cpu":
        return f"{info['backend']}-{_slug(info.get('device_kind', 'unknown'))}"
    used, total = info.get("cores_usable", "?"), info.get("cores", "?")
    cores = f"{used}core" if used == total else f"{used}of{total}core"
    return f"cpu-{_slug(info.get('cpu', 'unknown'))}-{cores}"


def add_save_arguments(p: argparse.ArgumentParser) -> None:
    """``--save`` and the options that say where it writes."""
    p.add_argument(
        "--save",
        action="store_true",
        help="write the results to raw/<machine>/ and regenerate RESULTS.md and its plot",
    )
    p.add_argument(
        "--machine",
        default=None,
        help="machine name for --save (default: derived from the CPU or GPU model)",
    )
    p.add_argument(
        "--note",
        default=None,
        help="free text about the machine shown on the results page (default: the "
        "note already saved for the machine)",
    )
    p.add_argument(
        "--raw-dir", type=Path, default=RAW_DIR, help="raw results folder (default: %(default)s)"
    )
    p.add_argument(
        "--page",
        type=Path,
        default=PAGE,
        help="results page to regenerate (default: %(default)s); the plot goes beside it",
    )


def save(kind: str, data: dict, args) -> Path:
    """Write ``data`` to ``<raw-dir>/<machine>/<kind>.json`` and regenerate the page."""
    machine = args.machine or machine_name(data["machine"])
    path = Path(args.raw_dir) / machine / f"{kind}.json"
    note = args.note
    if note is None:
        note = next((m.get("note") for m in _machines_in(path.parent) if m.get("note")), None)
    if note:
        data["machine"]["note"] = note
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
    print(f"wrote {path}")
    write_page(Path(args.raw_dir), Path(args.page))
    return path


def _read(path: Path) -> dict:
    return json.loads(path.read_text(encoding="utf-8"))


def _machines_in(folder: Path) -> list:
    return [_read(f)["machine"] for f in sorted(folder.glob("*.json"))]


def load(raw_dir: Path) -> dict:
    """{machine: {kind: data}} for every raw file."""
    raw: dict = {}
    for path in sorted(raw_dir.glob("*/*.json")):
        raw.setdefault(path.parent.name, {})[path.stem] = _read(path)
    return raw


def _date(info: dict) -> str:
    return info.get("date", "?").split()[0]


def _factorisation(info: dict) -> str:
    """The pose-graph run's sparse factorisation and its package's version."""
    solver = info.get("linear_solver", "QDLDL")
    if solver.startswith("CHOLMOD"):
        return f"CHOLMOD through cvxopt {info.get('cvxopt', '?')}"
    return f"QDLDL (qdldl {info.get('qdldl', '?')})"


def _commit(info: dict) -> str:
    """The commit a run measured, and the files that differed from it if the tree had
    uncommitted changes (``run.py`` records them as ``dirty_files``)."""
    commit = info.get("commit", "?")
    if not commit.endswith("-dirty"):
        return commit
    files = info.get("dirty_files")
    changed = ", ".join(f"`{f}`" for f in files) if files else "files not recorded"
    return f"{commit[: -len('-dirty')]} with uncommitted changes ({changed})"


def machine_order(raw: dict) -> list:
    """CPUs before GPUs; among each, the machine with the newest speed run first."""

    def newest(m):
        return max(
            [d["machine"].get("date", "") for k, d in raw[m].items() if k.startswith("speed")]
            or [""]
        )

    def gpu(m):
        return any(d["machine"].get("backend", "cpu") != "cpu" for d in raw[m].values())

    order = sorted(raw)
    order.sort(key=newest, reverse=True)
    order.sort(key=gpu)
    return order


def _cpu_name(info: dict) -> str:
    cpu = re.sub(r"\((R|TM)\)|\bProcessor\b|\bCPU\b", "", info.get("cpu", "CPU"))
    return re.sub(r"\s+", " ", cpu).strip()


def label(info: dict) -> str:
    """Short human name of a machine: CPU model and cores, or the GPU model."""
    if info.get("backend", "cpu") != "cpu":
        return info.get("device_kind", info["backend"].upper())
    used, total = info.get("cores_usable"), info.get("cores")
    cores = f"{used} cores" if used == total else f"{used} of {total} cores"
    return f"{_cpu_name(info)}, {cores}"


def _os(info: dict) -> str:
    """``Linux-6.1-...-x86_64-with-glibc2.36`` -> ``Linux x86_64, glibc 2.36``."""
    text = info.get("platform", "")
    m = re.match(r"(\w+)-.*?-(x86_64|aarch64|arm64|AMD64)(?:-with-(\D+)([\d.]+))?", text)
    if not m:
        return text
    return f"{m[1]} {m[2]}" + (f", {m[3]} {m[4]}" if m[3] else "")


def _n_at(n: int) -> str:
    return "N = 1" if n == 1 else pretty_n(n)


# --------------------------------------------------------------------------------------
# Page
# --------------------------------------------------------------------------------------

INTRO = """\
<!-- Generated by benchmarks/report.py from benchmarks/raw/*/*.json; do not edit by hand. -->

# Benchmark results: jaxlie_geo against jaxlie 1.5

Measured by the scripts in this folder ([how they run](README.md)); each one, run with
`--save`, replaces its raw file under `raw/<machine>/` and regenerates this page and its
plot. Speed-up = jaxlie's time / jaxlie_geo's time: above 1, jaxlie_geo is faster.
"""

METHOD = """\
## Method

**Speed** (`run.py`). Both libraries run in one process on identical inputs, each operation
under `jax.jit`. Rotation angles are uniform in (0, 2.8) rad for exp, log, apply and inverse,
and in (0, 1.5) rad for the operations on two elements (so that relative rotations stay below
π); translations are standard normal. Repetitions are interleaved (jaxlie_geo then jaxlie,
then jaxlie then jaxlie_geo, ...); each lasts about 10 ms and every call blocks until its
result is ready. A time is the median time per call divided by the batch size N, so at N = 1
it is the latency of one call. The speed-up is the median of the per-repetition ratios, and
its inter-quartile range (IQR, in brackets) is the noise gauge: an A/A run of jaxlie against
itself (`run.py --candidate jaxlie`) gave 0.94–1.07, so differences under about 10% are noise.
**Bold**: jaxlie_geo slower, with the whole IQR below 1. Compile time is one trace + lower +
XLA compile of each jitted function.

| op | timed expression |
|---|---|
| exp | `G.exp(xi)` |
| log | `T.log()` (T precomputed) |
| compose | `a @ b` |
| apply | `T @ points` |
| inverse | `T.inverse()` |
| interpolate | jaxlie_geo `a.interpolate(b, t)`; jaxlie `a @ G.exp(t * (a.inverse() @ b).log())` |
| grad | `jax.grad` of Σ‖log(exp(ξ)⁻¹ b)‖² with respect to ξ |

`run.py` also compares the two libraries' outputs (quaternion sign aligned) and lists the
cases that differ by more than 1e-3 (float32) or 1e-8 (float64) relative, ten times that for
gradients. Each such case checked against float64 and mpmath references was jaxlie's error:
its small-angle branches, at small relative rotations with long translations (SE2 and SE3).

**Memory**: XLA's buffer assignment of each compiled SE3 operation at N = 2²² (compiled, not
run): arguments, output and temporaries. **Eager latency**: `SE3.exp` of one tangent called
without a user `jit` (both libraries wrap their public methods in `jax.jit`).

**Jacobians** (`jacobians.py`): every closed-form Jacobian that depends on its input, against
`jax.vmap(jax.jacfwd(f))` of the map it is the Jacobian of, both jitted and timed as above;
speed-up = jacfwd's time / the closed form's. Every case is also checked against jacfwd in
float64 (agreement to 1e-9).

**Accuracy** (`accuracy.py`): worst error in ulp per output block, ‖got − ref‖∞ / (eps ·
max(1, ‖ref‖∞)), against mpmath at 60 digits, on the same inputs for both libraries. d/dx and
d²/dx² are the first and second derivatives of log(exp(x)), checked below π. Bounds: 4 ulp for
exp and log, 8 for d/dx, 64 for d²/dx², and 4 + |θ|/2 ulp for exp beyond π (the input's own
conditioning); `tests/test_accuracy.py` asserts them.

**Compatibility**: jaxlie 1.5's own test suite, from the jaxlie 1.5.0 source distribution,
passes against jaxlie_geo, 398 of 398 tests (`jaxlie_suite.py`; its docstring lists what it
leaves out). jaxlie_geo's test suite passes from jax 0.5.3 (with numpy 1.25.2 and with 2.4.6)
up.

Where jaxlie_geo is slower, the reasons are measured in the design notes: at 10³ elements on
two CPU cores, XLA:CPU splits jaxlie_geo's larger fusions over both threads
([threads at small batches](../docs/design/threads-at-small-batches.md)); SO3 grad and SE3
grad compile slower, mostly in tracing ([compile time](../docs/design/compile-time.md)).
"""


def _speed_cell(r: dict) -> str:
    text = f"{r['ratio']:.2f} [{r['ratio_q1']:.2f}–{r['ratio_q3']:.2f}]"
    return f"**{text}**" if _slower(r) else text


def _slower(r: dict) -> bool:
    return r["ratio"] < 0.95 and r["ratio_q3"] < 1.0


def _tolerance(r: dict) -> float:
    tol = 1e-3 if r.get("dtype") == "float32" else 1e-8
    return 10 * tol if r["op"] == "grad" else tol


def summary_section(raw: dict, order: list) -> list:
    rows = []
    for m in order:
        for dtype in ("float32", "float64"):
            data = raw[m].get(f"speed-{dtype}")
            if data is None:
                continue
            res = data["results"]
            sizes = sorted({r["n"] for r in res})
            cells = {n: f"{geomean([r['ratio'] for r in res if r['n'] == n]):.2f}" for n in sizes}
            rows.append((label(data["machine"]), dtype, cells, _date(data["machine"])))
    if not rows:
        return []
    sizes = sorted({n for _, _, cells, _ in rows for n in cells})
    header = ["machine", "dtype"] + [f"N = {pretty_n(n)}" for n in sizes] + ["measured"]
    body = [[name, dt] + [c.get(n, "") for n in sizes] + [d] for name, dt, c, d in rows]
    lines = ["Speed-up over jaxlie, geometric mean over the groups and operations measured:", ""]
    return lines + table(header, body, "ll" + "r" * len(sizes) + "l") + [""]


def machines_section(raw: dict, order: list) -> list:
    lines = ["## Machines", ""]
    body = []
    for m in order:
        infos = {k: d["machine"] for k, d in sorted(raw[m].items())}
        info = infos.get("speed-float32") or next(iter(infos.values()))
        hw = label(info)
        if info.get("backend", "cpu") != "cpu":
            hw += f"; host {_cpu_name(info)}, {info.get('cores')} cores"
        if info.get("note"):
            hw += f". {info['note']}"
        soft = []
        for key in ("python", "jax", "jaxlib", "numpy", "jaxlie"):
            values = sorted({i.get(key) for i in infos.values() if i.get(key)})
            if values:
                soft.append(f"{'Python' if key == 'python' else key} {' / '.join(values)}")
        soft.append(_os(info))
        runs = ", ".join(f"{_kind_text(k)} {_date(i)}" for k, i in infos.items())
        body.append([f"`{m}`", hw, ", ".join(soft), runs])
    return lines + table(["machine", "hardware", "software", "runs"], body, "llll") + [""]


def _kind_text(kind: str) -> str:
    """``speed-float32`` -> ``speed (float32)``, ``extended-groups-float32`` -> ``extended
    groups (float32)``."""
    name, _, dtype = kind.rpartition("-")
    if dtype not in ("float32", "float64"):
        return kind
    return f"{name.replace('-', ' ')} ({dtype})"


def speed_section(raw: dict, order: list) -> list:
    lines = ["## Speed against jaxlie", ""]
    for m in order:
        for dtype in ("float32", "float64"):
            data = raw[m].get(f"speed-{dtype}")
            if data is not None:
                lines += _speed_table(data)
    return lines


def _speed_table(data: dict) -> list:
    info, res = data["machine"], data["results"]
    dtype = info.get("dtype", res[0].get("dtype", "?"))
    sizes = sorted({r["n"] for r in res})
    top = sizes[-1]
    by_case = {(r["group"], r["op"], r["n"]): r for r in res}
    cases = [(g, o) for g in GROUPS for o in OPS if any((g, o, n) in by_case for n in sizes)]
    header, align = ["group", "op"], "ll"
    for n in sizes:
        if n == 1:
            header.append("N = 1")
            align += "r"
        else:
            header += [f"{pretty_n(n)}: {side}" for side in ("jaxlie_geo", "jaxlie", "speed-up")]
            align += "rrr"
    header.append(f"compile ms at {pretty_n(top)}, jaxlie_geo / jaxlie")
    align += "r"
    body = []
    for g, o in cases:
        row = [g, o]
        for n in sizes:
            r = by_case.get((g, o, n))
            if n == 1:
                row.append(_speed_cell(r) if r else "")
            elif r:
                row += [fmt_ns(r["geo_ns_per_elem"]), fmt_ns(r["ref_ns_per_elem"]), _speed_cell(r)]
            else:
                row += ["", "", ""]
        r = by_case.get((g, o, top))
        row.append(f"{r['compile_geo_ms']:.0f} / {r['compile_ref_ms']:.0f}" if r else "")
        body.append(row)

    single = "; the N = 1 column is the speed-up of a single call" if 1 in sizes else ""
    lines = [
        f"### {label(info)}, {dtype}",
        "",
        f"jax {info.get('jax', '?')}, measured {_date(info)}. Times per element{single}.",
        "",
    ]
    lines += table(header, body, align) + [""]
    lines += [f"- {note}" for note in _speed_notes(data)] + [""]
    memory = data.get("memory")
    if memory:
        lines += [
            f"Memory of the compiled SE3 operations at N = {pretty_n_pow2(memory[0]['n'])}, "
            f"{dtype}, MB:",
            "",
        ]
        header = ["op", "arguments", "output", "temporaries: jaxlie_geo", "temporaries: jaxlie"]
        lines += table(header, memory_rows(memory), "lrrrr") + [""]
    return lines


def memory_rows(memory: list) -> list:
    """The memory table's rows: op, arguments, output and both libraries' temporaries (MB)."""
    return [
        [
            r["op"],
            f"{r['geo_args_mb']:.0f}",
            f"{r['geo_out_mb']:.0f}",
            f"{r['geo_temp_mb']:.1f}",
            f"{r['ref_temp_mb']:.1f}",
        ]
        for r in memory
    ]


def _speed_notes(data: dict) -> list:
    res = data["results"]
    notes = []
    ones = [r for r in res if r["n"] == 1]
    if ones:
        lat = sorted(t for r in ones for t in (r["geo_ns_per_elem"], r["ref_ns_per_elem"]))
        lo, hi = lat[len(lat) // 10], lat[-1 - len(lat) // 10]
        notes.append(
            f"At N = 1 a call takes {fmt_ns(lo)}–{fmt_ns(hi)} with either library "
            "(10th to 90th percentile): dispatch, not arithmetic."
        )
    eager = data.get("eager_se3_exp")
    if eager:
        notes.append(
            f"Eager `SE3.exp` of one tangent: {eager['geo_us']:.1f} µs against jaxlie's "
            f"{eager['ref_us']:.1f} µs per call (speed-up {eager['ratio']:.2f})."
        )
    slower = sorted((r for r in res if _slower(r)), key=lambda r: r["ratio"])
    if slower:
        notes.append(
            "Slower than jaxlie: "
            + ", ".join(
                f"{r['group']} {r['op']} at {_n_at(r['n'])} ({r['ratio']:.2f})" for r in slower
            )
            + "."
        )
    else:
        notes.append(
            "No case where jaxlie_geo is slower (speed-up below 0.95 with the whole IQR below 1)."
        )
    differ = [r for r in res if not r["max_rel_diff"] < _tolerance(r)]
    if differ:
        notes.append(
            "Outputs differ beyond the tolerance (largest |Δ| / (1 + |jaxlie|)): "
            + ", ".join(
                f"{r['group']} {r['op']} at {_n_at(r['n'])} ({r['max_rel_diff']:.2g})"
                for r in differ
            )
            + "."
        )
    return notes


def pretty_n_pow2(n: int) -> str:
    """2²² for a power of two above 8, else ``pretty_n``."""
    k = round(math.log2(n)) if n > 0 else 0
    return f"2{str(k).translate(SUPERSCRIPT)}" if n == 2**k and k > 3 else pretty_n(n)


JAC_ORDER = (
    "jac_right",
    "jac_left",
    "jac_right_inv",
    "jac_left_inv",
    "jlog",
    "compose",
    "inverse",
    "between",
    "rminus",
    "rplus",
    "apply",
)


def jacobians_section(raw: dict, order: list) -> list:
    found = [raw[m][k] for m in order for k in sorted(raw[m]) if k.startswith("jacobians-")]
    if not found:
        return []
    lines = ["## Jacobians against `jax.jacfwd`", ""]
    for data in found:
        lines += _jacobian_table(data)
    return lines


def _jacobian_table(data: dict) -> list:
    info, res = data["machine"], data["results"]
    skipped = {(s["group"], s["case"]) for s in data.get("skipped_constant", [])}
    labels = {r["case"]: r["jacobian"] for r in res}
    cases = [c for c in JAC_ORDER if c in labels]
    groups = [
        g for g in GROUPS if any(r["group"] == g for r in res) or any(s[0] == g for s in skipped)
    ]
    lines = [f"### {label(info)}, {info.get('dtype', '?')}", ""]
    for n in sorted({r["n"] for r in res}):
        by = {(r["group"], r["case"]): r for r in res if r["n"] == n}
        body = []
        for c in cases:
            row = [f"`{labels[c]}`"]
            for g in groups:
                r = by.get((g, c))
                if r:
                    row.append(
                        f"{r['ratio']:.2f} ({_plain_ns(r['ours_ns_per_elem'])} / "
                        f"{_plain_ns(r['jacfwd_ns_per_elem'])} ns)"
                    )
                else:
                    row.append("constant" if (g, c) in skipped else "")
            body.append(row)
        lines += [
            f"jax {info.get('jax', '?')}, measured {_date(info)}, N = {pretty_n(n)}. "
            "Cells: speed-up (ns per element: closed form / jacfwd).",
            "",
        ]
        lines += table(["Jacobian"] + groups, body, "l" + "r" * len(groups)) + [""]
        rs = [r for r in res if r["n"] == n]
        means = ", ".join(
            f"{g} {geomean([r['ratio'] for r in rs if r['group'] == g]):.2f}"
            for g in groups
            if any(r["group"] == g for r in rs)
        )
        overall = geomean([r["ratio"] for r in rs])
        worst = max(r["max_abs_diff_float64"] for r in rs)
        lines += [
            f"- Geometric mean: {means}; overall {overall:.2f}.",
            f"- Largest difference from jacfwd in float64: {worst:.1e}.",
            "",
        ]
    return lines


EXTENDED_OPS = ("exp", "log", "compose", "apply", "jac_right", "grad")
EXTENDED_GROUPS = ("Sim3", "SE23")

EXTENDED_METHOD = """\
Method (`extended_groups.py`): jaxlie has neither group, so each operation is timed against
the matrix computation that defines it, written with jax alone: exp against
`vmap(jax.scipy.linalg.expm)(G.hat(ξ))`; compose against `A @ B`, the 4×4 (Sim3) or 5×5
(SE23) matrices from `as_matrix()`; apply against the matrix times the homogeneous point
(x, 1), or (x, 1, 0) for SE23; `G.jac_right(ξ)` against its definition J_r(ξ)δ = vee(E⁻¹ ·
d/dε expm(hat(ξ + εδ))), E = expm(hat ξ), one `jax.jvp` through expm per tangent direction
and E⁻¹ by `jnp.linalg.inv`. jax has no matrix logarithm, so `T.log()` and the gradient of
Σ‖log(exp ξ)‖² are ours alone, checked against the identities log(exp ξ) = ξ and gradient
2ξ; every other output is checked against its reference (max |Δ| / (1 + |ref|) below 1e-3 in
float32, 1e-8 in float64, unless listed). The references of compose and apply get the
matrices, computed before timing; those of exp and compose return matrices where ours return
parameters. Inputs: standard normal tangents with rotation angles uniform in (0, 2.8) rad,
Sim3's log-scale uniform in (−1, 1); elements are exp of such tangents. Timing is `run.py`'s:
one jitted call on the whole batch, inputs on the device, interleaved repetitions (at least
3, or 2 where a call takes over 5 s; each about 10 ms, or a tenth of the slower side's call
up to 1 s, or one call), median time per call
divided by N; speed-up = the reference's time / ours (median of the paired ratios, IQR in
brackets); compile time is one trace + lower + XLA compile. A reference whose compiled
program needs more than 80% of the available memory is compiled but not run. Under `vmap`,
expm's branches on the matrix norm (Padé degree, number of squarings) become selects, so
every element pays every Padé degree and all 16 squarings.\
"""


def _dtype_section(raw: dict, order: list, stem: str, title: str, method: str, table) -> list:
    """A section of the page from every machine's ``<stem>-float32`` and ``-float64``
    results: the title, the method text, one table per file."""
    found = [
        raw[m][f"{stem}-{dt}"]
        for m in order
        for dt in ("float32", "float64")
        if f"{stem}-{dt}" in raw[m]
    ]
    if not found:
        return []
    lines = [f"## {title}", ""] + method.splitlines() + [""]
    for data in found:
        lines += table(data)
    return lines


def extended_section(raw: dict, order: list) -> list:
    return _dtype_section(
        raw,
        order,
        "extended-groups",
        "Sim(3) and SE₂(3) against matrix references",
        EXTENDED_METHOD,
        _extended_table,
    )


def _extended_table(data: dict) -> list:
    info, res = data["machine"], data["results"]
    dtype = info.get("dtype", res[0].get("dtype", "?"))
    key = lambda r: (EXTENDED_GROUPS.index(r["group"]), EXTENDED_OPS.index(r["op"]), r["n"])
    body = []
    for r in sorted(res, key=key):
        ref = r["ratio"] is not None
        speed = f"{r['ratio']:.2f} [{r['ratio_q1']:.2f}–{r['ratio_q3']:.2f}]" if ref else "–"
        if ref and _slower(r):
            speed = f"**{speed}**"
        compile_ref = f"{r['compile_ref_ms']:.0f}" if ref else "–"
        if r.get("compile_ref_ms") is not None:
            compile_ref = f"{r['compile_ref_ms']:.0f}"
        body.append(
            [
                r["group"],
                r["op"],
                pretty_n(r["n"]),
                fmt_ns(r["ours_ns_per_elem"]),
                fmt_ns(r["ref_ns_per_elem"])
                if ref
                else "–"
                if r["reference"] is None
                else "not run ¹",
                speed,
                f"{r['compile_ours_ms']:.0f} / {compile_ref}",
            ]
        )
    header = ["group", "op", "N", "ours", "reference", "speed-up", "compile ms, ours / reference"]
    lines = [
        f"### {label(info)}, {dtype}",
        "",
        f"jax {info.get('jax', '?')}, measured {_date(info)}. Times per element; **bold**: "
        "ours slower, with the whole IQR below 1.",
        "",
    ]
    lines += table(header, body, "lllrrrr") + [""]
    tol = 1e-3 if dtype == "float32" else 1e-8
    slower = [r for r in res if r["ratio"] is not None and _slower(r)]
    notes = []
    if slower:
        notes.append(
            "Slower than the reference: "
            + ", ".join(
                f"{r['group']} {r['op']} at {_n_at(r['n'])} ({r['ratio']:.2f})" for r in slower
            )
            + "."
        )
    not_run = [r for r in res if r["ratio"] is None and r["reference"] is not None]
    if not_run:
        notes.append(
            "¹ Reference compiled but not run, its program larger than 80% of the memory "
            "available: "
            + ", ".join(
                f"{r['group']} {r['op']} at {_n_at(r['n'])} ({r['memory_ref_mb'] / 1e3:.1f} GB)"
                for r in not_run
            )
            + "."
        )
    checked = [r for r in res if r["max_rel_diff"] is not None]
    differ = [r for r in checked if not r["max_rel_diff"] < tol]
    worst = max((r["max_rel_diff"] for r in checked), default=float("nan"))
    if differ:
        notes.append(
            f"Outputs differ beyond {tol:g} (max |Δ| / (1 + |ref|)): "
            + ", ".join(
                f"{r['group']} {r['op']} at {_n_at(r['n'])} ({r['max_rel_diff']:.2g})"
                for r in differ
            )
            + "."
        )
    else:
        notes.append(f"Largest difference from the references and identities: {worst:.1e}.")
    return lines + [f"- {note}" for note in notes] + [""]


SPLINE_BENCHMARKS = ("derivatives", "jacobians")

SPLINES_METHOD = """\
Method (`splines.py`): one SE3 spline of 100 control points (`jaxlie_geo.splines.Spline`, a
random walk: steps with standard normal translations times 0.3 and rotation angles uniform in
(0, 0.5) rad; Δt = 0.1), degrees 3 and 5, evaluated at N times given to both sides as the
same `SplineTime` (segments uniform, fractions uniform in (0.001, 0.999)). **Derivatives**:
`spline.evaluate(t, 2)`, the value with the body velocity ω and dω/dt from the recursions of
Sommer, Demmel, Usenko and Cremers, "Efficient Derivative Computation for Cumulative
B-Splines on Lie Groups" (2020), against autodiff of the value: the parameters (q, p) of
`spline(t)` differentiated twice in the segment fraction u by nested forward mode (`jax.jvp`
of `jax.jvp`, on the whole batch), then SE3's kinematics ω = (Rᵀṗ, 2 vec(q̄ q̇)) and dω/dt =
(Rᵀp̈ − ω_rot × Rᵀṗ, 2 vec(q̄ q̈)), divided by Δt and Δt². This was the fastest autodiff of
the value measured; through the 4×4 matrices (ω = vee(T⁻¹ Ṫ)) it is 2 to 5 times slower on a
CPU. **Jacobians**: `spline.jacobians(t)`, the blocks of the value, ω and dω/dt with respect
to right perturbations T_m exp(δ_m) of the degree + 1 control points a time depends on,
against `jax.vmap` over the times of `jax.jacfwd` in δ (shape (degree + 1, 6)) of
(log(T₀⁻¹ T(δ)), ω(δ), dω/dt(δ)), evaluated by `evaluate(·, 2)` on those control points
alone. Outputs are checked against the references (max |Δ| / (1 + |ref|) below 1e-3 in
float32, 1e-8 in float64, unless listed). Timing is `extended_groups.py`'s: one jitted call
on the whole batch, inputs on the device, interleaved repetitions (at least 3, or 2 where a
call takes over 5 s), median time per call divided by N; speed-up = autodiff's time / ours
(median of the paired ratios, IQR in brackets); compile time is one trace + lower + XLA
compile. A side whose compiled program needs more than 80% of the available memory is
compiled but not run.\
"""


def splines_section(raw: dict, order: list) -> list:
    return _dtype_section(
        raw,
        order,
        "splines",
        "Cumulative B-splines against autodiff",
        SPLINES_METHOD,
        _splines_table,
    )


def _splines_table(data: dict) -> list:
    info, res = data["machine"], data["results"]
    dtype = info.get("dtype", res[0].get("dtype", "?"))
    key = lambda r: (SPLINE_BENCHMARKS.index(r["benchmark"]), r["degree"], r["n"])
    body = []
    for r in sorted(res, key=key):
        ref = r["ratio"] is not None
        speed = f"{r['ratio']:.2f} [{r['ratio_q1']:.2f}–{r['ratio_q3']:.2f}]" if ref else "–"
        if ref and _slower(r):
            speed = f"**{speed}**"
        ours, auto = r["ours_ns_per_elem"], r["ref_ns_per_elem"]
        body.append(
            [
                r["benchmark"],
                str(r["degree"]),
                pretty_n(r["n"]),
                fmt_ns(ours) if ours is not None else "not run ¹",
                fmt_ns(auto) if auto is not None else "not run ¹",
                speed,
                f"{r['compile_ours_ms']:.0f} / {r['compile_ref_ms']:.0f}",
            ]
        )
    header = [
        "benchmark",
        "degree",
        "N",
        "ours",
        "autodiff",
        "speed-up",
        "compile ms, ours / autodiff",
    ]
    groups = sorted({r["group"] for r in res})
    points = sorted({r["control_points"] for r in res})
    lines = [
        f"### {label(info)}, {dtype}",
        "",
        f"jax {info.get('jax', '?')}, measured {_date(info)}; {', '.join(groups)}, "
        f"{', '.join(map(str, points))} control points. Times per element (one time on the "
        "spline); **bold**: ours slower, with the whole IQR below 1.",
        "",
    ]
    lines += table(header, body, "lllrrrr") + [""]
    tol = 1e-3 if dtype == "float32" else 1e-8
    where = lambda r: f"{r['benchmark']} degree {r['degree']} at {_n_at(r['n'])}"
    notes = []
    slower = [r for r in res if r["ratio"] is not None and _slower(r)]
    if slower:
        notes.append(
            "Slower than autodiff: "
            + ", ".join(f"{where(r)} ({r['ratio']:.2f})" for r in slower)
            + "."
        )
    not_run = [
        f"{side} of {where(r)} ({r[mem] / 1e3:.1f} GB)"
        for r in res
        for side, note, mem in (
            ("ours", "ours_note", "memory_ours_mb"),
            ("autodiff", "reference_note", "memory_ref_mb"),
        )
        if r[note]
    ]
    if not_run:
        notes.append(
            "¹ Compiled but not run, the program larger than 80% of the memory available: "
            + ", ".join(not_run)
            + "."
        )
    checked = [r for r in res if r["max_rel_diff"] is not None]
    differ = [r for r in checked if not r["max_rel_diff"] < tol]
    worst = max((r["max_rel_diff"] for r in checked), default=float("nan"))
    if differ:
        notes.append(
            f"Outputs differ beyond {tol:g} (max |Δ| / (1 + |ref|)): "
            + ", ".join(f"{where(r)} ({r['max_rel_diff']:.2g})" for r in differ)
            + "."
        )
    else:
        notes.append(f"Largest difference from autodiff: {worst:.1e}.")
    return lines + [f"- {note}" for note in notes] + [""]


def change_section(raw: dict, order: list) -> list:
    """Before and after a change: a baseline run of an earlier commit (``baseline-speed-*``,
    with its ``change`` entry) beside today's run on the same machine."""
    pairs = [
        (raw[m][f"baseline-speed-{dt}"], raw[m][f"speed-{dt}"])
        for m in order
        for dt in ("float32", "float64")
        if f"baseline-speed-{dt}" in raw[m] and f"speed-{dt}" in raw[m]
    ]
    if not pairs:
        return []
    change = pairs[0][0]["change"]
    lines = [f"## Before and after: {change['title']}", "", change["text"], ""]
    for before, after in pairs:
        lines += _change_table(before, after)
    return lines


def _change_table(before: dict, after: dict) -> list:
    old = {(r["group"], r["op"], r["n"]): r for r in before["results"]}
    new = {(r["group"], r["op"], r["n"]): r for r in after["results"]}
    sizes = sorted({k[2] for k in old if k in new and k[2] > 1})
    cases = [(g, o) for g in GROUPS for o in OPS if any((g, o, n) in old for n in sizes)]
    header, align = ["group", "op"], "ll"
    for n in sizes:
        header += [f"{pretty_n(n)}: jaxlie_geo", f"{pretty_n(n)}: speed-up"]
        align += "rr"
    top = sizes[-1]
    header.append(f"compile ms at {pretty_n(top)} (jaxlie)")
    align += "r"
    body = []
    for g, o in cases:
        row = [g, o]
        for n in sizes:
            a, b = old.get((g, o, n)), new.get((g, o, n))
            if a and b:
                row += [
                    f"{fmt_ns(a['geo_ns_per_elem'])} → {fmt_ns(b['geo_ns_per_elem'])}",
                    f"{a['ratio']:.2f} → {b['ratio']:.2f}",
                ]
            else:
                row += ["", ""]
        a, b = old.get((g, o, top)), new.get((g, o, top))
        row.append(
            f"{a['compile_geo_ms']:.0f} → {b['compile_geo_ms']:.0f} ({b['compile_ref_ms']:.0f})"
            if a and b
            else ""
        )
        body.append(row)
    info, was = after["machine"], before["machine"]
    dtype = info.get("dtype", "?")
    lines = [
        f"### {label(info)}, {dtype}",
        "",
        f"Before: commit {_commit(was)}, measured {_date(was)}; after: commit "
        f"{_commit(info)}, measured {_date(info)}; jax {info.get('jax', '?')}. Time "
        "per element of jaxlie_geo, and its speed-up over jaxlie measured in the same run.",
        "",
    ]
    return lines + table(header, body, align) + [""]


MATRIX_OPS = ("jac_right", "jac_right_inv", "jlog", "adjoint", "grad", "from_matrix")
MATRIX_GROUPS = ("SO2", "SE2", "SO3", "SE3", "Sim3", "SE23")
MATRIX_METHOD = """\
`benchmarks/matrix_ops.py`: every group's Jacobians, `jlog`, adjoint, the gradient of
‖log(exp(x)⁻¹ b)‖² and `from_matrix` (of matrices with 10⁻³ noise on the rotation block),
timed beside jaxlie 1.5 where it has the operation and beside the *write floor*, a function
that writes an array of the output's shape and dtype from one input entry per element (at
10³ it is mostly the call's dispatch). Time per element, median of 5 rounds in which the
functions run in turn; ×floor is jaxlie_geo's time over the floor's. In bold: slower than
jaxlie, or a matrix-valued result over 3x its floor."""


def matrix_ops_section(raw: dict, order: list) -> list:
    found = [raw[m]["matrix-ops"] for m in order if "matrix-ops" in raw[m]]
    if not found:
        return []
    lines = ["## Matrix-valued operations: jaxlie and the write floor", ""]
    lines += MATRIX_METHOD.splitlines() + [""]
    for data in found:
        for dtype in ("float32", "float64"):
            rows = [r for r in data["results"] if r["dtype"] == dtype]
            if rows:
                lines += _matrix_ops_table(data["machine"], dtype, rows)
    return lines


def _matrix_ops_table(info: dict, dtype: str, rows: list) -> list:
    by = {(r["group"], r["op"], r["n"]): r for r in rows}
    sizes = sorted({r["n"] for r in rows})
    header, align = ["group", "op", "output"], "lll"
    for n in sizes:
        header += [f"{pretty_n(n)}: jaxlie_geo", f"{pretty_n(n)}: jaxlie", f"{pretty_n(n)}: ×floor"]
        align += "rrr"
    header.append(f"compile ms at {pretty_n(sizes[-1])}, jaxlie_geo / jaxlie")
    align += "r"
    body = []
    for g in MATRIX_GROUPS:
        for o in MATRIX_OPS:
            if not any((g, o, n) in by for n in sizes):
                continue
            first = next(by[g, o, n] for n in sizes if (g, o, n) in by)
            row = [g, o, "×".join(str(d) for d in first["output_shape"])]
            for n in sizes:
                r = by.get((g, o, n))
                if r is None:
                    row += ["", "", ""]
                    continue
                ours, ref = r["ours_ns_per_elem"], r["jaxlie_ns_per_elem"]
                over = r["ours_ns_per_elem"] / r["floor_ns_per_elem"]
                ours_text = fmt_ns(ours)
                if ref is not None and ours > ref:
                    ours_text = f"**{ours_text}**"
                over_text = f"{over:.1f}"
                if len(r["output_shape"]) == 2 and over > 3:
                    over_text = f"**{over_text}**"
                row += [ours_text, fmt_ns(ref) if ref is not None else "–", over_text]
            r = by.get((g, o, sizes[-1]), first)
            ref_ms = r["compile_jaxlie_ms"]
            row.append(
                f"{r['compile_ours_ms']:.0f} / {ref_ms:.0f}"
                if ref_ms
                else f"{r['compile_ours_ms']:.0f} / –"
            )
            body.append(row)
    lines = [
        f"### {label(info)}, {dtype}",
        "",
        f"jax {info.get('jax', '?')}, jaxlie {info.get('jaxlie', '?')}, commit {_commit(info)}, "
        f"measured {_date(info)}.",
        "",
    ]
    return lines + table(header, body, align) + [""]


def _plain_ns(x: float) -> str:
    return f"{x:.0f}" if x >= 100 else f"{x:.1f}" if x >= 10 else f"{x:.2f}"


def accuracy_section(raw: dict, order: list) -> list:
    found = [raw[m]["accuracy"] for m in order if "accuracy" in raw[m]]
    if not found:
        return []
    lines = ["## Accuracy", ""]
    for data in found:
        lines += _accuracy_tables(data)
    return lines


def _accuracy_tables(data: dict) -> list:
    info, bounds, libs = data["machine"], data["bounds"], data["libs"]
    cells = {
        (c["lib"], c["group"], c["op"], c["dtype"], c["regime"]): (
            c["ulp"],
            c.get("over", c["ulp"] is None or not c["ulp"] <= bounds[c["op"]]),
        )
        for c in data["cells"]
    }
    groups = [g for g in data.get("groups", GROUPS) if any(k[1] == g for k in cells)]
    dtypes = [d for d in ("float32", "float64") if any(k[3] == d for k in cells)]
    lines = [
        f"### {label(info)}",
        "",
        f"jax {info.get('jax', '?')}, measured {_date(info)}, {data['samples']} samples per "
        f"regime and translation norm. Worst error in ulp, cells {' / '.join(libs)}; "
        "**bold**: a case over its bound.",
        "",
    ]

    def cell(v, over):
        return f"**{fmt_ulp(v)}**" if over else fmt_ulp(v)

    for dt in dtypes:
        body = []
        for g in groups:
            for op, op_label in data["ops"].items():
                row = [g, op_label]
                for reg in data["regimes"]:
                    vals = [cells.get((lib, g, op, dt, reg["key"])) for lib in libs]
                    row.append(
                        ""
                        if all(v is None for v in vals)
                        else " / ".join(cell(*(v or (None, False))) for v in vals)
                    )
                body.append(row)
        header = ["group", "op"] + [r["label"] for r in data["regimes"]]
        lines += [f"**{dt}**", ""]
        lines += table(header, body, "ll" + "r" * len(data["regimes"])) + [""]
    for note in data.get("notes", []):
        lines += [note, ""]
    for section in data.get("sections", []):  # Markdown tables accuracy.py renders itself
        lines += [f"**{section['title']}**", "", *section["lines"], ""]
    return lines


POSE_GRAPHS_METHOD = """\
Method (`pose_graphs.py`): the public datasets that ship in the `gtsam` wheel, read by
`jaxlie_geo.pose_graph.read`; GTSAM's factor graph is built from that same reading
(`BetweenFactorPose2/3`, `noiseModel.Gaussian.Information` with the information moved to
GTSAM's (ω, v) order for Pose3, and a `PriorFactor` of σ = 1e-6 on the first pose, as
`solve`'s anchor), so both minimise ½ Σ ‖log(Z⁻¹ Tᵢ⁻¹ Tⱼ)‖²_Ω from the same initial
estimate (the file's vertices, or the chained odometry where it has none). Final costs are
GTSAM's `graph.error` of each side's estimate (our own cost function agrees to rounding).
GTSAM: `LevenbergMarquardtOptimizer`, default parameters (λI damping, relative and absolute
tolerances 1e-5, at most 100 iterations), timed `optimize()`, the optimiser's construction
included. Ours: `pose_graph.solve` with its defaults (Levenberg–Marquardt, λI damping, a
sparse Cholesky on the host, relative tolerance 1e-7, float64; the factorisation, CHOLMOD
or QDLDL, is named per machine), timed as the whole `solve` call (its checks of the graph
and the graph of the result included): "first call" includes tracing and compiling. The
other times are warm: GTSAM's and our solves alternate, at least 7 of each (3 where GTSAM
takes over 5 s) and 2 s in all, and each side's fastest run is shown (on a shared virtual
machine, noise only adds time); the cost-against-time curves are those of a warm run.
"sphere2500, load3D's blocks" swaps the 3 × 3 blocks of every information matrix, the
reading of GTSAM's own `load3D`, which puts the first block of a TORO `EDGE3` matrix on
rotation (TORO and HOG-Man put translation first).\
"""


def _seconds(x: float) -> str:
    """A wall time in s, or in ms under 0.1 s."""
    return f"{x:.2f} s" if x >= 0.1 else f"{1e3 * x:.1f} ms"


def pose_graphs_section(raw: dict, order: list) -> list:
    found = [raw[m]["pose-graphs"] for m in order if "pose-graphs" in raw[m]]
    if not found:
        return []
    lines = ["## Pose graphs against GTSAM", ""] + POSE_GRAPHS_METHOD.splitlines() + [""]
    for data in found:
        info, res = data["machine"], data["results"]
        header = [
            "dataset",
            "poses",
            "edges",
            "initial cost",
            "GTSAM final (iterations)",
            "ours final (iterations)",
            "ours ≤ GTSAM × (1 + 10⁻⁶)",
            "GTSAM time",
            "ours time",
            "ours, first call",
            "ours / GTSAM time",
        ]
        body = [
            [
                r["dataset"],
                f"{r['poses']:,}",
                f"{r['edges']:,}",
                f"{r['initial_cost_gtsam']:.4g}",
                f"{r['gtsam_final']:.9g} ({r['gtsam_iterations']})",
                f"{r['ours_final_in_gtsam']:.9g} ({r['ours_iterations']})",
                "yes" if r["reaches_gtsam"] else "**no**",
                _seconds(r["gtsam_s"]),
                _seconds(r["ours_s"]),
                _seconds(r["ours_cold_s"]),
                f"{r['time_ratio']:.2f}",
            ]
            for r in res
        ]
        lines += [
            f"### {label(info)}",
            "",
            f"jax {info.get('jax', '?')}, GTSAM {info.get('gtsam', '?')}, "
            f"{_factorisation(info)}, measured {_date(info)}.",
            "",
        ]
        lines += table(header, body, "lrrrrrlrrrr") + [""]
        per_it = ", ".join(
            f"{r['dataset']} {1e3 * r['gtsam_s'] / max(r['gtsam_iterations'], 1):.3g} / "
            f"{1e3 * r['ours_s'] / max(r['ours_iterations'], 1):.3g} ms"
            for r in res
        )
        lines += [f"Per iteration, GTSAM / ours: {per_it}.", ""]
    lines += [
        f"![Cost against time, GTSAM and ours, per dataset]({POSE_GRAPH_PLOT})",
        "",
        "*Cost against wall time (warm runs), one panel per dataset.*",
        "",
    ]
    return lines


SPLINE_FIT_METHOD = """\
Method (`spline_fit.py`): `splines.fit` of a cubic SE3 spline with n control points (Δt =
0.1) to N = 10 (n − 3) noisy poses of a smooth trajectory (each pose right-multiplied by
exp(ε), ε ~ N(0, 0.01² I₆)), float64, from the default initial spline to a relative
tolerance of 1e-10, with one linear solver per row: **dense**, LAPACK's Cholesky of the full
6n × 6n normal matrix; **banded**, LAPACK's banded Cholesky of the same matrix (23
off-diagonals); **CHOLMOD** (supernodal, through cvxopt) and **QDLDL**, sparse. Every
solver reaches the same final cost to 1e-9 relative. Each row runs in its own process:
"first call" includes tracing and compiling, "warm" is one second fit of the same data (a
single run, so it carries the machine's noise); "peak memory" is the process's peak resident
set (`VmHWM`), JAX and the data included, and "fit's share" its increase over the peak
before the first fit (the compiler's memory included). The dense solver is not run
where its matrix alone needs more than half the available memory.\
"""

SPLINE_FIT_SOLVERS = {"dense": "dense", "banded": "banded", "cholmod": "CHOLMOD", "qdldl": "QDLDL"}


def spline_fit_section(raw: dict, order: list) -> list:
    found = [raw[m]["spline-fit"] for m in order if "spline-fit" in raw[m]]
    if not found:
        return []
    lines = ["## Spline fits: dense and sparse normal equations", ""]
    lines += SPLINE_FIT_METHOD.splitlines() + [""]
    header = [
        "control points",
        "samples",
        "solver",
        "iterations",
        "warm",
        "first call",
        "peak memory",
        "fit's share",
    ]
    for data in found:
        info, res = data["machine"], data["results"]
        body = []
        for r in res:
            name = SPLINE_FIT_SOLVERS[r["solver"]]
            if "skipped_gb" in r:
                needs = f"not run: its matrix alone needs {r['skipped_gb']:.1f} GB"
                body.append([f"{r['control_points']:,}", "", name, needs, "", "", "", ""])
                continue
            body.append(
                [
                    f"{r['control_points']:,}",
                    f"{r['samples']:,}",
                    name,
                    str(r["iterations"]),
                    _seconds(r["warm_s"]),
                    _seconds(r["first_s"]),
                    f"{r['peak_gb']:.2f} GB",
                    f"{r['peak_gb'] - r['before_gb']:.2f} GB",
                ]
            )
        lines += [
            f"### {label(info)}",
            "",
            f"jax {info.get('jax', '?')}, SciPy {info.get('scipy', '?')}, cvxopt "
            f"{info.get('cvxopt', '?')}, qdldl {info.get('qdldl', '?')}, "
            f"{info.get('memory_available_gb', 0):.0f} GB available, measured {_date(info)}.",
            "",
        ]
        lines += table(header, body, "rrlrrrrr") + [""]
    return lines


def render(raw: dict, plot_name: str | None) -> str:
    """The page's Markdown for the raw results ``raw`` (see ``load``)."""
    order = machine_order(raw)
    lines = INTRO.splitlines() + [""]
    lines += summary_section(raw, order)
    runs = plotted_runs(raw, order)
    if plot_name and runs:
        name = label(runs[0]["machine"])
        lines += [
            f"![Speed-up over jaxlie by group, operation and batch size, {name}]({plot_name})",
            "",
            f"*The plot: {name}; float32 filled, float64 hollow; bars are the IQR.*",
            "",
        ]
    lines += METHOD.splitlines() + [""]
    lines += machines_section(raw, order)
    lines += speed_section(raw, order)
    lines += jacobians_section(raw, order)
    lines += extended_section(raw, order)
    lines += matrix_ops_section(raw, order)
    lines += splines_section(raw, order)
    lines += pose_graphs_section(raw, order)
    lines += spline_fit_section(raw, order)
    lines += change_section(raw, order)
    lines += accuracy_section(raw, order)
    while lines and lines[-1] == "":
        lines.pop()
    return "\n".join(lines) + "\n"


def plotted_runs(raw: dict, order: list) -> list:
    """The speed runs the plot shows: those of the first machine that has any."""
    for m in order:
        runs = [raw[m][k] for k in ("speed-float32", "speed-float64") if k in raw[m]]
        if runs:
            return runs
    return []


def write_page(raw_dir: Path = RAW_DIR, page: Path = PAGE, plot: bool = True) -> None:
    """Render ``page`` (and the plot beside it) from the raw files in ``raw_dir``."""
    raw = load(raw_dir)
    runs = plotted_runs(raw, machine_order(raw))
    if plot and runs:
        try:
            import plot as _plot  # benchmarks/plot.py: matplotlib is optional
        except ImportError as e:
            print(f"plot not redrawn ({e})", file=sys.stderr)
        else:
            _plot.plot(runs, page.parent / PLOT_NAME, GROUPS, OPS, label, pretty_n)
            graphs = [raw[m]["pose-graphs"] for m in machine_order(raw) if "pose-graphs" in raw[m]]
            if graphs:
                machine = label(graphs[0]["machine"])
                _plot.plot_pose_graphs(graphs[0], page.parent / POSE_GRAPH_PLOT, machine)
    page.write_text(render(raw, PLOT_NAME), encoding="utf-8")
    print(f"wrote {page}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--raw-dir", type=Path, default=RAW_DIR, help="raw results (default: %(default)s)"
    )
    ap.add_argument("--page", type=Path, default=PAGE, help="page to write (default: %(default)s)")
    ap.add_argument("--no-plot", action="store_true", help="leave the plot as it is")
    ap.add_argument(
        "--plot",
        type=Path,
        metavar="PNG",
        help="draw only the speed-up figure, of the raw speed files given, into PNG",
    )
    ap.add_argument("files", nargs="*", type=Path, help="raw speed-*.json files, for --plot")
    ap.add_argument(
        "--check",
        action="store_true",
        help="write nothing; exit 1 if the page differs from what the raw files render to",
    )
    args = ap.parse_args(argv)
    if args.plot:
        import plot as _plot  # benchmarks/plot.py: needs matplotlib

        runs = [json.loads(f.read_text(encoding="utf-8")) for f in args.files]
        if not runs:
            raw = load(args.raw_dir)
            runs = plotted_runs(raw, machine_order(raw))
        _plot.plot(runs, args.plot, GROUPS, OPS, label, pretty_n)
        print(f"wrote {args.plot}")
        return 0
    if args.check:
        text = render(load(args.raw_dir), PLOT_NAME)
        current = args.page.read_text(encoding="utf-8") if args.page.exists() else ""
        if text != current:
            print(f"{args.page} is out of date: run python benchmarks/report.py", file=sys.stderr)
            return 1
        print(f"{args.page} is up to date")
        return 0
    write_page(args.raw_dir, args.page, plot=not args.no_plot)
    return 0


if __name__ == "__main__":
    sys.exit(main())
