"""Draw the PsychoPy Builder icons of the vibrofocus tap component.

PsychoPy's Builder looks for a component's icon in ``light/``, ``dark/`` and ``classic/``
beside the file the component names (``VibrofocusTapComponent.iconFile``), at 1x and
``@2x``. This script draws them: four actuators (dots) around a focused tap (rings).

    python scripts/make_psychopy_icons.py          # rewrites src/vibrofocus/psychopy/{light,dark,classic}/tap*.png
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.patches import Circle, FancyBboxPatch  # noqa: E402

from vibrofocus.io import save_figure  # noqa: E402

#: (outline and actuators, focus) per theme: dark strokes on light panels, light on dark,
#: PsychoPy's classic icons are coloured.
THEMES = {"light": ("#3a3a3a", "#e0457b"), "dark": ("#e8e8e8", "#ff7aa8"), "classic": ("#2f6fb0", "#e05a1c")}
SIZES = {"": 48, "@2x": 96}


def draw(stroke: str, focus: str, pixels: int) -> plt.Figure:
    """One icon, ``pixels`` square at its dpi."""
    fig = plt.figure(figsize=(1, 1), dpi=pixels)
    ax = fig.add_axes((0, 0, 1, 1))
    ax.set_xlim(0, 1)
    ax.set_ylim(0, 1)
    ax.axis("off")
    ax.add_patch(FancyBboxPatch((0.08, 0.08), 0.84, 0.84, boxstyle="round,pad=0,rounding_size=0.18",
                                fill=False, lw=pixels / 24, ec=stroke))
    for x, y in ((0.27, 0.27), (0.73, 0.27), (0.27, 0.73), (0.73, 0.73)):
        ax.add_patch(Circle((x, y), 0.075, color=stroke))
    for r, alpha in ((0.2, 0.45), (0.12, 0.75)):
        ax.add_patch(Circle((0.5, 0.5), r, fill=False, lw=pixels / 32, ec=focus, alpha=alpha))
    ax.add_patch(Circle((0.5, 0.5), 0.05, color=focus))
    return fig


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=Path(__file__).resolve().parents[1] / "src/vibrofocus/psychopy",
                        help="the folder of the component's module (default: the package's)")
    args = parser.parse_args(argv)
    for theme, (stroke, focus) in THEMES.items():
        folder = args.out / theme
        folder.mkdir(exist_ok=True)
        for suffix, pixels in SIZES.items():
            fig = draw(stroke, focus, pixels)
            save_figure(fig, folder / f"tap{suffix}.png", what="icon", transparent=True, dpi=pixels)
            plt.close(fig)
            print(f"wrote {folder / f'tap{suffix}.png'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
