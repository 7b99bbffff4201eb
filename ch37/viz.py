"""The emit region's drawing: the PNG figure and the Rerun recording. Nothing here computes a result."""

from __future__ import annotations

import functools
import io
import math
from pathlib import Path

import numpy as np

from ch37.ownership import place, temp_path, write_atomic

DATA_COLOURS = {"source": "tab:blue", "augmented": "tab:orange"}
# metrics.json names the data arms "source" and "augmented"; the augmented arm trains on both sets
DATA_LABEL = {"source": "source only", "augmented": "source + augmented"}
RERUN_APP_ID = "ch3_7_scale_data"  # letters, digits and underscores: accepted by Rerun as is


def save_png(fig, path: Path, dpi=None, claim=None) -> Path:
    """A matplotlib figure to `path` as PNG, atomically (whole file or none; recorded in `claim`, the
    run's ch37.ownership.Claim on the folder, when given); the figure is closed."""
    import matplotlib.pyplot as plt

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    plt.close(fig)
    return write_atomic(path, buf.getvalue(), claim)


def figure(path: Path, src_starts, aug_starts, metrics: dict, annulus, claim=None) -> Path:
    """Coverage map of block starts over the spawn annulus + the 2x2's success bars with 95% intervals."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    coverage, arms, budgets = metrics["coverage"], metrics["arms"], metrics["budgets"]
    r_min, r_max, rings, sectors = annulus
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(10, 4.4))
    for r in np.linspace(r_min, r_max, rings + 1):
        ax0.add_patch(plt.Circle((0, 0), r, fill=False, color="0.7", lw=0.8))
    for th in np.linspace(0, 2 * math.pi, sectors, endpoint=False):
        c, s = math.cos(th), math.sin(th)
        ax0.plot([r_min * c, r_max * c], [r_min * s, r_max * s], color="0.7", lw=0.8)
    if len(aug_starts):
        label = f"augmented starts ({len(aug_starts)})"
        ax0.scatter(aug_starts[:, 0], aug_starts[:, 1], s=10, c=DATA_COLOURS["augmented"], label=label)
    label = f"source starts ({len(src_starts)})"
    ax0.scatter(src_starts[:, 0], src_starts[:, 1], s=30, c=DATA_COLOURS["source"], marker="s", label=label)
    ax0.plot(0, 0, "k+", ms=10, label="target (the block's goal pose)")
    lim = (-r_max * 1.25, r_max * 1.25)
    title = f"block starts: cells {coverage['source']} -> {coverage['union']} of {coverage['cells']}"
    ax0.set(aspect="equal", xlim=lim, ylim=lim, xlabel="block x (m)", ylabel="block y (m)", title=title)
    # below the map, never over a start: the annulus fills the axes out to every corner
    ax0.legend(loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=2, fontsize=8, frameon=False)
    width = 0.38
    for j, data in enumerate(DATA_COLOURS):  # bars grouped by budget, one colour per data set
        for i, budget in enumerate(budgets):
            arm = arms[f"{data}_{budget}"]
            x, rate = i + (j - 0.5) * width, arm["success"]
            err = [[rate - arm["ci95"][0]], [arm["ci95"][1] - rate]]
            label = DATA_LABEL[data] if i == 0 else None
            colour = DATA_COLOURS[data]  # its edge keeps a bar of 0.00 visible: a coloured stroke on 0
            ax1.bar(x, rate, width, color=colour, edgecolor=colour, lw=2, label=label, yerr=err, capsize=5)
            ax1.text(x, arm["ci95"][1] + 0.02, f"{rate:.2f}", ha="center", va="bottom", fontsize=8)
    ax1.set_xticks(range(len(budgets)), [f"{b} budget\n{n} steps each" for b, n in budgets.items()])
    title = "BC policy on held-out PushT starts"
    ax1.set(ylim=(-0.03, 1), ylabel="success rate (95% Wilson interval)", title=title)
    ax1.axhline(0, color="0.6", lw=0.8, zorder=0)  # 0 lies above the axis, so a bar of 0.00 shows
    ax1.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    return save_png(fig, path, dpi=100, claim=claim)


def save_rrd(path: Path, recording_id: str, log, claim=None) -> Path:
    """A Rerun recording to `path`, whole or not at all (ch37.ownership.place): log(rec) fills it."""
    import rerun as rr

    rec = rr.RecordingStream(RERUN_APP_ID, recording_id=recording_id)
    tmp = temp_path(path)
    try:
        rec.save(tmp)
        log(rec)
        rec.flush()
        rec.disconnect()
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return place(tmp, path, claim)


def recording(path: Path, metrics: dict, src_starts, aug_starts, trajectories, annulus, claim=None) -> Path:
    """A Rerun .rrd: the data-scale curve, block starts over the annulus, some augmented trajectories."""
    log = functools.partial(_record, metrics, src_starts, aug_starts, trajectories, annulus)
    return save_rrd(path, f"seed{metrics['seed']}", log, claim)


def _record(metrics, src_starts, aug_starts, trajectories, annulus, rec) -> None:
    import rerun as rr

    for arm in metrics["arms"].values():  # success vs frames of data, one curve per budget
        rec.set_time("frames", sequence=arm["frames"])
        rec.log(f"scale/{arm['budget']}/success", rr.Scalars(arm["success"]))
        rec.log(f"scale/{arm['budget']}/ci95_low", rr.Scalars(arm["ci95"][0]))
        rec.log(f"scale/{arm['budget']}/ci95_high", rr.Scalars(arm["ci95"][1]))
    rec.log("coverage/source", rr.Points2D(src_starts, radii=0.006, colors=[31, 119, 180]), static=True)
    if len(aug_starts):
        aug = rr.Points2D(aug_starts, radii=0.004, colors=[255, 127, 14])
        rec.log("coverage/augmented", aug, static=True)
    r_min, r_max = annulus[:2]
    circle = np.linspace(0, 2 * math.pi, 73)
    rings = [np.stack([r * np.cos(circle), r * np.sin(circle)], 1) for r in (r_min, r_max)]
    rec.log("coverage/annulus", rr.LineStrips2D(rings, colors=[160, 160, 160]), static=True)
    for i, ep in enumerate(trajectories):
        s = ep["observation.state"]
        rec.log(f"augmented/{i}/block", rr.LineStrips2D([s[:, 2:4]], colors=[255, 127, 14]), static=True)
        rec.log(f"augmented/{i}/pusher", rr.LineStrips2D([s[:, 0:2]], colors=[44, 160, 44]), static=True)
    cov = metrics["coverage"]
    text = f"coverage cells: source {cov['source']}, union {cov['union']} of {cov['cells']}\n"
    text += f"yield {metrics['yield']:.2f} ({metrics['kept']}/{metrics['attempts']})"
    rec.log("summary", rr.TextDocument(text), static=True)


# The Scale Lab (scale_lab.py): success against demos, one line per curve.
LAB_STYLE = {  # curve -> (colour, line style, label)
    "fresh": ("tab:blue", "-", "fresh expert demos"),
    "resolve": ("tab:orange", "-", "12 sources + re-solve (engine)"),
    "replay": ("tab:green", "-", "12 sources + replay (engine), at demos kept"),
    "resolve_fixed": ("tab:red", "-.", "re-solve at the fixed budget (N=108's steps)"),
}
LAB_DEFAULT = ("resolve", "108")  # the chapter's default point: 12 sources + 96 re-solves


def _lab_rows(result: dict, curve: str):
    """(demos, success, low, high) arrays of one curve, in N order; demos is the mean actually trained on."""
    rows = sorted(result["curves"][curve].items(), key=lambda kv: int(kv[0]))
    demos = np.array([r["demos"] for _, r in rows], float)
    rate = np.array([r["success"] for _, r in rows], float)
    lo = np.array([r["ci95"][0] for _, r in rows], float)
    hi = np.array([r["ci95"][1] for _, r in rows], float)
    return demos, rate, lo, hi


def scale_lab_figure(path: Path, result: dict, claim=None) -> Path:
    """Success vs demos (log x), one line per curve with its pooled 95% band, the chapter's default
    point marked and the expert's own success as the ceiling."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 4.8))
    for curve, (colour, ls, label) in LAB_STYLE.items():
        demos, rate, lo, hi = _lab_rows(result, curve)
        ax.plot(demos, rate, ls, color=colour, marker="o", ms=4, label=label)
        ax.fill_between(demos, lo, hi, color=colour, alpha=0.15, lw=0)
    curve, n = LAB_DEFAULT
    if n in result["curves"][curve]:
        r = result["curves"][curve][n]
        label = f"the chapter's default point (N={n}, re-solve)"
        ax.plot([r["demos"]], [r["success"]], "*", color="k", ms=14, zorder=5, label=label)
    ceiling = result["expert"]["success"]
    ax.axhline(ceiling, color="0.3", ls="--", lw=1.5, label=f"expert's own success ({ceiling:.2f})")
    cfg = result["config"]
    ax.set_xscale("log")
    ns = cfg["n"]
    ax.set_xticks(ns, [str(n) for n in ns])
    ax.minorticks_off()
    seeds, pooled = cfg["seeds"], cfg["eval_episodes"] * len(cfg["seeds"])
    title = f"BC success vs demos: mean over seeds {seeds}, band = Wilson 95% of {pooled} pooled episodes"
    ax.set_ylim(0, 1.02)
    ax.set(xlabel="PushT demos trained on (log scale)", ylabel="success rate on held-out starts")
    ax.set_title(title + (" (smoke)" if result.get("smoke") else ""), fontsize=9)
    ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    return save_png(fig, path, dpi=100, claim=claim)


def scale_lab_recording(path: Path, result: dict, claim=None) -> Path:
    """The Scale Lab's curves as Rerun scalars on a "demos" timeline (scale_lab/CURVE/success, ci95_*)."""
    import rerun as rr

    def log(rec):
        for curve in LAB_STYLE:
            for demos, rate, lo, hi in zip(*_lab_rows(result, curve)):
                rec.set_time("demos", sequence=int(round(demos)))
                rec.log(f"scale_lab/{curve}/success", rr.Scalars(rate))
                rec.log(f"scale_lab/{curve}/ci95_low", rr.Scalars(lo))
                rec.log(f"scale_lab/{curve}/ci95_high", rr.Scalars(hi))
                rec.log("scale_lab/expert/success", rr.Scalars(result["expert"]["success"]))
        text = rr.TextDocument(f"{result['command']}\n{result['interval']}")
        rec.log("scale_lab/summary", text, static=True)

    return save_rrd(path, "scale_lab", log, claim)
