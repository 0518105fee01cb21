"""Writing figures as small PNG files."""
from __future__ import annotations

from pathlib import Path

from ..atomic import atomic_path

__all__ = ["save_png"]


def save_png(fig, path: str | Path, dpi: int = 100, colors: int | None = 256) -> Path:
    """Save ``fig`` as a PNG; with ``colors`` (default 256) as a palette image without dithering.

    Plots are mostly flat colours, so a 256-colour palette looks the same and is about a third
    of the size of the RGBA file (dense scatter plots with transparency otherwise make large
    files). ``colors=None`` writes the plain RGBA PNG of ``fig.savefig``.
    """
    import io

    from PIL import Image

    path = Path(path)
    if colors is None:
        with atomic_path(path) as tmp:  # whole or not at all
            fig.savefig(tmp, dpi=dpi, format="png")
        return path
    buf = io.BytesIO()
    fig.savefig(buf, dpi=dpi, format="png")
    buf.seek(0)
    with Image.open(buf) as im:
        pal = im.convert("RGB").quantize(colors=int(colors), method=Image.Quantize.MEDIANCUT,
                                         dither=Image.Dither.NONE)
    with atomic_path(path) as tmp:
        pal.save(tmp, format="PNG", optimize=True)
    return path
