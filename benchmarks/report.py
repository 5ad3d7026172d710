"""Render ``benchmarks/RESULTS.md`` and its figures from the raw results.

The raw results are JSON files ``benchmarks/raw/<machine>/<kind>.json``, one per machine and
script (``<kind>-<dtype>`` for the runs of one dtype); a script given ``--save`` replaces its
file and calls ``write_page``. The page depends on the raw files only (no clock, no
environment), so rendering twice gives the same bytes. The README and the guides
(``COPIES``) show some of the same figures in blocks marked
``<!-- rendered by benchmarks/report.py: NAME -->``, rewritten from the same files
(``excerpts``); ``--check`` exits with status 1 when the page or any block is stale.

Usage:
  python -m benchmarks.report                  # raw/ -> RESULTS.md and its figures
  python -m benchmarks.report --check          # is RESULTS.md what raw/ renders to?
  python -m benchmarks.report --raw-dir /tmp/raw --page /tmp/RESULTS.md
"""

from __future__ import annotations

import argparse
import math
import re
import string
import sys
from pathlib import Path

from benchmarks import common as C
from benchmarks.common import GROUPS, OPS, fmt_ns, geomean, label, pretty_n, table
from benchmarks.mpref import fmt_ulp

PLOT_NAME = "results.png"
POSE_GRAPH_PLOT = "pose_graphs.png"
DTYPES = ("float32", "float64")
ALL_GROUPS = ("SO2", "SE2", "SO3", "SE3", "Sim3", "SE23")


def save(kind: str, data: dict, args) -> Path | None:
    """Write ``data`` where the script's options say (``common.write_raw``: ``--json``,
    ``--save``) and, with ``--save``, regenerate the page from every raw file."""
    path = C.write_raw(kind, data, args)
    if path is not None:
        write_page(Path(args.raw_dir), Path(args.page))
    return path


def _date(info: dict) -> str:
    return info.get("date", "?").split()[0]


def _commit(info: dict) -> str:
    """The commit a run measured, and the files that differed from it if the tree had
    uncommitted changes (``common.machine_info`` records them as ``dirty_files``)."""
    commit = info.get("commit", "?")
    if not commit.endswith("-dirty"):
        return commit
    files = info.get("dirty_files")
    changed = ", ".join(f"`{f}`" for f in files) if files else "files not recorded"
    return f"{commit[: -len('-dirty')]} with uncommitted changes ({changed})"


def machine_order(raw: dict) -> list:
    """CPUs before GPUs; among each, the machine with the newest speed run first."""

    def newest(m):
        dates = [d["machine"].get("date", "") for k, d in raw[m].items() if k.startswith("speed")]
        return max(dates or [""])

    order = sorted(sorted(raw), key=newest, reverse=True)
    return sorted(order, key=lambda m: any(_gpu(d["machine"]) for d in raw[m].values()))


def _gpu(info: dict) -> bool:
    return info.get("backend", "cpu") != "cpu"


def _os(info: dict) -> str:
    """``Linux-6.1-...-x86_64-with-glibc2.36`` -> ``Linux x86_64, glibc 2.36``."""
    text = info.get("platform", "")
    m = re.match(r"(\w+)-.*?-(x86_64|aarch64|arm64|AMD64)(?:-with-(\D+)([\d.]+))?", text)
    if not m:
        return text
    return f"{m[1]} {m[2]}" + (f", {m[3]} {m[4]}" if m[3] else "")


def _n_at(n: int) -> str:
    return "N = 1" if n == 1 else pretty_n(n)


def pretty_n_pow2(n: int) -> str:
    """2²² for a power of two above 8, else ``pretty_n``."""
    k = round(math.log2(n)) if n > 0 else 0
    return f"2{str(k).translate(C.SUPERSCRIPT)}" if n == 2**k and k > 3 else pretty_n(n)


def _seconds(x: float) -> str:
    """A wall time in s, or in ms under 0.1 s."""
    return f"{x:.2f} s" if x >= 0.1 else f"{1e3 * x:.1f} ms"


def _slower(r: dict) -> bool:
    return r["ratio"] < 0.95 and r["ratio_q3"] < 1.0


def _speedup(r: dict) -> str:
    """A measured speed-up with its IQR, bold where slower; "–" where not measured."""
    if r.get("ratio") is None:
        return "–"
    text = f"{r['ratio']:.2f} [{r['ratio_q1']:.2f}–{r['ratio_q3']:.2f}]"
    return f"**{text}**" if _slower(r) else text


def _listing(prefix: str, items) -> list:
    """``[prefix + "a, b, c."]``, or nothing for no items."""
    items = list(items)
    return [prefix + ", ".join(items) + "."] if items else []


def _cols(cols, items) -> list:
    """A table whose columns are (header, align, cell function) triples, one row per item."""
    header = [h for h, _, _ in cols]
    align = "".join(a for _, a, _ in cols)
    return table(header, [[f(x) for _, _, f in cols] for x in items], align)


class _Format(string.Formatter):
    """``str.format`` with two more conversions: ``{x!n}`` a time in ns (``fmt_ns``, "–"
    for None), ``{x!t}`` a wall time in s (``_seconds``); a missing field is "?"."""

    def get_value(self, key, args, kwargs):
        return kwargs.get(key, "?") if isinstance(key, str) else args[key]

    def convert_field(self, value, conversion):
        if conversion == "n":
            return "–" if value is None else fmt_ns(value)
        return _seconds(value) if conversion == "t" else super().convert_field(value, conversion)


_FORMAT = _Format()


def _spec(spec: str, rows, **extra) -> list:
    """A table from a column spec, one ``header | align | template`` line per column, each
    cell its template formatted (``_Format``) with the row's fields and ``extra``'s."""
    cols = [line.strip().split(" | ") for line in spec.strip().splitlines()]
    cell = lambda t: lambda r: _FORMAT.vformat(t, (), {**extra, **r})
    return _cols([(h, a, cell(t)) for h, a, t in cols], rows)


def _facts(info: dict, template: str, **extra) -> str:
    """A run's line of facts: ``template`` formatted with the machine's fields, ``date``,
    ``commit`` (``_commit``) and ``extra``'s."""
    fields = {**info, "date": _date(info), "commit": _commit(info), **extra}
    return _FORMAT.vformat(template, (), fields)


def _heading(title: str, facts: str) -> list:
    return [f"### {title}", "", facts, ""]


def _runs(raw: dict, order: list, kind: str, by_dtype: bool = False) -> list:
    kinds = [f"{kind}-{dt}" for dt in DTYPES] if by_dtype else [kind]
    return [raw[m][k] for m in order for k in kinds if k in raw[m]]


def _dtype(data: dict) -> str:
    return data["machine"].get("dtype", data["results"][0].get("dtype", "?"))


#: The page's fixed text, by part: ``methods.md``, each part under a ``<!-- name -->`` line.
TEXT = {
    name: text.strip("\n")
    for name, text in re.findall(
        r"^<!-- ([a-z-]+) -->\n(.*?)(?=^<!-- [a-z-]+ -->$|\Z)",
        (C.HERE / "methods.md").read_text(encoding="utf-8"),
        re.S | re.M,
    )
}


# --------------------------------------------------------------------------------------
# Sections
# --------------------------------------------------------------------------------------


def summary_section(raw: dict, order: list) -> list:
    runs = _runs(raw, order, "speed", by_dtype=True)
    if not runs:
        return []
    sizes = sorted({n for d in runs for n in C.sizes(d)})
    cols = [("machine", "l", lambda d: label(d["machine"])), ("dtype", "l", _dtype)]
    cols += [(f"N = {pretty_n(n)}", "r", lambda d, n=n: _mean(d, n)) for n in sizes]
    cols.append(("measured", "l", lambda d: _date(d["machine"])))
    lines = ["Speed-up over jaxlie, geometric mean over the groups and operations measured:", ""]
    return lines + _cols(cols, runs) + [""]


def _mean(data: dict, n: int, fmt="{:.2f}".format) -> str:
    ratios = [r["ratio"] for r in data["results"] if r["n"] == n]
    return fmt(geomean(ratios)) if ratios else ""


def machines_section(raw: dict, order: list) -> list:
    body = []
    for m in order:
        infos = {k: d["machine"] for k, d in sorted(raw[m].items())}
        info = infos.get("speed-float32") or next(iter(infos.values()))
        hw = label(info)
        if _gpu(info):
            hw += f"; host {C.cpu_name(info)}, {info.get('cores')} cores"
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
    head = ["machine", "hardware", "software", "runs"]
    return ["## Machines", ""] + table(head, body, "llll") + [""]


def _kind_text(kind: str) -> str:
    """``extended-groups-float32`` -> ``extended groups (float32)``."""
    name, _, dtype = kind.rpartition("-")
    return f"{name.replace('-', ' ')} ({dtype})" if dtype in DTYPES else kind


def speed_table(data: dict) -> list:
    """A speed run's section of the page: the table, its notes and the memory table."""
    info, res = data["machine"], data["results"]
    dtype, sizes = _dtype(data), C.sizes(data)
    by = {(r["group"], r["op"], r["n"]): r for r in res}
    cases = [(g, o) for g in GROUPS for o in OPS if any((g, o, n) in by for n in sizes)]

    def at(n, f):
        return lambda c: f(by[(*c, n)]) if (*c, n) in by else ""

    cols = [("group", "l", lambda c: c[0]), ("op", "l", lambda c: c[1])]
    for n in sizes:
        if n == 1:
            cols.append(("N = 1", "r", at(n, _speedup)))
            continue
        cols += [
            (f"{pretty_n(n)}: jaxlie_geo", "r", at(n, lambda r: fmt_ns(r["ours_ns_per_elem"]))),
            (f"{pretty_n(n)}: jaxlie", "r", at(n, lambda r: fmt_ns(r["ref_ns_per_elem"]))),
            (f"{pretty_n(n)}: speed-up", "r", at(n, _speedup)),
        ]
    compile_ms = lambda r: f"{r['compile_ours_ms']:.0f} / {r['compile_ref_ms']:.0f}"
    cols.append(
        (
            f"compile ms at {pretty_n(sizes[-1])}, jaxlie_geo / jaxlie",
            "r",
            at(sizes[-1], compile_ms),
        )
    )
    single = "; the N = 1 column is the speed-up of a single call" if 1 in sizes else ""
    facts = f"jax {info.get('jax', '?')}, measured {_date(info)}. Times per element{single}."
    lines = _heading(f"{label(info)}, {dtype}", facts) + _cols(cols, cases) + [""]
    lines += [f"- {note}" for note in _speed_notes(data)] + [""]
    memory = data.get("memory")
    if memory:
        n = pretty_n_pow2(memory[0]["n"])
        lines += [f"Memory of the compiled SE3 operations at N = {n}, {dtype}, MB:", ""]
        lines += memory_table(memory) + [""]
    return lines


def memory_table(memory: list) -> list:
    """Per op: arguments, output and both libraries' temporaries (MB)."""
    cols = [("op", "l", lambda r: r["op"])]
    for head, key, fmt in (
        ("arguments", "geo_args_mb", "{:.0f}"),
        ("output", "geo_out_mb", "{:.0f}"),
        ("temporaries: jaxlie_geo", "geo_temp_mb", "{:.1f}"),
        ("temporaries: jaxlie", "ref_temp_mb", "{:.1f}"),
    ):
        cols.append((head, "r", lambda r, k=key, f=fmt: f.format(r[k])))
    return _cols(cols, memory)


def _speed_notes(data: dict) -> list:
    res, notes = data["results"], []
    ones = [r for r in res if r["n"] == 1]
    if ones:
        lat = sorted(t for r in ones for t in (r["ours_ns_per_elem"], r["ref_ns_per_elem"]))
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
    where = lambda r: f"{r['group']} {r['op']} at {_n_at(r['n'])}"
    slower = sorted((r for r in res if _slower(r)), key=lambda r: r["ratio"])
    notes += _listing("Slower than jaxlie: ", (f"{where(r)} ({r['ratio']:.2f})" for r in slower))
    if not slower:
        notes.append(
            "No case where jaxlie_geo is slower (speed-up below 0.95 with the whole IQR below 1)."
        )
    tol = lambda r: (
        (1e-3 if r.get("dtype") == "float32" else 1e-8) * (10 if r["op"] == "grad" else 1)
    )
    notes += _listing(
        "Outputs differ beyond the tolerance (largest |Δ| / (1 + |jaxlie|)): ",
        (f"{where(r)} ({r['max_rel_diff']:.2g})" for r in res if not r["max_rel_diff"] < tol(r)),
    )
    return notes


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


def jacobians_table(data: dict) -> list:
    """A Jacobian run's section of the page: one table per batch size."""
    info = data["machine"]
    lines = [f"### {label(info)}, {info.get('dtype', '?')}", ""]
    return lines + [line for n in C.sizes(data) for line in _jacobians_at(data, n)]


def _jacobians_at(data: dict, n: int) -> list:
    info, rs = data["machine"], [r for r in data["results"] if r["n"] == n]
    skipped = {(s["group"], s["case"]) for s in data.get("skipped_constant", [])}
    labels = {r["case"]: r["jacobian"] for r in data["results"]}
    present = {r["group"] for r in data["results"]} | {g for g, _ in skipped}
    groups = [g for g in GROUPS if g in present]
    by = {(r["group"], r["case"]): r for r in rs}

    def cell(c, g):
        r = by.get((g, c))
        if r is None:
            return "constant" if (g, c) in skipped else ""
        ours, theirs = C.plain_ns(r["ours_ns_per_elem"]), C.plain_ns(r["ref_ns_per_elem"])
        return f"{r['ratio']:.2f} ({ours} / {theirs} ns)"

    cols = [("Jacobian", "l", lambda c: f"`{labels[c]}`")]
    cols += [(g, "r", lambda c, g=g: cell(c, g)) for g in groups]
    means = ", ".join(
        f"{g} {geomean([r['ratio'] for r in rs if r['group'] == g]):.2f}"
        for g in groups
        if any(r["group"] == g for r in rs)
    )
    return [
        f"jax {info.get('jax', '?')}, measured {_date(info)}, N = {pretty_n(n)}. "
        "Cells: speed-up (ns per element: closed form / jacfwd).",
        "",
        *_cols(cols, [c for c in JAC_ORDER if c in labels]),
        "",
        f"- Geometric mean: {means}; overall {geomean([r['ratio'] for r in rs]):.2f}.",
        f"- Largest difference from jacfwd in float64: "
        f"{max(r['max_abs_diff_float64'] for r in rs):.1e}.",
        "",
    ]


def _checked_notes(res: list, dtype: str, where, peer: str, agree: str, not_run: list) -> list:
    """The notes under a table of ours against a reference: slower cases, sides not run,
    outputs beyond the dtype's tolerance or else the largest difference."""
    tol = 1e-3 if dtype == "float32" else 1e-8
    slower = [r for r in res if r["ratio"] is not None and _slower(r)]
    notes = _listing(f"Slower than {peer}: ", (f"{where(r)} ({r['ratio']:.2f})" for r in slower))
    notes += not_run
    checked = [r for r in res if r["max_rel_diff"] is not None]
    differ = [
        f"{where(r)} ({r['max_rel_diff']:.2g})" for r in checked if not r["max_rel_diff"] < tol
    ]
    notes += _listing(f"Outputs differ beyond {tol:g} (max |Δ| / (1 + |ref|)): ", differ)
    if not differ:
        worst = max((r["max_rel_diff"] for r in checked), default=float("nan"))
        notes.append(f"Largest difference from {agree}: {worst:.1e}.")
    return [f"- {note}" for note in notes] + [""]


def _compile_pair(r: dict) -> str:
    ref = r.get("compile_ref_ms")
    return f"{r['compile_ours_ms']:.0f} / " + (f"{ref:.0f}" if ref is not None else "–")


EXTENDED_OPS = ("exp", "log", "compose", "apply", "jac_right", "grad")


EXTENDED_COLUMNS = """
    group | l | {group}
    op | l | {op}
    N | l | {N}
    ours | r | {ours_ns_per_elem!n}
    reference | r | {reference_time}
    speed-up | r | {speedup}
    compile ms, ours / reference | r | {compile}
"""


def extended_groups_table(data: dict) -> list:
    """A Sim3/SE23 run's section of the page."""
    info, res, dtype = data["machine"], data["results"], _dtype(data)
    key = lambda r: (ALL_GROUPS.index(r["group"]), EXTENDED_OPS.index(r["op"]), r["n"])
    where = lambda r: f"{r['group']} {r['op']} at {_n_at(r['n'])}"
    not_run = [r for r in res if r["ratio"] is None and r["reference"] is not None]
    rows = [
        {
            **r,
            **_derived(r),
            "reference_time": "not run ¹"
            if r in not_run
            else _FORMAT.format("{!n}", r["ref_ns_per_elem"]),
        }
        for r in sorted(res, key=key)
    ]
    facts = _facts(
        info,
        "jax {jax}, measured {date}. Times per element; **bold**: ours "
        "slower, with the whole IQR below 1.",
    )
    notes = _listing(
        "¹ Reference compiled but not run, its program larger than 80% of the memory available: ",
        (f"{where(r)} ({r['memory_ref_mb'] / 1e3:.1f} GB)" for r in not_run),
    )
    lines = _heading(f"{label(info)}, {dtype}", facts) + _spec(EXTENDED_COLUMNS, rows) + [""]
    agree = "the references and identities"
    return lines + _checked_notes(res, dtype, where, "the reference", agree, notes)


def _derived(r: dict) -> dict:
    """The cells of a record of ours against a reference that are more than a format."""
    return {"N": pretty_n(r["n"]), "speedup": _speedup(r), "compile": _compile_pair(r)}


SPLINES_COLUMNS = """
    benchmark | l | {benchmark}
    degree | l | {degree}
    N | l | {N}
    ours | r | {ours}
    autodiff | r | {autodiff}
    speed-up | r | {speedup}
    compile ms, ours / autodiff | r | {compile}
"""


def splines_table(data: dict) -> list:
    """A spline run's section of the page."""
    info, res, dtype = data["machine"], data["results"], _dtype(data)
    key = lambda r: (r["benchmark"] != "derivatives", r["degree"], r["n"])
    where = lambda r: f"{r['benchmark']} degree {r['degree']} at {_n_at(r['n'])}"
    ns = lambda x: "not run ¹" if x is None else fmt_ns(x)
    rows = [
        {
            **r,
            **_derived(r),
            "ours": ns(r["ours_ns_per_elem"]),
            "autodiff": ns(r["ref_ns_per_elem"]),
        }
        for r in sorted(res, key=key)
    ]
    groups = ", ".join(sorted({r["group"] for r in res}))
    points = ", ".join(map(str, sorted({r["control_points"] for r in res})))
    facts = _facts(
        info,
        "jax {jax}, measured {date}; {groups}, {points} control points. Times "
        "per element (one time on the spline); **bold**: ours slower, with the whole "
        "IQR below 1.",
        groups=groups,
        points=points,
    )
    sides = (
        ("ours", "ours_note", "memory_ours_mb"),
        ("autodiff", "reference_note", "memory_ref_mb"),
    )
    notes = _listing(
        "¹ Compiled but not run, the program larger than 80% of the memory available: ",
        (
            f"{side} of {where(r)} ({r[mem] / 1e3:.1f} GB)"
            for r in res
            for side, note, mem in sides
            if r[note]
        ),
    )
    lines = _heading(f"{label(info)}, {dtype}", facts) + _spec(SPLINES_COLUMNS, rows) + [""]
    return lines + _checked_notes(res, dtype, where, "autodiff", "autodiff", notes)


def matrix_ops_table(data: dict) -> list:
    """A matrix-ops run: one table per dtype."""
    return [line for dt in DTYPES for line in _matrix_ops_dtype(data, dt)]


def _matrix_ops_dtype(data: dict, dtype: str) -> list:
    info, rows = data["machine"], [r for r in data["results"] if r["dtype"] == dtype]
    if not rows:
        return []
    by = {(r["group"], r["op"], r["n"]): r for r in rows}
    sizes = sorted({r["n"] for r in rows})
    cases = [
        (g, o) for g in ALL_GROUPS for o in C.MATRIX_OPS if any((g, o, n) in by for n in sizes)
    ]
    first = lambda c: next(by[(*c, n)] for n in sizes if (*c, n) in by)
    at = lambda n, f: lambda c: f(by[(*c, n)]) if (*c, n) in by else ""

    def ours(r):
        text, ref = fmt_ns(r["ours_ns_per_elem"]), r["jaxlie_ns_per_elem"]
        return f"**{text}**" if ref is not None and r["ours_ns_per_elem"] > ref else text

    def floor(r):
        over = r["ours_ns_per_elem"] / r["floor_ns_per_elem"]
        return f"**{over:.1f}**" if len(r["output_shape"]) == 2 and over > 3 else f"{over:.1f}"

    def compile_ms(c):
        r = by.get((*c, sizes[-1]), first(c))
        ref = r["compile_jaxlie_ms"]
        return f"{r['compile_ours_ms']:.0f} / " + (f"{ref:.0f}" if ref else "–")

    jaxlie = lambda r: "–" if r["jaxlie_ns_per_elem"] is None else fmt_ns(r["jaxlie_ns_per_elem"])
    shape = lambda c: "×".join(map(str, first(c)["output_shape"]))
    cols = [("group", "l", lambda c: c[0]), ("op", "l", lambda c: c[1]), ("output", "l", shape)]
    for n in sizes:
        p = pretty_n(n)
        cols += [(f"{p}: jaxlie_geo", "r", at(n, ours)), (f"{p}: jaxlie", "r", at(n, jaxlie))]
        cols.append((f"{p}: ×floor", "r", at(n, floor)))
    cols.append((f"compile ms at {pretty_n(sizes[-1])}, jaxlie_geo / jaxlie", "r", compile_ms))
    facts = (
        f"jax {info.get('jax', '?')}, jaxlie {info.get('jaxlie', '?')}, commit {_commit(info)}, "
        f"measured {_date(info)}."
    )
    return _heading(f"{label(info)}, {dtype}", facts) + _cols(cols, cases) + [""]


def kernel_sizes_table(data: dict) -> list:
    """A kernel-sizes run: one table per dtype."""
    return [line for dt in DTYPES for line in _kernel_sizes_dtype(data, dt)]


def _kernel_sizes_dtype(data: dict, dtype: str) -> list:
    info = data["machine"]
    by = {(r["group"], r["op"]): r for r in data["results"] if r["dtype"] == dtype}
    groups = [g for g in ALL_GROUPS if any((g, o) in by for o in C.KERNEL_OPS)]
    if not groups:
        return []

    def cell(o, g):
        c = by.get((g, o))
        return f"{c['instructions']:,} / {c['compile_s']:.2f} s" if c else ""

    def ratio(o, g):
        c, ref = by.get((g, o)), by.get(("SE3", o))
        if c is None or ref is None:
            return ""
        ri, rc = c["instructions"] / ref["instructions"], c["compile_s"] / ref["compile_s"]
        return f"**{ri:.1f}x / {rc:.1f}x**" if max(ri, rc) > 3 else f"{ri:.1f}x / {rc:.1f}x"

    ops = [o for o in C.KERNEL_OPS if any((g, o) in by for g in groups)]
    cols = [("op", "l", lambda o: o)] + [(g, "r", lambda o, g=g: cell(o, g)) for g in groups]
    cols += [(f"{g} / SE3", "r", lambda o, g=g: ratio(o, g)) for g in ("Sim3", "SE23")]
    facts = (
        f"jax {info.get('jax', '?')}, commit {_commit(info)}, measured {_date(info)}. "
        "**Bold**: over 3x SE(3)'s."
    )
    return (
        _heading(f"{label(info)}, {dtype}: instructions / compile", facts) + _cols(cols, ops) + [""]
    )


IK_COLUMNS = """
    problems | r | {batch}
    compile: jaxlie_geo | r | {compile_ours}
    jaxlie | r | {compile_jaxlie}
    ratio | r | {compile_ratio}
    run: jaxlie_geo | r | {run_ours}
    jaxlie | r | {run_jaxlie}
    ratio | r | {run_ratio}
"""


def ik_program_table(data: dict) -> list:
    info, rows = data["machine"], []
    for r in data["results"]:
        row = {"batch": r["batch"]}
        for k, fmt in (("compile", "{:.2f} s".format), ("run", lambda x: fmt_ns(x * 1e9))):
            ours, theirs = r[f"{k}_ours_s"], r[f"{k}_jaxlie_s"]
            row[f"{k}_ours"] = f"**{fmt(ours)}**" if ours > theirs else fmt(ours)
            row.update({f"{k}_jaxlie": fmt(theirs), f"{k}_ratio": f"{ours / theirs:.2f}"})
        rows.append(row)
    facts = _facts(info, "jax {jax}, jaxlie {jaxlie}, commit {commit}, measured {date}.")
    return _heading(label(info), facts) + _spec(IK_COLUMNS, rows) + [""]


LEAST_SQUARES_COLUMNS = """
    batch | l | {batch}
    solver | l | {solver}
    time per problem | r | {per}
    GTSAM / it | r | {speedup}
    compile | r | {compile}
    cost ratio (ours / its) | r | {cost_ratio}
    from Kabsch (angle, translation) | r | {kabsch}
    derivative | r | {derivative}
"""


def _least_squares_rows(r: dict) -> list:
    """One batch's rows: ours, GTSAM's loop and (where run) optimistix."""
    B = r["problems"]
    names = {"ours": "jaxlie_geo", "gtsam": "GTSAM (loop)", "optimistix": "optimistix"}
    size = f"{r['points']} points" if "points" in r else f"{r['poses']} poses"
    gradient = {"ours": "gradient_rel_error_max", "optimistix": "optimistix_gradient_rel_error_max"}
    rows = []
    for side in [s for s in names if f"run_{s}_s" in r]:
        compile_s, kabsch = r.get(f"compile_{side}_s"), r.get(f"kabsch_{side}")
        rows.append(
            {
                "batch": "" if rows else f"{r['problem']} (B = {B:,}, {size})",
                "solver": names[side]
                + (f" ({r['converged']:,} of {B:,} converged)" if side == "ours" else ""),
                "per": fmt_ns(r[f"run_{side}_s"] / B * 1e9),
                "speedup": f"{r['run_gtsam_s'] / r[f'run_{side}_s']:.2f}x",
                "compile": "–" if compile_s is None else f"{compile_s:.1f} s",
                "cost_ratio": f"{r.get(f'cost_ratio_{side}_max', 1.0):.9f}",
                "kabsch": "–" if kabsch is None else "{:.1e} rad, {:.1e}".format(*kabsch),
                "derivative": f"{r[gradient[side]]:.1e}" if side in gradient else "–",
            }
        )
    return rows


def least_squares_table(data: dict) -> list:
    """The batched solves beside their peers, one row per batch and solver, and the
    derivative checks that have no peer."""
    info, results = data["machine"], data["results"]
    rows = [row for r in results if "problems" in r for row in _least_squares_rows(r)]
    notes = [
        f"{r['problem'].capitalize()} ({r['control_points']} control points, {r['samples']} "
        f"samples): derivative error {r['gradient_rel_error_max']:.1e}."
        for r in results
        if "problems" not in r
    ]
    facts = _facts(
        info,
        "jax {jax}, GTSAM {gtsam}, optimistix {optimistix}, {dtype}, commit {commit}, "
        "measured {date}.",
    )
    return _heading(label(info), facts) + _spec(LEAST_SQUARES_COLUMNS, rows) + [""] + notes + [""]


BUNDLE_COLUMNS = """
    problem | l | {problem}
    cameras | r | {cameras:,}
    points | r | {points:,}
    observations | r | {observations:,}
    initial cost | r | {initial_cost:.6g}
    GTSAM final (iterations) | r | {gtsam_cost:.9g} ({gtsam_iterations})
    ours final (iterations) | r | {ours_cost:.9g} ({ours_iterations})
    GTSAM time | r | {gtsam_s!t}
    ours time | r | {ours_s!t}
    ours, first call | r | {ours_cold_s!t}
    ours / GTSAM time | r | {ratio:.2f}
"""


def bundle_adjustment_table(data: dict) -> list:
    """Bundle adjustment beside GTSAM, and the implicit gradient against central differences."""
    info, g = data["machine"], data["implicit_gradient"]
    rows = [
        {**r, "problem": r["problem"].removesuffix(".txt"), "ratio": r["ours_s"] / r["gtsam_s"]}
        for r in data["rows"]
    ]
    kernel = {tuple(r["robust"]) for r in data["rows"]}
    kernels = ", ".join(f"{k.capitalize()} (k = {v:g})" for k, v in sorted(kernel))
    facts = _facts(info, "jax {jax}, GTSAM {gtsam}, {dtype}, commit {commit}, measured {date}.")
    gradient = (
        f"Implicit gradient ({g['problem']}): {g['implicit']:.10g} against the central "
        f"difference {g['central_difference']:.10g} (step {g['step']:g}), relative error "
        f"{g['relative_error']:.1e}."
    )
    return (
        _heading(label(info), f"{facts} Robust kernel: {kernels}.")
        + _spec(BUNDLE_COLUMNS, rows)
        + ["", gradient, ""]
    )


def accuracy_table(data: dict) -> list:
    """An accuracy run's section of the page: a grid per dtype, the notes, Sim(3)'s tables."""
    info = data["machine"]
    facts = (
        f"jax {info.get('jax', '?')}, measured {_date(info)}, {data['samples']} samples per "
        f"regime and translation norm. Worst error in ulp, cells {' / '.join(data['libs'])}; "
        "**bold**: a case over its bound."
    )
    lines = _heading(label(info), facts)
    for dt in DTYPES:
        grid = _accuracy_grid(data, dt)
        if grid:
            lines += [f"**{dt}**", "", *grid, ""]
    for note in data.get("notes", []):
        lines += [note, ""]
    for section in data.get("sections", []):  # Markdown tables accuracy.py renders itself
        lines += [f"**{section['title']}**", "", *section["lines"], ""]
    return lines


def _accuracy_grid(data: dict, dtype: str) -> list:
    """The table of worst errors of one dtype: group × op rows, regime columns."""
    bounds, libs = data["bounds"], data["libs"]
    cells = {
        (c["lib"], c["group"], c["op"], c["regime"]): (
            c["ulp"],
            c.get("over", c["ulp"] is None or not c["ulp"] <= bounds[c["op"]]),
        )
        for c in data["cells"]
        if c["dtype"] == dtype
    }
    if not cells:
        return []
    groups = [g for g in data.get("groups", GROUPS) if any(k[1] == g for k in cells)]

    def cell(g, op, reg):
        vals = [cells.get((lib, g, op, reg)) for lib in libs]
        if all(v is None for v in vals):
            return ""
        texts = [(fmt_ulp(u), over) for u, over in (v or (None, False) for v in vals)]
        return " / ".join(f"**{t}**" if over else t for t, over in texts)

    rows = [(g, op) for g in groups for op in data["ops"]]
    cols = [("group", "l", lambda x: x[0]), ("op", "l", lambda x: data["ops"][x[1]])]
    cols += [(reg["label"], "r", lambda x, k=reg["key"]: cell(*x, k)) for reg in data["regimes"]]
    return _cols(cols, rows)


POSE_GRAPH_COLUMNS = """
    dataset | l | {dataset}
    poses | r | {poses:,}
    edges | r | {edges_text}
    initial cost | r | {initial_cost_gtsam:.4g}
    GTSAM final (iterations) | r | {gtsam_final:.9g} ({gtsam_iterations})
    ours final (iterations) | r | {ours_final_in_gtsam:.9g} ({ours_iterations})
    ours ≤ GTSAM × (1 + 10⁻⁶) | l | {reaches}
    GTSAM time | r | {gtsam_s!t}
    ours time | r | {ours_s!t}
    ours, first call | r | {ours_cold_s!t}
    ours / GTSAM time | r | {time_ratio:.2f}
"""


def pose_graphs_table(data: dict) -> list:
    info, res = data["machine"], data["results"]
    rows = [
        {
            **r,
            "reaches": "yes" if r["reaches_gtsam"] else "**no**",
            "edges_text": f"{r['edges']:,}"
            + (f" + {r['observations']:,} obs." if r.get("observations") else ""),
        }
        for r in res
    ]
    cholmod = info.get("linear_solver", "QDLDL").startswith("CHOLMOD")
    factor = "CHOLMOD through cvxopt {cvxopt}" if cholmod else "QDLDL (qdldl {qdldl})"
    facts = _facts(info, f"jax {{jax}}, GTSAM {{gtsam}}, {factor}, measured {{date}}.")
    per_it = ", ".join(
        f"{r['dataset']} {1e3 * r['gtsam_s'] / max(r['gtsam_iterations'], 1):.3g} / "
        f"{1e3 * r['ours_s'] / max(r['ours_iterations'], 1):.3g} ms"
        for r in res
    )
    lines = _heading(label(info), facts) + _spec(POSE_GRAPH_COLUMNS, rows) + [""]
    return lines + [f"Per iteration, GTSAM / ours: {per_it}.", ""]


SPLINE_FIT_SOLVERS = {"dense": "dense", "banded": "banded", "cholmod": "CHOLMOD", "qdldl": "QDLDL"}


SPLINE_FIT_COLUMNS = """
    control points | r | {control_points:,}
    samples | r | {samples}
    solver | l | {name}
    iterations | r | {iterations}
    warm | r | {warm}
    first call | r | {first}
    peak memory | r | {peak}
    fit's share | r | {share}
"""


def spline_fit_table(data: dict) -> list:
    info, rows = data["machine"], []
    for r in data["results"]:
        row = {**r, "name": SPLINE_FIT_SOLVERS[r["solver"]], "samples": "", "warm": "", "first": ""}
        if "skipped_gb" in r:
            row.update(
                iterations=f"not run: its matrix alone needs {r['skipped_gb']:.1f} GB",
                peak="",
                share="",
            )
        else:
            row.update(
                samples=f"{r['samples']:,}",
                warm=_seconds(r["warm_s"]),
                first=_seconds(r["first_s"]),
                peak=f"{r['peak_gb']:.2f} GB",
                share=f"{r['peak_gb'] - r['before_gb']:.2f} GB",
            )
        rows.append(row)
    facts = _facts(
        info,
        "jax {jax}, SciPy {scipy}, cvxopt {cvxopt}, qdldl {qdldl}, {gb:.0f} GB "
        "available, measured {date}.",
        gb=info.get("memory_available_gb", 0),
    )
    return _heading(label(info), facts) + _spec(SPLINE_FIT_COLUMNS, rows) + [""]


# --------------------------------------------------------------------------------------
# Rendered copies: the figures that the README and the guides show, from the same raw files
# --------------------------------------------------------------------------------------

#: The files outside this folder that hold rendered blocks, relative to the repository root.
COPIES = ("README.md", "docs/speed.md", "docs/accuracy.md")
_BLOCK = re.compile(
    r"(<!-- rendered by benchmarks/report\.py: ([\w-]+) -->\n)(.*?)"
    r"(<!-- end of rendered block -->)",
    re.S,
)
_SUMMARY_ROWS = (
    ("exp", "SE3 exp"),
    ("log", "SE3 log"),
    ("compose", "SE3 compose"),
    ("apply", "SE3 apply"),
    ("interpolate", "SE3 interpolate"),
    ("grad", "SE3 gradient through exp, log, compose"),
)
_README_ROWS = ("exp", "log", "interpolate")
_COMPILE_ROWS = [(g, o) for g in ("SO3", "SE3") for o in ("exp", "log", "interpolate", "grad")]
#: The accuracy regimes of the README's summary: 0 to π, every translation norm.
_BELOW_PI = ("zero", "tiny", "small", "mid", "near_pi")


def _summary_table(f32: dict, f64: dict | None, ops: tuple) -> list:
    """Speed-ups of the chosen SE3 rows and the geometric mean over every group and op, per
    batch size of the float32 run, plus the float64 run's largest size when given."""
    columns = [(f32, n, f"N = {pretty_n(n)}") for n in C.sizes(f32)]
    if f64 is not None:
        n = C.sizes(f64)[-1]
        columns.append((f64, n, f"N = {pretty_n(n)}, float64"))

    def ratio(data, op, n):
        r = [r for r in data["results"] if (r["group"], r["op"], r["n"]) == ("SE3", op, n)]
        return C.fmt_ratio(r[0]["ratio"]) if r else ""

    body = [
        [name] + [ratio(d, o, n) for d, n, _ in columns] for o, name in _SUMMARY_ROWS if o in ops
    ]
    body.append(
        ["all groups and ops, geometric mean"] + [_mean(d, n, C.fmt_ratio) for d, n, _ in columns]
    )
    return table([""] + [h for _, _, h in columns], body, "l" + "r" * len(columns))


def _where(info: dict) -> str:
    return f"{label(info)}, jax {info.get('jax', '?')}"


def excerpts(raw: dict) -> dict:
    """Each rendered block's Markdown, by name; empty when its raw file is missing."""
    order = machine_order(raw)
    runs = {k: d for m in order[:1] for k, d in raw[m].items()}
    f32, f64 = runs.get("speed-float32"), runs.get("speed-float64")
    blocks = {}
    if f32:
        where, top = _where(f32["machine"]), C.sizes(f32)[-1]
        blocks["readme-speed"] = [
            "Speed-up over jaxlie (jaxlie time / jaxlie_geo time, both under `jax.jit`; "
            f"{where}, float32; [more](docs/speed.md)):",
            "",
            *_summary_table(f32, None, _README_ROWS),
        ]
        head = (
            f"{where}; float32, and float64 at {pretty_n(C.sizes(f64)[-1])}:"
            if f64
            else f"{where}; float32:"
        )
        blocks["speed-summary"] = [
            head,
            "",
            *_summary_table(f32, f64, tuple(o for o, _ in _SUMMARY_ROWS)),
        ]
        blocks["speed-slower"] = [
            f"- {r['group']} {r['op']} at {_n_at(r['n'])}, {_dtype(d)}: {r['ratio']:.2f}"
            for d in (f32, f64)
            if d
            for r in sorted(d["results"], key=lambda r: r["ratio"])
            if _slower(r)
        ] or ["- none in these runs"]
        by = {(r["group"], r["op"]): r for r in f32["results"] if r["n"] == top}
        rows = [
            [f"{g} {o}", f"{by[g, o]['compile_ours_ms']:.0f}", f"{by[g, o]['compile_ref_ms']:.0f}"]
            for g, o in _COMPILE_ROWS
            if (g, o) in by
        ]
        blocks["speed-compile"] = [
            f"At {pretty_n(top)} in float32, in ms ({where}):",
            "",
            *table(["", "jaxlie_geo", "jaxlie"], rows, "lrr"),
        ]
        memory = f32.get("memory")
        if memory:
            blocks["speed-memory"] = [
                f"SE3 operations at N = {pretty_n_pow2(memory[0]['n'])}, float32, MB "
                f"({where}; compiled, not run):",
                "",
                *memory_table(memory),
            ]
    jac = runs.get("jacobians-float32")
    if jac:
        ratios = [r["ratio"] for r in jac["results"]]
        n = max(r["n"] for r in jac["results"])
        blocks["speed-jacobians"] = [
            f"At {pretty_n(n)} elements in float32 ({_where(jac['machine'])}) the closed forms run "
            f"{min(ratios):.1f}x–{max(ratios):.0f}x faster than `jax.jacfwd`, "
            f"{geomean(ratios):.1f}x in geometric mean over {len(ratios)} Jacobians."
        ]
    acc = runs.get("accuracy")
    if acc:
        blocks["readme-accuracy"] = _accuracy_summary(acc)
        for dt in DTYPES:
            blocks[f"accuracy-{dt}"] = [
                f"**{dt}** (cells: jaxlie_geo / jaxlie; {_where(acc['machine'])}, measured "
                f"{_date(acc['machine'])})",
                "",
                *_accuracy_grid(acc, dt),
            ]
        for i, section in enumerate(acc.get("sections", [])):
            blocks[f"accuracy-section-{i + 1}"] = [f"**{section['title']}**", "", *section["lines"]]
    return {k: "\n".join(v) + "\n" for k, v in blocks.items()}


def _accuracy_summary(data: dict) -> list:
    """Worst error of each library over jaxlie's four groups, angles 0 to π."""
    rows = (
        (("exp", "log"), "exp, log"),
        (("jac",), "d log(exp x)/dx"),
        (("hess",), "d² log(exp x)/dx²"),
    )
    sides = [(lib, dt) for dt in DTYPES for lib in data["libs"]]

    def worst(side, ops):
        vals = [
            c["ulp"]
            for c in data["cells"]
            if (c["lib"], c["dtype"]) == side
            and c["op"] in ops
            and c["regime"] in _BELOW_PI
            and c["group"] in GROUPS
            and c["ulp"] is not None
        ]
        return fmt_ulp(max(vals)) if vals else ""

    body = [[name] + [worst(s, ops) for s in sides] for ops, name in rows]
    return table([""] + [f"{lib}, {dt}" for lib, dt in sides], body, "l" + "r" * len(sides))


def render_copy(text: str, blocks: dict, name: str = "") -> str:
    """``text`` with every rendered block replaced by its current Markdown."""

    def fill(m: re.Match) -> str:
        if m[2] not in blocks:
            raise KeyError(f"{name}: no rendered block named {m[2]!r} (known: {sorted(blocks)})")
        return m[1] + blocks[m[2]] + m[4]

    return _BLOCK.sub(fill, text)


def stale_copies(raw: dict, root: Path = C.REPO_ROOT, write: bool = False) -> list:
    """The copies whose rendered blocks differ from what ``raw`` renders to; rewritten when
    ``write``."""
    blocks, stale = excerpts(raw), []
    for rel in COPIES:
        path = root / rel
        text = path.read_text(encoding="utf-8")
        new = render_copy(text, blocks, rel)
        if new != text:
            stale.append(rel)
            if write:
                path.write_text(new, encoding="utf-8")
    return stale


#: Each section of the page below the machines: (one raw file per dtype, its renderer).
SECTIONS = {
    "speed": (True, speed_table),
    "jacobians": (True, jacobians_table),
    "extended-groups": (True, extended_groups_table),
    "matrix-ops": (False, matrix_ops_table),
    "kernel-sizes": (False, kernel_sizes_table),
    "ik-program": (False, ik_program_table),
    "splines": (True, splines_table),
    "pose-graphs": (False, pose_graphs_table),
    "spline-fit": (False, spline_fit_table),
    "least-squares": (False, least_squares_table),
    "bundle-adjustment": (False, bundle_adjustment_table),
    "accuracy": (False, accuracy_table),
}


def render(raw: dict, plot_name: str | None) -> str:
    """The page's Markdown for the raw results ``raw`` (see ``common.load``)."""
    order = machine_order(raw)
    lines = TEXT["intro"].splitlines() + [""] + summary_section(raw, order)
    runs = plotted_runs(raw, order)
    if plot_name and runs:
        name = label(runs[0]["machine"])
        lines += [
            f"![Speed-up over jaxlie by group, operation and batch size, {name}]({plot_name})",
            "",
            f"*The plot: {name}; float32 filled, float64 hollow; bars are the IQR.*",
            "",
        ]
    lines += TEXT["method"].splitlines() + [""] + machines_section(raw, order)
    for kind, (by_dtype, render_one) in SECTIONS.items():
        found = _runs(raw, order, kind, by_dtype)
        if found:
            lines += TEXT[kind].splitlines() + [""]
            lines += [line for data in found for line in render_one(data)]
            if f"{kind}-end" in TEXT:
                lines += TEXT[f"{kind}-end"].splitlines() + [""]
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


def write_page(raw_dir: Path = C.RAW_DIR, page: Path = C.PAGE, plot: bool = True) -> None:
    """Render ``page`` (and the figures beside it) from the raw files in ``raw_dir``."""
    raw = C.load(raw_dir)
    order = machine_order(raw)
    runs = plotted_runs(raw, order)
    if plot and runs:
        try:
            from benchmarks import plot as _plot  # matplotlib is optional
        except ImportError as e:
            print(f"plot not redrawn ({e})", file=sys.stderr)
        else:
            _plot.plot(runs, page.parent / PLOT_NAME)
            graphs = _runs(raw, order, "pose-graphs")
            if graphs:
                machine = label(graphs[0]["machine"])
                _plot.plot_pose_graphs(graphs[0], page.parent / POSE_GRAPH_PLOT, machine)
    page.write_text(render(raw, PLOT_NAME), encoding="utf-8")
    print(f"wrote {page}")
    if raw_dir == C.RAW_DIR and page == C.PAGE:
        for rel in stale_copies(raw, write=True):
            print(f"wrote {rel}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--raw-dir", type=Path, default=C.RAW_DIR, help="raw results (default: %(default)s)"
    )
    ap.add_argument(
        "--page", type=Path, default=C.PAGE, help="page to write (default: %(default)s)"
    )
    ap.add_argument("--no-plot", action="store_true", help="leave the figures as they are")
    ap.add_argument(
        "--plot", type=Path, metavar="PNG", help="draw only the speed-up figure into PNG"
    )
    ap.add_argument("files", nargs="*", type=Path, help="raw speed-*.json files, for --plot")
    ap.add_argument("--check", action="store_true", help="write nothing; exit 1 if stale")
    args = ap.parse_args(argv)
    raw = C.load(args.raw_dir)
    if args.plot:
        from benchmarks import plot as _plot  # needs matplotlib

        runs = [C.read_json(f) for f in args.files] or plotted_runs(raw, machine_order(raw))
        _plot.plot(runs, args.plot)
        return 0
    if not args.check:
        write_page(args.raw_dir, args.page, plot=not args.no_plot)
        return 0
    current = args.page.read_text(encoding="utf-8") if args.page.exists() else ""
    stale = [str(args.page)] if render(raw, PLOT_NAME) != current else []
    stale += stale_copies(raw) if args.raw_dir == C.RAW_DIR else []
    if stale:
        print(f"out of date: {', '.join(stale)}: run python -m benchmarks.report", file=sys.stderr)
        return 1
    print(f"{args.page} and the rendered blocks of {', '.join(COPIES)} are up to date")
    return 0


if __name__ == "__main__":
    sys.exit(main())
