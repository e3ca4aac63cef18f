"""What every example shares: where figures go, how they are written, and the command line."""

from __future__ import annotations

import argparse
import io
from collections.abc import Callable
from pathlib import Path

from matplotlib.figure import Figure
from PIL import Image

FIGURES = Path(__file__).resolve().parent / "figures"


def save_figure(fig: Figure, out_dir: str | Path | None, name: str) -> Path:
    """Write ``fig`` as an 8-bit palette PNG (a third of the RGBA size) into ``out_dir``; return its path."""
    out = Path(out_dir) if out_dir is not None else FIGURES
    out.mkdir(parents=True, exist_ok=True)
    path = out / name
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    Image.open(buf).convert("RGB").quantize(256, dither=Image.Dither.NONE).save(path, optimize=True)
    return path


def command_line(main: Callable[[Path | None, bool], Path], doc: str | None) -> None:
    """``python examples/X.py [--out DIR] [--quick]``: run ``main`` and print where the figure went."""
    parser = argparse.ArgumentParser(description=(doc or "").splitlines()[0] if doc else None)
    parser.add_argument("--out", type=Path, default=None, help=f"output folder (default {FIGURES})")
    parser.add_argument("--quick", action="store_true", help="a coarse, fast run (for tests)")
    args = parser.parse_args()
    print(f"figure: {main(args.out, args.quick)}")
