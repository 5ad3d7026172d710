"""What every benchmark script shares: the machine facts a run records, the labels and tables
it prints, its timing loop, its common command-line options and its raw result files.

A leaf of the package: it imports nothing of the other modules (and jax only inside the
functions that time or describe a run). A script measures, prints with the labels here and
hands its results to ``report.save``, which writes the raw file (``write_raw``) and
re-renders the page from every raw file.
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

#: The operations of ``matrix_ops.py`` and of ``kernel_sizes.py``, in the page's order (the
#: scripts and ``report.py`` read them from here).
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

#: jaxlie's layouts: tangent dimension, the tangent's rotation slice, the dimension of the
#: space acted on and the quaternion slice of the parameters.
GROUP_INFO = {
    "SO2": dict(tangent_dim=1, rot=slice(0, 1), space_dim=2, quat=None),
    "SE2": dict(tangent_dim=3, rot=slice(2, 3), space_dim=2, quat=None),
    "SO3": dict(tangent_dim=3, rot=slice(0, 3), space_dim=3, quat=slice(0, 4)),
    "SE3": dict(tangent_dim=6, rot=slice(3, 6), space_dim=3, quat=slice(0, 4)),
}


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
RESULT_FILES = ("benchmarks/raw/", "benchmarks/RESULTS.md", "benchmarks/results.png",
                "benchmarks/pose_graphs.png")  # fmt: skip


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


def plain_ns(x: float) -> str:
    """A time in ns, three significant digits, without unit (the unit is in a header)."""
    return f"{x:.0f}" if x >= 100 else f"{x:.1f}" if x >= 10 else f"{x:.2f}"


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


def fmt_ratio(x: float) -> str:
    """A speed-up as the pages print it: three significant digits (two decimals below 10)."""
    return f"{x:.2f}" if x < 10 else f"{x:.1f}" if x < 100 else f"{x:.0f}"


def progress_text(r: dict) -> str:
    """One measured case on one line, as the scripts print it while they run."""
    ours, ref = r.get("ours_ns_per_elem"), r.get("ref_ns_per_elem")
    text = f"ours {fmt_ns(ours) if ours is not None else 'not run'}"
    if ref is not None:
        text += f", reference {fmt_ns(ref)}"
    if r.get("ratio") is not None:
        text += f", speed-up {r['ratio']:.2f} [{r['ratio_q1']:.2f}–{r['ratio_q3']:.2f}]"
    compile_ref = r.get("compile_ref_ms")
    text += f", compile {r['compile_ours_ms']:.0f}" + (
        f"/{compile_ref:.0f} ms" if compile_ref is not None else " ms"
    )
    if r.get("max_rel_diff") is not None:
        text += f", max rel diff {r['max_rel_diff']:.1e}"
    return text


def sizes(data: dict) -> list:
    """The batch sizes of a run's results, ascending."""
    return sorted({r["n"] for r in data["results"]})


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


def compile_fn(fn, args):
    """Trace + lower + compile; returns (compiled, seconds)."""
    import jax

    t0 = time.perf_counter()
    compiled = jax.jit(fn).lower(*args).compile()
    return compiled, time.perf_counter() - t0


def run_n(fn, args, n: int) -> float:
    """Mean seconds per call over n blocking calls."""
    import jax

    bur = jax.block_until_ready
    t0 = time.perf_counter()
    for _ in range(n):
        bur(fn(*args))
    return (time.perf_counter() - t0) / n


def timed_call(fn, args):
    """(output, seconds) of one blocking call."""
    import jax

    t0 = time.perf_counter()
    out = jax.block_until_ready(fn(*args))
    return out, time.perf_counter() - t0


def calls_per_measurement(fn, args, first_s: float, target_s: float):
    """(calls so that one measurement lasts about target_s, seconds per call). ``first_s``
    is the time of a call already made; a fast function is timed again over more calls."""
    t = first_s
    if t < target_s / 10:
        t = run_n(fn, args, max(1, min(1000, int(target_s / 10 / max(t, 1e-9)))))
    return max(1, int(round(target_s / max(t, 1e-9)))), t


def calibrate(fn, args, target_s: float) -> int:
    """Number of calls so that one measurement lasts about target_s."""
    return calls_per_measurement(fn, args, run_n(fn, args, 1), target_s)[0]


def _alternate(sides, repeats: int) -> list:
    """Seconds per call of each (fn, args, calls) side, one entry per repetition; repetition
    i runs the sides in order for even i, reversed for odd i, so that a drift of the machine
    hits all alike."""
    times: list = [[] for _ in sides]
    for i in range(repeats):
        order = range(len(sides)) if i % 2 == 0 else reversed(range(len(sides)))
        for j in order:
            fn, args, calls = sides[j]
            times[j].append(run_n(fn, args, calls))
    return times


def interleaved(fn_a, fn_b, args, repeats, target_s, budget_s, min_repeats=7):
    """Interleaved timing of two functions of the same arguments, each measurement about
    ``target_s`` long; returns (seconds per call of A, of B), one entry per repetition.
    ``repeats=None`` chooses from ``min_repeats`` to 25 repetitions within ``budget_s``."""
    n_a = calibrate(fn_a, args, target_s)
    n_b = calibrate(fn_b, args, target_s)
    if repeats is None:
        one = run_n(fn_a, args, n_a) * n_a + run_n(fn_b, args, n_b) * n_b
        repeats = int(min(25, max(min_repeats, budget_s / max(one, 1e-9))))
    t_a, t_b = _alternate([(fn_a, args, n_a), (fn_b, args, n_b)], repeats)
    return t_a, t_b


#: A side slower than this per call lowers ``measure``'s minimum to 2 repetitions.
SLOW_CALL_S = 5.0


def measure(sides, repeats, target_s, budget_s, min_repeats):
    """Interleaved timing of one or more (fn, args, first call's seconds) sides whose calls
    may take seconds (a matrix reference beside our kernel); returns the seconds per call of
    each side, one entry per repetition. Beside a slow side, a measurement lasts a tenth of
    its call (up to 1 s), so that a fast side's is not a single short call; ``repeats=None``
    chooses from ``min_repeats`` (2 beside a side over ``SLOW_CALL_S``) to 25 repetitions
    within ``budget_s``."""
    target_s = max(target_s, min(1.0, 0.1 * max(first for _, _, first in sides)))
    plan = [calls_per_measurement(fn, args, first, target_s) for fn, args, first in sides]
    if repeats is None:
        one = sum(k * t for k, t in plan)
        if max(t for _, t in plan) > SLOW_CALL_S:
            min_repeats = min(min_repeats, 2)
        repeats = int(min(25, max(min_repeats, budget_s / max(one, 1e-9))))
    return _alternate([(fn, args, k) for (fn, args, _), (k, _) in zip(sides, plan)], repeats)


def quantiles(xs):
    """First and third quartiles."""
    xs = sorted(xs)
    if len(xs) == 1:
        return xs[0], xs[0]
    q = statistics.quantiles(xs, n=4, method="inclusive")
    return q[0], q[2]


def paired_stats(t_a, t_b) -> dict:
    """Medians of two interleaved timing series and the ratio b/a as the median of the paired
    (same-repetition) ratios, robust to slow drift of the machine, with its quartiles."""
    paired = [b / a for a, b in zip(t_a, t_b)]
    q1, q3 = quantiles(paired)
    return {
        "median_a": statistics.median(t_a),
        "median_b": statistics.median(t_b),
        "ratio": statistics.median(paired),
        "ratio_q1": q1,
        "ratio_q3": q3,
    }


def available_bytes():
    """MemAvailable from /proc/meminfo, or None where there is none."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def footprint_bytes(compiled) -> int:
    """Arguments, output and temporaries of a compiled program (XLA's buffer assignment)."""
    m = compiled.memory_analysis()
    return m.argument_size_in_bytes + m.output_size_in_bytes + m.temp_size_in_bytes


# --------------------------------------------------------------------------------------
# Command line
# --------------------------------------------------------------------------------------


def parse_sizes(p, text: str) -> list:
    """Comma-separated batch sizes ("1,1e3") -> ints >= 1 (argparse error otherwise)."""
    sizes = [int(float(s)) for s in text.split(",") if s.strip()]
    if any(n < 1 for n in sizes):
        p.error("sizes must be >= 1")
    return sizes


def parse_choices(p, text: str, choices, what: str) -> list:
    """Comma-separated names, matched to ``choices`` without regard to case."""
    by_name = {str(c).lower(): c for c in choices}
    items = [by_name.get(x.strip().lower(), x.strip()) for x in text.split(",") if x.strip()]
    for x in items:
        if x not in choices:
            p.error(f"unknown {what} {x!r}; choose from {tuple(choices)}")
    return items


def parser(description: str, choices: dict, sizes, quick: str, min_repeats: int, sizes_text=None):
    """An argument parser with the options of the timing scripts: ``--sizes``, one option per
    entry of ``choices`` (``{"groups": GROUPS, "ops": OPS}``: ``--groups``, ``--ops``, each a
    comma-separated subset), ``--repeats``, ``--dtype``, ``--quick``,
    ``--seed`` and the saving options; ``parse`` reads it. ``sizes`` and ``quick`` are the
    default batch sizes of a full and of a ``--quick`` run (``sizes=None``: the script's
    own, which ``sizes_text`` describes)."""
    p = argparse.ArgumentParser(
        prog="python -m benchmarks." + Path(sys.argv[0]).stem,
        description=description,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.set_defaults(_choices=choices, _sizes=sizes, _quick=quick)
    p.add_argument(
        "--sizes",
        default=None,
        help=f"comma-separated batch sizes (default {sizes_text or sizes})",
    )
    for name, options in choices.items():
        default = ",".join(map(str, options))
        p.add_argument(f"--{name}", default=default, help="a subset of %(default)s")
    p.add_argument(
        "--repeats",
        type=int,
        default=None,
        help=f"interleaved repetitions per case; default: automatic, {min_repeats}..25 within "
        "a time budget per case",
    )
    p.add_argument("--dtype", choices=("float32", "float64"), default="float32")
    p.add_argument("--quick", action="store_true", help=f"sizes {quick}, few repeats (smoke test)")
    p.add_argument("--seed", type=int, default=0)
    add_save_arguments(p)
    return p


def parse(p: argparse.ArgumentParser, argv=None) -> argparse.Namespace:
    """Parse the options of ``parser``: ``sizes`` (None for the script's own) and each of the
    ``choices`` become lists."""
    args = p.parse_args(argv)
    sizes = args.sizes or (args._quick if args.quick else args._sizes)
    args.sizes = None if sizes is None else parse_sizes(p, sizes)
    for name, options in args._choices.items():
        picked = parse_choices(p, getattr(args, name), [str(o) for o in options], name[:-1])
        setattr(args, name, [next(o for o in options if str(o) == x) for x in picked])
    return args


# --------------------------------------------------------------------------------------
# Raw result files
# --------------------------------------------------------------------------------------


def add_save_arguments(p: argparse.ArgumentParser) -> None:
    """``--json``, ``--save`` and the options that say where ``--save`` writes."""
    p.add_argument(
        "--json", default=None, metavar="PATH", help="also write the raw results to PATH"
    )
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
    machine = args.machine or machine_name(data["machine"])
    path = Path(args.raw_dir) / machine / f"{kind}.json"
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
