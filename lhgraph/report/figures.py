"""Matplotlib figures as PNG bytes, for embedding in a report or writing atomically."""

from __future__ import annotations

import io
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from matplotlib.figure import Figure


def png_bytes(fig: Figure, dpi: int) -> bytes:
    """The figure as a PNG, cropped to its content (``bbox_inches="tight"``)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    return buf.getvalue()
