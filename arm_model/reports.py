"""The pieces every report of the toolkit shares (``calibrate``, ``close-loop``, ``ring``, ``paper``):
matplotlib off screen (Agg), figures as PNG bytes, HTML tables. Loads matplotlib only when a figure is
made."""
from __future__ import annotations

import html
import io

__all__ = ["DPI", "pyplot", "figure", "png", "html_table"]

#: resolution of the report figures [dots per inch]
DPI = 110


def pyplot():
    """``matplotlib.pyplot`` drawing off screen (the Agg backend: no display needed)."""
    import matplotlib
    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    return plt


def figure(width: float, height: float, rows: int | None = None, cols: int | None = None):
    """A figure ``width`` x ``height`` inches: ``(fig, ax)`` with one plot, or ``(fig, axes)`` with an
    array (rows, cols) of plots when ``rows`` or ``cols`` is given (the other one then defaults to 1)."""
    if rows is None and cols is None:
        return pyplot().subplots(figsize=(width, height))
    return pyplot().subplots(rows or 1, cols or 1, figsize=(width, height), squeeze=False)


def png(fig, dpi: int = DPI, crop: bool = True) -> bytes:
    """The PNG bytes of ``fig``, cropped to what is drawn (``crop``: matplotlib's ``bbox_inches="tight"``, which
    lays the figure out once more; False for a figure laid out in fixed margins); the figure is closed."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight" if crop else None)
    pyplot().close(fig)
    return buf.getvalue()


def html_table(headers, rows) -> str:
    """An HTML table: a header row of ``headers``, then one row a sequence of ``rows`` (every cell
    escaped)."""
    h = "".join(f"<th>{html.escape(str(c))}</th>" for c in headers)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in r) + "</tr>" for r in rows)
    return f"<table><thead><tr>{h}</tr></thead><tbody>{body}</tbody></table>"
