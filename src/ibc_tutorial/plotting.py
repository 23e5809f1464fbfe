"""Figures for the book.

``show(fig)`` is how every chapter displays a figure: it emits only a PNG (no
``<Figure size ...>`` text that nbval would compare) and closes the figure. Figure
functions below are grouped by chapter; each gives its axes titles, labels and units.
"""

from __future__ import annotations

import io

import matplotlib

matplotlib.use("Agg", force=False)
import matplotlib.pyplot as plt  # noqa: E402

DPI = 90
"""Resolution of figures stored in notebooks (keeps each chapter well under 3 MB)."""


def show(fig, *, dpi: int = DPI) -> None:
    """Display ``fig`` as a PNG only, then close it.

    In Jupyter this shows the picture; the output holds no text that nbval would compare.
    Outside IPython it does nothing but close the figure.
    """
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    plt.close(fig)
    try:
        from IPython import get_ipython
        from IPython.display import display
    except ImportError:  # pragma: no cover - IPython is always installed with jupyter
        return
    if get_ipython() is not None:
        display({"image/png": buf.getvalue()}, raw=True)


def save(fig, path, *, dpi: int = 120) -> None:
    """Save ``fig`` to ``path`` atomically (e.g. for the README) and close it."""
    from ibc_tutorial.utils import atomic_write_bytes

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    plt.close(fig)
    atomic_write_bytes(path, buf.getvalue())
