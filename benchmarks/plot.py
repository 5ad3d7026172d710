"""The figures of the results page, drawn from raw results: jaxlie_geo's speed-up over
jaxlie, and pose-graph cost against time beside GTSAM.

``report.py`` calls it whenever it regenerates the page (imported there only then:
matplotlib is optional); it takes the groups, operations and labels from ``common``. Speed-up:
one panel per group, with the median speed-up and its inter-quartile range per operation and
batch size N; float32 is drawn with filled markers, float64 with hollow ones. From the
command line, through ``report.py``::

    python -m benchmarks.report                        # the page and its figures
    python -m benchmarks.report --plot h100.png benchmarks/raw/gpu-*/speed-*.json
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.ticker import FixedLocator, NullLocator  # noqa: E402

from benchmarks.common import GROUPS, OPS, label, pretty_n  # noqa: E402

SIZE_COLORS = ("#4c72b0", "#dd8452", "#55a868", "#8172b3")
SHAPES = ("o", "s", "^", "D")


def plot(runs: list, out: Path) -> None:
    """Draw the speed runs (raw ``speed-*.json`` contents) into the PNG ``out``: a panel for
    each group, the operations along it."""
    sizes = sorted({r["n"] for run in runs for r in run["results"]})
    machines = list(dict.fromkeys(label(run["machine"]) for run in runs))
    fig, axes = plt.subplots(2, 2, figsize=(12, 7.5), sharey=True)
    slot = 0.8 / max(1, len(sizes))
    for ax, group in zip(axes.flat, GROUPS):
        for i in range(0, len(OPS), 2):
            ax.axvspan(i - 0.5, i + 0.5, color="0.94", zorder=0)
        ax.axhline(1.0, color="0.3", lw=1, zorder=1)
        for k, run in enumerate(runs):
            hollow = run["machine"].get("dtype") == "float64"
            shape = SHAPES[machines.index(label(run["machine"])) % len(SHAPES)]
            for r in run["results"]:
                if r["group"] != group or r["op"] not in OPS:
                    continue
                j = sizes.index(r["n"])
                x = (
                    OPS.index(r["op"])
                    + (j - (len(sizes) - 1) / 2) * slot
                    + (k - (len(runs) - 1) / 2) * slot / (len(runs) + 1)
                )
                color = SIZE_COLORS[j % len(SIZE_COLORS)]
                yerr = [[r["ratio"] - r["ratio_q1"]], [r["ratio_q3"] - r["ratio"]]]
                ax.errorbar(
                    x,
                    r["ratio"],
                    yerr=yerr,
                    fmt=shape,
                    ms=5.5,
                    color=color,
                    mfc="white" if hollow else color,
                    mew=1.3,
                    elinewidth=1,
                    capsize=1.5,
                    zorder=3,
                )
        ax.set_title(group, fontsize=12, fontweight="bold", loc="left")
        ax.set_yscale("log")
        ax.set_xlim(-0.5, len(OPS) - 0.5)
        ax.set_xticks(range(len(OPS)), OPS, fontsize=9.5)
        ax.grid(axis="y", which="major", color="0.85", lw=0.6)
    ticks = [0.25, 0.5, 1, 2, 3, 5, 10, 20, 40, 80]
    lo = min(r["ratio_q1"] for run in runs for r in run["results"])
    hi = max(r["ratio_q3"] for run in runs for r in run["results"])
    axes[0, 0].set_ylim(min(0.8, lo / 1.15), max(4.0, hi * 1.15))
    for ax in axes.flat:
        ax.yaxis.set_major_locator(FixedLocator(ticks))
        ax.yaxis.set_minor_locator(NullLocator())
        ax.set_yticklabels([f"{t:g}×" for t in ticks])
    for ax in axes[:, 0]:
        ax.set_ylabel("jaxlie time / jaxlie_geo time")
    handles = [
        Line2D(
            [],
            [],
            ls="",
            marker="o",
            color=SIZE_COLORS[j % len(SIZE_COLORS)],
            label=f"N = {pretty_n(n)}",
        )
        for j, n in enumerate(sizes)
    ]
    handles += [
        Line2D([], [], ls="", marker="o", color="0.3", label="float32"),
        Line2D([], [], ls="", marker="o", color="0.3", mfc="white", mew=1.3, label="float64"),
    ]
    if len(machines) > 1:
        handles += [
            Line2D([], [], ls="", marker=SHAPES[i % len(SHAPES)], color="0.3", label=m)
            for i, m in enumerate(machines)
        ]
    handles.append(Line2D([], [], color="0.3", lw=1, label="1× = as fast as jaxlie"))
    rows = -(-len(handles) // 7)
    fig.legend(
        handles=handles,
        loc="lower center",
        ncol=-(-len(handles) // rows),
        fontsize=9,
        frameon=False,
    )

    def field(key: str) -> str:
        values = (str(run["machine"].get(key, "?")).split()[0] for run in runs)  # date: day only
        return ", ".join(dict.fromkeys(values))

    fig.suptitle(
        "jaxlie_geo against jaxlie: speed-up per element (>1× = jaxlie_geo faster; "
        f"bars = IQR)\n{' | '.join(machines)} — {field('date')} — jax {field('jax')}, "
        f"jaxlie {field('jaxlie')}",
        fontsize=12,
    )
    fig.tight_layout(rect=(0, 0.035 * rows + 0.015, 1, 1))
    fig.savefig(out, dpi=120, metadata={"Software": None})  # no version stamp: reproducible
    plt.close(fig)
    print(f"wrote {out}")


def plot_pose_graphs(data: dict, out: Path, machine: str) -> None:
    """Cost against wall time for GTSAM and ours, one panel per dataset
    (``raw/<machine>/pose-graphs.json``), into the PNG ``out``; ``machine`` for the title."""
    res = data["results"]
    fig, axes = plt.subplots(1, len(res), figsize=(3.2 * len(res), 3.2), squeeze=False)
    for ax, r in zip(axes[0], res):
        ax.plot(r["gtsam_times"], r["gtsam_costs"], "o-", ms=3, label="GTSAM", color="#dd8452")
        ax.plot(r["ours_times"], r["ours_costs"], "s-", ms=3, label="jaxlie_geo", color="#4c72b0")
        ax.set_yscale("log")
        ax.set_title(r["dataset"], fontsize=9)
        ax.set_xlabel("seconds")
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("cost")
    axes[0][0].legend(fontsize=8)
    fig.suptitle(f"Pose graphs, {machine}", fontsize=10)
    fig.tight_layout()
    fig.savefig(out, dpi=100)
    plt.close(fig)
