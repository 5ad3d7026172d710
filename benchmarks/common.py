"""What every benchmark script shares: the machine facts a run records, the labels and
tables it prints, one timing harness, the common command-line options and the raw files.

A leaf of the package: it imports none of the other modules (and jax only inside the
functions that time or describe a run). A script builds its cases, times each with
``compare`` (or ``measure``), and hands its results to ``report.save``, which writes the raw
file (``write_raw``) and re-renders the page from every raw file.
"""

from __future__ import annotations

import argparse
import datetime
import importlib
import importlib.metadata
import json
import math
import os
import platform
import re
import statistics
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO_ROOT = HERE.parent
RAW_DIR = HERE / "raw"
PAGE = HERE / "RESULTS.md"

#: The groups and operations timed against jaxlie, in the order of the page and the plot.
GROUPS = ("SO2", "SE2", "SO3", "SE3")
OPS = ("exp", "log", "compose", "apply", "inverse", "interpolate", "grad")
#: Every group, and the operations of ``matrix_ops.py`` and ``kernel_sizes.py``, in order.
ALL_GROUPS = ("SO2", "SE2", "SO3", "SE3", "Sim3", "SE23")
MATRIX_OPS = (
    "jac_right",
    "jac_right_inv",
    "jlog",
    "adjoint",
    "grad",
    "from_matrix",
    "from_matrix_project",
)
KERNEL_OPS = ("exp", "log", "jac_right", "jac_right_inv", "jlog", "grad", "from_matrix")


# --------------------------------------------------------------------------------------
# Machine facts
# --------------------------------------------------------------------------------------


def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def version_of(dist: str) -> str:
    try:
        return importlib.metadata.version(dist)
    except importlib.metadata.PackageNotFoundError:
        return "not installed"


#: What the scripts themselves write: a tree that differs from its commit only there is clean.
RESULT_FILES = (
    "benchmarks/raw/",
    "benchmarks/RESULTS.md",
    "benchmarks/results.png",
    "benchmarks/pose_graphs.png",
)


def _git(*args: str) -> str:
    try:
        out = subprocess.run(
            ["git", "-C", str(REPO_ROOT), *args], capture_output=True, text=True, timeout=10
        )
    except (OSError, subprocess.SubprocessError):
        return ""
    return out.stdout


def dirty_files() -> list:
    """The tracked files that differ from the commit (``git status``), so that a page
    rendered from a run of a modified tree says which files differed. The benchmark results
    (``RESULT_FILES``) are not counted: one script's run may follow another's ``--save``."""
    lines = _git("status", "--porcelain", "--untracked-files=no").splitlines()
    files = (line[3:].strip() for line in lines if line.strip())
    return sorted(f for f in files if not f.startswith(RESULT_FILES))


def git_commit() -> str:
    """The checkout's commit, with ``-dirty`` when ``dirty_files`` names any file."""
    commit = _git("rev-parse", "--short=7", "HEAD").strip()
    if not commit:
        return "unknown"
    return commit + "-dirty" if dirty_files() else commit


def machine_info(module: str, **run) -> dict:
    """The machine and the versions a run used (the ``machine`` entry of a raw file), then
    the run's own fields (dtype, ...) and its command line (``python -m <module> ...``)."""
    import jax

    try:
        affinity: int | None = len(os.sched_getaffinity(0))
    except AttributeError:  # macOS, Windows
        affinity = os.cpu_count()
    geo = importlib.import_module("jaxlie_geo")
    return {
        "date": datetime.datetime.now().astimezone().strftime("%Y-%m-%d %H:%M %Z"),
        "cpu": cpu_model(),
        "cores": os.cpu_count(),
        "cores_usable": affinity,
        "platform": platform.platform(),
        "python": platform.python_version(),
        "jax": version_of("jax"),
        "jaxlib": version_of("jaxlib"),
        "jaxlie": version_of("jaxlie"),
        "jaxlie_geo": getattr(geo, "__version__", version_of("jaxlie_geo")),
        "commit": git_commit(),
        "dirty_files": dirty_files(),
        "numpy": version_of("numpy"),
        "backend": jax.default_backend(),
        "devices": ", ".join(str(d) for d in jax.devices()),
        "device_kind": jax.devices()[0].device_kind,
        **run,
        "command": " ".join(["python", "-m", module, *sys.argv[1:]]),
    }


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


def cpu_name(info: dict) -> str:
    cpu = re.sub(r"\((R|TM)\)|\bProcessor\b|\bCPU\b", "", info.get("cpu", "CPU"))
    return re.sub(r"\s+", " ", cpu).strip()


def label(info: dict) -> str:
    """Short human name of a machine: CPU model and cores, or the GPU model."""
    if info.get("backend", "cpu") != "cpu":
        return info.get("device_kind", info["backend"].upper())
    used, total = info.get("cores_usable"), info.get("cores")
    cores = f"{used} cores" if used == total else f"{used} of {total} cores"
    return f"{cpu_name(info)}, {cores}"


# --------------------------------------------------------------------------------------
# Labels and tables
# --------------------------------------------------------------------------------------

SUPERSCRIPT = str.maketrans("0123456789-", "⁰¹²³⁴⁵⁶⁷⁸⁹⁻")


def fmt_ns(x: float) -> str:
    """A time in ns with its unit, three significant digits."""
    for scale, unit in ((1e6, "ms"), (1e3, "µs")):
        if x >= scale:
            return f"{x / scale:.2f} {unit}"
    if x >= 1:
        return f"{plain_ns(x)} ns"
    return f"{x:.3g} ns"  # a GPU at 10^6: 0.1 ns/element needs three significant digits


def plain_ns(x: float) -> str:
    """A time in ns, three significant digits, without unit (the unit is in a header)."""
    return f"{x:.0f}" if x >= 100 else f"{x:.1f}" if x >= 10 else f"{x:.2f}"


def pretty_n(n: int) -> str:
    """A batch size, as 10³ when it is a power of ten from 1000 up."""
    e = round(math.log10(n)) if n > 0 else 0
    return "10" + str(e).translate(SUPERSCRIPT) if n >= 1000 and n == 10**e else str(n)


def fmt_ratio(x: float) -> str:
    """A speed-up as the pages print it: three significant digits (two decimals below 10)."""
    return f"{x:.2f}" if x < 10 else f"{x:.1f}" if x < 100 else f"{x:.0f}"


def sizes(data: dict) -> list:
    """The batch sizes of a run's results, ascending."""
    return sorted({r["n"] for r in data["results"]})


def geomean(xs) -> float:
    xs = [x for x in xs if x > 0]
    return math.exp(sum(math.log(x) for x in xs) / len(xs)) if xs else float("nan")


def table(header, rows, align) -> list:
    """Markdown table lines; ``align`` is one of "l"/"r" per column."""
    out = ["| " + " | ".join(header) + " |"]
    out.append("|" + "|".join("---" if a == "l" else "--:" for a in align) + "|")
    return out + ["| " + " | ".join(r) + " |" for r in rows]


# --------------------------------------------------------------------------------------
# Timing
# --------------------------------------------------------------------------------------


def compile_fn(fn, args):
    """Trace + lower + compile; returns (compiled, seconds)."""
    import jax

    t0 = time.perf_counter()
    compiled = jax.jit(fn).lower(*args).compile()
    return compiled, time.perf_counter() - t0


def run_n(fn, args, n: int) -> float:
    """Mean seconds per call over n calls, each blocking until its result is ready."""
    import jax

    t0 = time.perf_counter()
    for _ in range(n):
        jax.block_until_ready(fn(*args))
    return (time.perf_counter() - t0) / n


def measure(sides, repeats=None, target_s=0.01, budget_s=1.5, min_repeats=3) -> list:
    """Interleaved timing of (fn, args, seconds of a call already made) sides; returns the
    seconds per call of each side, one entry per repetition. Repetition i runs the sides in
    order for even i, reversed for odd i, so that a drift of the machine hits all alike.
    A measurement lasts about ``target_s``, or a tenth of the slowest side's call (up to
    1 s), or one call; a fast side is timed again over more calls to size it.
    ``repeats=None`` chooses from ``min_repeats`` (2 beside a call over 5 s) to 25 within
    ``budget_s``."""
    target_s = max(target_s, min(1.0, 0.1 * max(first for _, _, first in sides)))
    plan = []
    for fn, args, first in sides:
        t = first
        if t < target_s / 10:
            t = run_n(fn, args, max(1, min(1000, int(target_s / 10 / max(t, 1e-9)))))
        plan.append((fn, args, max(1, round(target_s / max(t, 1e-9))), t))
    if repeats is None:
        one = sum(k * t for *_, k, t in plan)
        least = min(min_repeats, 2) if max(t for *_, t in plan) > 5.0 else min_repeats
        repeats = int(min(25, max(least, budget_s / max(one, 1e-9))))
    times: list = [[] for _ in sides]
    for i in range(repeats):
        for j in range(len(plan)) if i % 2 == 0 else reversed(range(len(plan))):
            fn, args, k, _ = plan[j]
            times[j].append(run_n(fn, args, k))
    return times


def timed_call(fn, args):
    """(output, seconds) of one blocking call."""
    import jax

    t0 = time.perf_counter()
    out = jax.block_until_ready(fn(*args))
    return out, time.perf_counter() - t0


def paired_stats(t_a, t_b) -> dict:
    """The ratio b/a of two interleaved series as the median of the same-repetition ratios
    (robust to slow drift of the machine), with its quartiles."""
    paired = sorted(b / a for a, b in zip(t_a, t_b))
    q = statistics.quantiles(paired, n=4, method="inclusive") if len(paired) > 1 else paired * 3
    return {"ratio": statistics.median(paired), "ratio_q1": q[0], "ratio_q3": q[2]}


def available_bytes() -> int | None:
    """MemAvailable from /proc/meminfo, or None where there is none."""
    try:
        with open("/proc/meminfo") as f:
            line = next(x for x in f if x.startswith("MemAvailable:"))
        return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError, StopIteration):
        return None


def footprint_bytes(compiled) -> int:
    """Arguments, output and temporaries of a compiled program (XLA's buffer assignment)."""
    m = compiled.memory_analysis()
    return m.argument_size_in_bytes + m.output_size_in_bytes + m.temp_size_in_bytes


def compare(sides, n: int, args, index: int = 0, min_repeats: int = 3, budget_s: float = 1.5):
    """Time ``sides``, ``[(fn, inputs), ...]`` (ours first, then the references; a reference
    may be ``(None, None)``, absent), on a batch of ``n``: each compiled ahead (the order
    alternating with ``index``), a side whose program would take over 80% of the available
    memory compiled but not run, a warm call whose output is returned, then ``measure``.
    Returns (the record, the outputs, None for a side not run). The record holds per side
    ``<side>_ns_per_elem`` (median), ``compile_<side>_ms``, ``memory_<side>_mb`` and
    ``<side>_note`` (why it did not run), sides named ``ours`` and ``ref``; and ``ratio``,
    ``ratio_q1``, ``ratio_q3`` of ref / ours where both ran."""
    names = ("ours", "ref")
    order = range(len(sides)) if index % 2 == 0 else reversed(range(len(sides)))
    compiled: dict = {}
    for j in order:
        fn, inputs = sides[j]
        if fn is not None:
            compiled[j] = compile_fn(fn, inputs)
    rec: dict = {}
    timed, outs = [], [None] * len(sides)
    for j, (fn, inputs) in enumerate(sides):
        side = names[j]
        rec.update({f"{side}_ns_per_elem": None, f"compile_{side}_ms": None})
        rec.update({f"memory_{side}_mb": None, f"{side}_note": None})
        if fn is None:
            continue
        c, seconds = compiled[j]
        mem, avail = footprint_bytes(c), available_bytes()
        rec[f"compile_{side}_ms"], rec[f"memory_{side}_mb"] = seconds * 1e3, mem / 1e6
        if avail is not None and mem > 0.8 * avail:
            rec[f"{side}_note"] = (
                f"not run: needs {mem / 1e9:.1f} GB, {avail / 1e9:.1f} GB available"
            )
            continue
        outs[j], first = timed_call(c, inputs)
        timed.append((j, (c, inputs, first)))
    quick = getattr(args, "quick", False)
    repeats = 3 if quick and args.repeats is None else args.repeats
    times = (
        measure(
            [s for _, s in timed],
            repeats,
            0.002 if quick else 0.01,
            0.1 if quick else budget_s,
            min_repeats,
        )
        if timed
        else []
    )
    for (j, _), t in zip(timed, times):
        rec[f"{names[j]}_ns_per_elem"] = statistics.median(t) * 1e9 / n
    rec["repeats"] = len(times[0]) if times else 0
    rec.update(ratio=None, ratio_q1=None, ratio_q3=None)
    if len(timed) == 2:
        rec.update(paired_stats(times[0], times[1]))
    return rec, outs


def max_rel_diff(x, y) -> float:
    """max |x − y| / (1 + |y|) over the leaves of two pytrees; a non-finite difference or a
    different shape counts as inf."""
    import jax
    import numpy as np

    worst = 0.0
    for a, b in zip(jax.tree_util.tree_leaves(x), jax.tree_util.tree_leaves(y)):
        a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
        if a.shape != b.shape:
            return float("inf")
        d = np.abs(a - b) / (1.0 + np.abs(b))
        worst = max(worst, float(np.max(np.where(np.isfinite(d), d, np.inf))) if d.size else 0.0)
    return worst


# --------------------------------------------------------------------------------------
# Command line and raw result files
# --------------------------------------------------------------------------------------


def parser(doc: str, sizes=None, quick=None, **choices) -> argparse.ArgumentParser:
    """The options every script has: the saving options, and with ``sizes`` (the default
    batch sizes, comma-separated) ``--sizes``, ``--quick`` (``quick``'s sizes, 3 repeats),
    ``--repeats``, ``--dtype`` and ``--seed``; one comma-separated option per entry of
    ``choices`` (``groups=GROUPS``: ``--groups``, a subset). ``parse`` reads it."""
    p = argparse.ArgumentParser(
        prog="python -m benchmarks." + Path(sys.argv[0]).stem, description=doc.split("\n\n")[0]
    )
    p.set_defaults(_choices=choices, _sizes=sizes, _quick=quick)
    if sizes is not None:
        p.add_argument("--sizes", default=None, help=f"batch sizes (default {sizes})")
        p.add_argument("--quick", action="store_true", help=f"sizes {quick}, 3 repeats")
        p.add_argument("--repeats", type=int, default=None, help="repetitions (default: automatic)")
        p.add_argument("--dtype", choices=("float32", "float64"), default="float32")
        p.add_argument("--seed", type=int, default=0)
    for name, options in choices.items():
        p.add_argument(
            f"--{name}", default=",".join(map(str, options)), help="a subset of %(default)s"
        )
    p.add_argument(
        "--json", default=None, metavar="PATH", help="also write the raw results to PATH"
    )
    p.add_argument(
        "--save", action="store_true", help="write raw/<machine>/ and regenerate the page"
    )
    p.add_argument(
        "--machine", default=None, help="machine name for --save (default: from the hardware)"
    )
    p.add_argument("--note", default=None, help="a sentence about the machine for the page")
    p.add_argument(
        "--raw-dir", type=Path, default=RAW_DIR, help="raw results folder (default: %(default)s)"
    )
    p.add_argument(
        "--page", type=Path, default=PAGE, help="results page to regenerate (default: %(default)s)"
    )
    return p


def add_save_arguments(p: argparse.ArgumentParser) -> None:
    """``--json``, ``--save`` and where ``--save`` writes (``--machine``, ``--note``,
    ``--raw-dir``, ``--page``), on a parser of the script's own."""
    for action in parser("")._actions:
        if action.dest in ("json", "save", "machine", "note", "raw_dir", "page"):
            p._add_action(action)


def parse(p: argparse.ArgumentParser, argv=None) -> argparse.Namespace:
    """Parse ``parser``'s options: ``sizes`` and each of the ``choices`` become lists (a
    choice matched without regard to case); x64 is turned on for ``--dtype float64``."""
    args = p.parse_args(argv)
    if args._sizes is not None:
        text = args.sizes or (args._quick if args.quick else args._sizes)
        args.sizes = [int(float(s)) for s in text.split(",") if s.strip()]
        if any(n < 1 for n in args.sizes):
            p.error("sizes must be >= 1")
        if args.dtype == "float64":
            importlib.import_module("jax").config.update("jax_enable_x64", True)
    for name, options in args._choices.items():
        by_name = {str(o).lower(): o for o in options}
        picked = [x.strip().lower() for x in getattr(args, name).split(",") if x.strip()]
        for x in picked:
            if x not in by_name:
                p.error(f"unknown {name[:-1]} {x!r}; choose from {tuple(options)}")
        setattr(args, name, [by_name[x] for x in picked])
    return args


def read_json(path: Path) -> dict:
    return json.loads(Path(path).read_text(encoding="utf-8"))


def write_json(path: Path, data: dict) -> None:
    Path(path).write_text(json.dumps(data, indent=1, ensure_ascii=False) + "\n", encoding="utf-8")


def write_raw(kind: str, data: dict, args) -> Path | None:
    """Write ``data`` to ``--json`` if given, and with ``--save`` to
    ``<raw-dir>/<machine>/<kind>.json`` (the machine's note kept); returns the raw file's path,
    or None without ``--save``."""
    if getattr(args, "json", None):
        write_json(args.json, data)
    if not args.save:
        return None
    path = Path(args.raw_dir) / (args.machine or machine_name(data["machine"])) / f"{kind}.json"
    note = args.note
    if note is None:
        saved = [read_json(f)["machine"] for f in sorted(path.parent.glob("*.json"))]
        note = next((m["note"] for m in saved if m.get("note")), None)
    if note:
        data["machine"]["note"] = note
    path.parent.mkdir(parents=True, exist_ok=True)
    write_json(path, data)
    print(f"wrote {path}")
    return path


def load(raw_dir: Path) -> dict:
    """{machine: {kind: data}} for every raw file."""
    raw: dict = {}
    for path in sorted(Path(raw_dir).glob("*/*.json")):
        raw.setdefault(path.parent.name, {})[path.stem] = read_json(path)
    return raw
