"""Figures drawn off-screen and written atomically: every verb's plot goes through here.

Figures are made with :class:`matplotlib.figure.Figure` directly (the Agg canvas, imported
on first use), so drawing never changes matplotlib's global backend for a caller, and an
image is drawn in memory then written in one step: no partial file on an error.
"""

import io
from pathlib import Path
from typing import Any

from baseparams.errors import InputError
from baseparams.io.atomic import atomic_write

IMAGE_FORMATS = ("png", "pdf", "svg")


def new_figure(**kwargs: Any) -> Any:
    """A matplotlib Figure not attached to pyplot (``kwargs`` as Figure's)."""
    from matplotlib.figure import Figure
    return Figure(**kwargs)


def save_figure(fig: Any, path: str | Path, fmt: str | None) -> Path:
    """Write ``fig`` to ``path`` as ``fmt`` (else the suffix's format, else PNG); the path written."""
    path = Path(path)
    suffix = path.suffix[1:].lower()
    if fmt is None and suffix and suffix not in IMAGE_FORMATS:
        # writing PNG bytes under a .jpg name would mislead every program that opens it
        raise InputError(f"cannot write a {suffix!r} image (known formats: {', '.join(IMAGE_FORMATS)}); "
                         f"name the file .png, .pdf or .svg, or give --image-format", file=path)
    fmt = fmt or (suffix if suffix in IMAGE_FORMATS else "png")
    if fmt not in IMAGE_FORMATS:
        raise InputError(f"unknown image format {fmt!r} (known: {', '.join(IMAGE_FORMATS)})", file=path)
    buffer = io.BytesIO()
    fig.savefig(buffer, format=fmt, dpi=150)
    atomic_write(path, buffer.getvalue(), what="the figure")
    return path
