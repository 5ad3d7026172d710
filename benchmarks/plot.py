"""Plot jaxlie/jaxlie_geo speed ratios from raw `benchmarks/run.py --markdown` outputs.

Reads the header block (date, cpu, cores_usable, jax, backend, dtype, ...) and the
per-case lines, e.g.

    SE3  exp  N=  10^3  geo  162 ns/el  jaxlie  138 ns/el  ratio  0.92 [0.77–0.98]  compile  366/ 526 ms ...

of each given file (default: the two committed 2-core CPU runs) and draws one panel
per group with the median ratio and its IQR per op and batch size N; float32 is drawn
with filled markers, float64 with hollow ones. Regenerate the committed figure with

    python benchmarks/plot.py                      # -> benchmarks/results.png
    python benchmarks/plot.py --out gpu.png benchmarks/gpu/h100_float32.md benchmarks/gpu/h100_float64.md
"""

from __future__ import annotations

import argparse
import re
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.ticker import FixedLocator, NullLocator  # noqa: E402

HERE = Path(__file__).resolve().parent
GROUPS = ("SO2", "SE2", "SO3", "SE3")
OPS = ("exp", "log", "compose", "apply", "inverse", "interpolate", "grad")
SIZES = ("1", "10^3", "10^6")
SIZE_LABELS = ("N=1", "N=10³", "N=10⁶")
SIZE_COLORS = ("#4c72b0", "#dd8452", "#55a868")
SE3_TARGETS = {"exp": 3.0, "log": 2.5, "compose": 2.5, "interpolate": 2.5, "apply": 2.0, "grad": 2.0}
TO_NS = {"s": 1e9, "ms": 1e6, "µs": 1e3, "us": 1e3, "ns": 1.0}
_T = r"([\d.]+)\s*(s|ms|µs|us|ns)/el"
CASE_RE = re.compile(
    rf"^(S[OE][23])\s+(\w+)\s+N=\s*(1|10\^\d+)\s+geo\s+{_T}\s+jaxlie\s+{_T}\s+"
    r"ratio\s+([\d.]+)\s+\[([\d.]+)\s*[–-]\s*([\d.]+)\]\s+compile\s+(\d+)\s*/\s*(\d+)\s*ms"
)
HEADER_RE = re.compile(r"^\s+(\w+)\s{2,}(\S.*?)\s*$")


@dataclass(frozen=True)
class Case:
    group: str
    op: str
    n: str
    geo_ns: float
    jaxlie_ns: float
    ratio: float
    iqr_lo: float
    iqr_hi: float
    compile_geo_ms: int
    compile_jaxlie_ms: int


def parse(path: Path) -> tuple[dict[str, str], list[Case]]:
    """Header key/values and benchmark cases of one raw output file."""
    header: dict[str, str] = {}
    cases: list[Case] = []
    for line in path.read_text(encoding="utf-8").splitlines():
        if m := CASE_RE.match(line):
            g = m.groups()
            cases.append(Case(g[0], g[1], g[2], float(g[3]) * TO_NS[g[4]], float(g[5]) * TO_NS[g[6]],
                              float(g[7]), float(g[8]), float(g[9]), int(g[10]), int(g[11])))
        elif not cases and (m := HEADER_RE.match(line)):
            header[m[1]] = m[2]
    if not cases:
        raise SystemExit(f"{path}: no benchmark lines found")
    return header, cases


def machine(h: dict[str, str]) -> str:
    if h.get("backend", "cpu") != "cpu":
        return f"{h.get('backend', '?').upper()} {h.get('devices', '')}".strip()
    cores = h.get("cores_usable", "?")
    return f"{h.get('cpu', 'CPU')}, pinned to {cores} cores" if cores != h.get("cores") else h.get("cpu", "CPU")


def plot(files: list[Path], out: Path) -> None:
    runs = [parse(f) for f in files]
    machines = list(dict.fromkeys(machine(h) for h, _ in runs))
    shapes = ("o", "s", "^", "D")
    fig, axes = plt.subplots(2, 2, figsize=(12, 7.5), sharey=True)
    slot, n_runs = 0.27, len(runs)
    for ax, group in zip(axes.flat, GROUPS):
        for i in range(0, len(OPS), 2):
            ax.axvspan(i - 0.5, i + 0.5, color="0.94", zorder=0)
        ax.axhline(1.0, color="0.3", lw=1, zorder=1)
        for k, (h, cases) in enumerate(runs):
            hollow = h.get("dtype") == "float64"
            shape = shapes[machines.index(machine(h)) % len(shapes)]
            for c in (c for c in cases if c.group == group and c.op in OPS and c.n in SIZES):
                j = SIZES.index(c.n)
                x = OPS.index(c.op) + (j - 1) * slot + (k - (n_runs - 1) / 2) * slot / (n_runs + 1)
                color = SIZE_COLORS[j]
                ax.errorbar(x, c.ratio, yerr=[[c.ratio - c.iqr_lo], [c.iqr_hi - c.ratio]], fmt=shape,
                            ms=5.5, color=color, mfc="white" if hollow else color, mew=1.3, elinewidth=1,
                            capsize=1.5, zorder=3)
        if group == "SE3":
            for op, target in SE3_TARGETS.items():
                i = OPS.index(op)
                ax.hlines(target, i - 0.45, i + 0.45, colors="crimson", linestyles="--", lw=1.4, zorder=2)
        ax.set_title(group, fontsize=12, fontweight="bold", loc="left")
        ax.set_yscale("log")
        ax.set_xlim(-0.5, len(OPS) - 0.5)
        ax.set_xticks(range(len(OPS)), OPS, fontsize=9.5)
        ax.grid(axis="y", which="major", color="0.85", lw=0.6)
    ticks = [0.25, 0.5, 1, 2, 3, 5, 10, 20, 40]
    lo = min(c.iqr_lo for _, cs in runs for c in cs)
    hi = max(c.iqr_hi for _, cs in runs for c in cs)
    axes[0, 0].set_ylim(min(0.8, lo / 1.15), max(4.0, hi * 1.15))
    for ax in axes.flat:
        ax.yaxis.set_major_locator(FixedLocator(ticks))
        ax.yaxis.set_minor_locator(NullLocator())
        ax.set_yticklabels([f"{t:g}×" for t in ticks])
    for ax in axes[:, 0]:
        ax.set_ylabel("jaxlie time / jaxlie_geo time")
    handles = [Line2D([], [], ls="", marker="o", color=c, label=lab) for c, lab in zip(SIZE_COLORS, SIZE_LABELS)]
    handles += [Line2D([], [], ls="", marker="o", color="0.3", label="float32"),
                Line2D([], [], ls="", marker="o", color="0.3", mfc="white", mew=1.3, label="float64")]
    if len(machines) > 1:
        handles += [Line2D([], [], ls="", marker=shapes[i % len(shapes)], color="0.3", label=m)
                    for i, m in enumerate(machines)]
    handles += [Line2D([], [], color="0.3", lw=1, label="1× = as fast as jaxlie"),
                Line2D([], [], color="crimson", ls="--", lw=1.4, label="SE3 target (issue)")]
    rows = -(-len(handles) // 7)
    fig.legend(handles=handles, loc="lower center", ncol=-(-len(handles) // rows), fontsize=9, frameon=False)

    def field(key: str) -> str:
        return ", ".join(dict.fromkeys(h.get(key, "?").split()[0] for h, _ in runs))  # date: day only

    fig.suptitle(f"jaxlie_geo vs jaxlie: speed-up per element (>1× = jaxlie_geo faster; bars = IQR)\n"
                 f"{' | '.join(machines)} — {field('date')} — jax {field('jax')}, jaxlie {field('jaxlie')}",
                 fontsize=12)
    fig.tight_layout(rect=(0, 0.035 * rows + 0.015, 1, 1))
    fig.savefig(out, dpi=120)
    print(f"wrote {out}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("files", nargs="*", type=Path,
                    default=[HERE / "cpu" / "xeon_2cores_2026-11-23_float32.md", HERE / "cpu" / "xeon_2cores_2026-11-23_float64.md"],
                    help="raw outputs of benchmarks/run.py --markdown (default: the 2-core CPU float32/64 runs)")
    ap.add_argument("--out", type=Path, default=HERE / "results.png", help="output PNG (default: benchmarks/results.png)")
    args = ap.parse_args()
    plot(args.files, args.out)


if __name__ == "__main__":
    main()
