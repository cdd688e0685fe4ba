"""print.png: the print on its stand, and a sheet that says where the torch goes.

Left: the print rendered as it stands on a table, its board showing the shadow it will catch.
Right: a side view with the torch's place measured in millimetres, and the lines a person
needs (how far, how high, which way is up, how big, how to print it).
"""

from __future__ import annotations

import dataclasses
import io

import numpy as np

from handshadow.export.meshes import SKIN
from handshadow.render.views import Camera, ViewMesh, render_view

STAND_COLOR = (0.78, 0.80, 0.84)
BOARD_TINT = np.array([0.97, 0.96, 0.93])


@dataclasses.dataclass(frozen=True)
class SheetFacts:
    """What the sheet states, print millimetres (x right, y up from the table, z from the
    board's back toward the lamp). lamp: (3,) position; wall_z: the board's front face;
    frame: (x0, x1, y0, y1) of the picture on the board; height_mm; life_scale: print length
    per real length; min_wall_mm; thinnest_mm; thickened: spots thickened; stand: whether
    there is one; foot_mm: (length, thickness) of the foot, zeros without a stand; bounds_mm:
    (2, 3) lowest and highest corner of the print; thickened_parts: names of the parts
    thickened."""

    lamp: np.ndarray
    wall_z: float
    frame: tuple[float, float, float, float]
    height_mm: float
    life_scale: float
    min_wall_mm: float
    thinnest_mm: float
    thickened: int
    stand: bool
    foot_mm: tuple[float, float] = (0.0, 0.0)
    bounds_mm: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((2, 3)))
    thickened_parts: tuple[str, ...] = ()


def instructions(f: SheetFacts) -> list[str]:
    """The sheet's lines, plain text (also printed by the command line)."""
    lamp_x, lamp_y, lamp_z = f.lamp
    side = "centred" if abs(lamp_x) < 0.5 else f"{abs(lamp_x):.0f} mm {'right' if lamp_x > 0 else 'left'} of centre"
    size = f.bounds_mm[1] - f.bounds_mm[0]
    if f.stand:
        place = [
            f"Torch: {lamp_z - f.wall_z:.0f} mm in front of the board, {lamp_y:.0f} mm above the table, {side},",
            "  pointing at the cross on the board; a small bare LED gives the sharpest shadow. Dark room.",
            "Up is up as drawn: the board stands on its foot, the hands reach toward the torch.",
        ]
    else:
        place = [
            f"Torch: {lamp_z - f.wall_z:.0f} mm in front of the wall, pointing at it. Hold the print upright,",
            f"  its lowest point {lamp_y:.0f} mm below the torch, its back {f.bounds_mm[0][2] - f.wall_z:.0f} mm"
            " from the wall (print.json has the exact place).",
        ]
    return place + [
        f"Size: {f.height_mm:.0f} mm tall, {f.life_scale:.3f} x life size (1:{1 / f.life_scale:.1f});"
        f" {size[0]:.0f} x {size[1]:.0f} x {size[2]:.0f} mm (wide, tall, deep).",
        f"Thinnest part {f.thinnest_mm:.1f} mm (minimum wall {f.min_wall_mm:g} mm"
        + (f"; thickened to it: {', '.join(f.thickened_parts) or f'{f.thickened} spots'})." if f.thickened else ")."),
        "Print it lying on its back as the file lies (the board on the bed), with supports for the hands."
        if f.stand
        else "Print it with supports; it is not one piece if the hands do not touch.",
    ]


def print_picture(
    hands: tuple[np.ndarray, np.ndarray],
    stand: tuple[np.ndarray, np.ndarray] | None,
    shadow: np.ndarray,
    facts: SheetFacts,
    render_px: int = 560,
) -> np.ndarray:
    """(H, W, 3) uint8: the render on the left, the measured sheet on the right.

    hands, stand: (vertices (V, 3) mm, faces (F, 3)) in print coordinates; shadow: (H, W)
    bool, the picture the board catches.
    """
    view = _render(hands, stand, shadow, facts, render_px)
    return _sheet(view, hands[0], facts)


def _render(hands, stand, shadow, facts: SheetFacts, size: int) -> np.ndarray:
    meshes = [ViewMesh(hands[0], hands[1], color=SKIN)]
    if stand is not None:
        meshes.append(ViewMesh(stand[0], stand[1], color=STAND_COLOR))
    x0, x1, y0, y1 = facts.frame
    z = facts.wall_z + 0.05
    corners = np.array([[x0, y1, z], [x1, y1, z], [x1, y0, z], [x0, y0, z]])
    texture = (1.0 - 0.8 * np.asarray(shadow, float))[..., None] * BOARD_TINT
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    meshes.append(ViewMesh(corners, np.array([[0, 2, 1], [0, 3, 2]]), texture=texture, uv=uv, emissive=True))
    points = np.concatenate([m.vertices for m in meshes])
    lo, hi = points.min(0), points.max(0)
    centre = 0.5 * (lo + hi)
    reach = float(np.linalg.norm(hi - lo))
    eye = centre + reach * np.array([0.6, 0.35, 1.05])
    camera = Camera(tuple(eye), tuple(centre), (0.0, 1.0, 0.0), fov_deg=36.0, width=size, height=size)
    return render_view(meshes, camera, background=(1.0, 1.0, 1.0), supersample=2)


def _sheet(view: np.ndarray, hand_points: np.ndarray, f: SheetFacts) -> np.ndarray:
    import imageio.v3 as iio
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(13.5, 6.6), dpi=100)
    grid = fig.add_gridspec(2, 2, width_ratios=[1.0, 1.35], height_ratios=[1.0, 0.62], wspace=0.08, hspace=0.28)
    ax = fig.add_subplot(grid[:, 0])
    ax.imshow(view)
    ax.set_axis_off()
    ax.set_title("the print on its stand" if f.stand else "the print", fontsize=11)
    _side_view(fig.add_subplot(grid[0, 1]), hand_points, f)
    text = fig.add_subplot(grid[1, 1])
    text.set_axis_off()
    for i, line in enumerate(instructions(f)):
        weight = "bold" if i == 0 else "normal"
        text.text(0.0, 1.0 - i * 0.17, line, fontsize=10.5, va="top", weight=weight, transform=text.transAxes)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", facecolor="white", bbox_inches="tight", pad_inches=0.15)
    plt.close(fig)
    return iio.imread(buf.getvalue())[..., :3]


def _side_view(ax, hand_points: np.ndarray, f: SheetFacts) -> None:
    """Seen from the side: table, board and foot (or the wall), the hands, the torch, the
    picture's extreme rays, and the distances the sheet states."""
    lamp_y, lamp_z = f.lamp[1], f.lamp[2]
    _, _, y0, y1 = f.frame
    low, high = min(0.0, y0), max(y1, f.height_mm)
    if f.stand:
        ax.axhline(0, color="#8a7356", lw=3)
        ax.fill_between([-0.08 * lamp_z, 1.15 * lamp_z], -0.05 * f.height_mm, 0, color="#e9e1d4")
        ax.add_patch(_rect((0, 0), f.wall_z, y1, "#aab2c0"))
        ax.add_patch(_rect((f.wall_z, 0), f.foot_mm[0], f.foot_mm[1], "#aab2c0"))
    else:
        ax.plot([f.wall_z, f.wall_z], [y0, y1], color="#888", lw=2)
    for y in (y0, y1):
        ax.plot([lamp_z, f.wall_z], [lamp_y, y], color="#f2b632", lw=1, ls="--")
    ax.scatter(hand_points[::7, 2], hand_points[::7, 1], s=1, color=np.asarray(SKIN) * 0.85)
    ax.plot(lamp_z, lamp_y, marker="*", ms=16, color="#f2a900", mec="#8a5a00")
    ax.annotate("torch", (lamp_z, lamp_y), xytext=(6, 8), textcoords="offset points", fontsize=10)
    wall = "board" if f.stand else "wall"
    _dimension(ax, (f.wall_z, lamp_z), (low - 0.12 * f.height_mm,) * 2, f"{lamp_z - f.wall_z:.0f} mm to the {wall}")
    _dimension(ax, (1.05 * lamp_z,) * 2, (0, lamp_y), f"{lamp_y:.0f} mm")
    ax.annotate(
        "",
        xy=(0.03, 0.97),
        xytext=(0.03, 0.75),
        xycoords="axes fraction",
        arrowprops=dict(arrowstyle="-|>", color="black", lw=1.5),
    )
    ax.text(0.045, 0.86, "up", transform=ax.transAxes, fontsize=10)
    ax.set_aspect("equal")
    ax.set_xlim(-0.08 * lamp_z, 1.15 * lamp_z)
    ax.set_ylim(low - 0.2 * f.height_mm, 1.08 * high)
    ax.set_xlabel(f"mm from the back of the {wall}" if f.stand else "mm from the wall")
    ax.set_ylabel("mm above the table" if f.stand else "mm above the print's lowest point", fontsize=9)
    ax.set_title("from the side", fontsize=11)
    ax.tick_params(labelsize=8)


def _rect(xy, width, height, color):
    from matplotlib.patches import Rectangle

    return Rectangle(xy, width, height, color=color)


def _dimension(ax, xs, ys, label: str) -> None:
    ax.annotate("", xy=(xs[1], ys[1]), xytext=(xs[0], ys[0]), arrowprops=dict(arrowstyle="<->", color="#333", lw=1))
    ax.text(
        0.5 * (xs[0] + xs[1]),
        0.5 * (ys[0] + ys[1]),
        " " + label,
        fontsize=9.5,
        va="center",
        ha="center" if ys[0] == ys[1] else "left",
        bbox=dict(fc="white", ec="none", pad=1),
    )
