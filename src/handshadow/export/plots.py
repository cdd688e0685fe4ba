"""Plots: how a morph path behaves frame by frame."""

from __future__ import annotations

import io

import numpy as np


def path_plot(report) -> np.ndarray:
    """(H, W, 3) uint8: each frame's IoU with target A and with B, and the largest joint-angle
    step between consecutive frames (with the 10-degree bar)."""
    import matplotlib

    matplotlib.use("Agg")
    import imageio.v3 as iio
    import matplotlib.pyplot as plt

    frames = np.arange(len(report.iou_a))
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(7, 5.2), sharex=True, dpi=110)
    ax1.plot(frames, report.iou_a, "o-", ms=3, label="IoU with A")
    ax1.plot(frames, report.iou_b, "s-", ms=3, label="IoU with B")
    ax1.set_ylim(0, 1.02)
    ax1.set_ylabel("IoU")
    ax1.legend(loc="center right")
    ax1.grid(alpha=0.3)
    steps = np.asarray(report.steps_deg)
    ax2.bar(frames[1:] - 0.5, steps, width=0.8, color="#5577aa", label="largest step")
    ax2.axhline(10, color="#cc4444", lw=1, ls="--", label="10 degrees")
    ax2.set_ylabel("joint-angle step (deg)")
    ax2.set_xlabel("frame")
    ax2.legend(loc="upper right")
    ax2.grid(alpha=0.3)
    fig.suptitle(f"max step {steps.max() if len(steps) else 0:.1f} deg; penetrating frames {report.penetrating_frames}")
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    plt.close(fig)
    return iio.imread(buf.getvalue())[..., :3]
