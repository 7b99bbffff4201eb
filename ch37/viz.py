"""The emit region's drawing: the PNG figure and the Rerun recording. Nothing here computes a result."""

from __future__ import annotations

import io
import math
import os
from pathlib import Path

import numpy as np

from ch37.files import write_atomic

ARM_LABELS = {
    "source": "source\nonly",
    "augmented": "source +\naugmented",
    "compute_matched": "compute-\nmatched",
}
RERUN_APP_ID = "ch3_7_scale_data"  # letters, digits and underscores: accepted by Rerun as is


def figure(path: Path, src_starts, aug_starts, arms: dict, coverage: dict, annulus) -> Path:
    """Coverage map of block starts over the spawn annulus + success bars with 95% intervals."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    r_min, r_max, rings, sectors = annulus
    fig, (ax0, ax1) = plt.subplots(1, 2, figsize=(10, 4.4))
    for r in np.linspace(r_min, r_max, rings + 1):
        ax0.add_patch(plt.Circle((0, 0), r, fill=False, color="0.7", lw=0.8))
    for th in np.linspace(0, 2 * math.pi, sectors, endpoint=False):
        ax0.plot(
            [r_min * math.cos(th), r_max * math.cos(th)],
            [r_min * math.sin(th), r_max * math.sin(th)],
            color="0.7",
            lw=0.8,
        )
    if len(aug_starts):
        ax0.scatter(
            aug_starts[:, 0], aug_starts[:, 1], s=10, c="tab:orange", label=f"augmented ({len(aug_starts)})"
        )
    ax0.scatter(
        src_starts[:, 0],
        src_starts[:, 1],
        s=30,
        c="tab:blue",
        marker="s",
        label=f"source ({len(src_starts)})",
    )
    ax0.plot(0, 0, "k+", ms=10)
    ax0.set(
        aspect="equal",
        xlim=(-0.3, 0.3),
        ylim=(-0.3, 0.3),
        xlabel="block x (m)",
        ylabel="block y (m)",
        title=f"block starts: cells {coverage['source']} -> {coverage['union']} of {coverage['cells']}",
    )
    ax0.legend(loc="lower left", fontsize=8)
    names = [n for n in ARM_LABELS if n in arms]  # fixed order and colour per arm
    rates = [arms[n]["success"] for n in names]
    err = np.array([[r - arms[n]["ci95"][0], arms[n]["ci95"][1] - r] for n, r in zip(names, rates)]).T
    ax1.bar(
        [ARM_LABELS.get(n, n) for n in names],
        rates,
        yerr=err,
        capsize=6,
        color=[{"source": "tab:blue", "augmented": "tab:orange"}.get(n, "tab:gray") for n in names],
    )
    for i, n in enumerate(names):
        ax1.text(
            i,
            arms[n]["ci95"][1] + 0.02,
            f"{rates[i]:.2f}\n{arms[n]['frames']} frames",
            ha="center",
            va="bottom",
            fontsize=8,
        )
    ax1.set(
        ylim=(0, 1), ylabel="success rate (95% Wilson interval)", title="BC policy on held-out PushT starts"
    )
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    plt.close(fig)
    return write_atomic(path, buf.getvalue())


def recording(path: Path, arms: dict, metrics: dict, src_starts, aug_starts, trajectories, annulus) -> Path:
    """A Rerun .rrd: the data-scale curve, block starts over the annulus, some augmented trajectories."""
    import rerun as rr

    rec = rr.RecordingStream(RERUN_APP_ID, recording_id=f"seed{metrics['seed']}")
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    rec.save(tmp)
    for arm in ("source", "augmented"):  # success vs frames of data: the data-scale curve
        rec.set_time("frames", sequence=arms[arm]["frames"])
        rec.log("scale/success", rr.Scalars(arms[arm]["success"]))
        rec.log("scale/ci95_low", rr.Scalars(arms[arm]["ci95"][0]))
        rec.log("scale/ci95_high", rr.Scalars(arms[arm]["ci95"][1]))
    rec.log("coverage/source", rr.Points2D(src_starts, radii=0.006, colors=[31, 119, 180]), static=True)
    if len(aug_starts):
        rec.log(
            "coverage/augmented", rr.Points2D(aug_starts, radii=0.004, colors=[255, 127, 14]), static=True
        )
    r_min, r_max = annulus[:2]
    circle = np.linspace(0, 2 * math.pi, 73)
    rings = [np.stack([r * np.cos(circle), r * np.sin(circle)], 1) for r in (r_min, r_max)]
    rec.log("coverage/annulus", rr.LineStrips2D(rings, colors=[160, 160, 160]), static=True)
    for i, ep in enumerate(trajectories):
        s = ep["observation.state"]
        rec.log(f"augmented/{i}/block", rr.LineStrips2D([s[:, 2:4]], colors=[255, 127, 14]), static=True)
        rec.log(f"augmented/{i}/pusher", rr.LineStrips2D([s[:, 0:2]], colors=[44, 160, 44]), static=True)
    rec.log(
        "summary",
        rr.TextDocument(
            f"coverage cells: source {metrics['coverage']['source']}, union {metrics['coverage']['union']} "
            f"of {metrics['coverage']['cells']}\n"
            f"yield {metrics['yield']:.2f} ({metrics['kept']}/{metrics['attempts']})"
        ),
        static=True,
    )
    rec.flush()
    rec.disconnect()
    os.replace(tmp, path)
    return path
