"""Figures for the book, one module per part.

``show(fig)`` is how every chapter displays a figure: it emits only a PNG (no
``<Figure size ...>`` text that nbval would compare) and closes the figure. ``save(fig, path)``
writes one to a file (e.g. the README's). Every figure function gives its axes titles, labels and
units, and returns the ``Figure``; import it from the module of its part of the book:

- ``plotting.common`` (several chapters): lines, grouped bars, learning curves over seeds; shared
  labels and helpers.
- ``plotting.multimodality`` (01-03, Part I): tree and side-road scenes, rollouts, action histograms,
  constant losses, Beta shapes, action distributions, density fits, energy landscapes and curves,
  command traces.
- ``plotting.ingredients`` (04-06, Part II): counter-examples, σ sweep, 2-D energies, KDE, inverse
  weights, DFO iterations, valley shares, populations, DFO rollouts.
- ``plotting.town`` (07): towns, junctions, lights, the car's step and turn, BEV channels, drives,
  routes, the dataset.
- ``plotting.agents`` (08-09): the agents' network, training and loss curves, trajectories, energy
  landscapes.
- ``plotting.steering`` (10): the road-following study's metrics per model beside the paper's, the
  Fig. 5 analogue.
- ``plotting.routes`` (11): routes coloured by their commands, intervals per group of drivers, success
  per command, an agent's output under each command.
- ``plotting.two_answers`` (12): the label gaps at the forks, the Fig. 6 analogue at a held-out fork,
  steering profiles at every fork, exits at the stems per agent, two valleys on the stem approaches.
- ``plotting.stems`` (12): the minority exit at the stems under each change tried.

Steering is drawn in the book's convention: −1 turns left, +1 turns right
(``common.STEER_LABEL``); positions in a right-handed world frame (y > 0 to the left).
"""

from __future__ import annotations

import io

import matplotlib.pyplot as plt

from ibc_tutorial.utils import atomic_write_bytes, check_int

DPI = 90
"""Resolution of figures stored in notebooks (keeps each chapter well under 3 MB)."""


def _png(fig, dpi: int) -> bytes:
    """``fig`` as PNG bytes (tight bounding box), then closed."""
    dpi = check_int("dpi", dpi, minimum=1)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight")
    plt.close(fig)
    return buf.getvalue()


def show(fig, *, dpi: int = DPI) -> None:
    """Display ``fig`` as a PNG only, then close it.

    In Jupyter this shows the picture; the output holds no text that nbval would compare.
    Outside IPython it does nothing but close the figure.
    """
    png = _png(fig, dpi)
    # deferred: IPython is heavy to import and only needed when a kernel displays the figure
    from IPython import get_ipython
    from IPython.display import display

    if get_ipython() is not None:
        display({"image/png": png}, raw=True)


def save(fig, path, *, dpi: int = 120) -> None:
    """Save ``fig`` as a PNG to ``path`` atomically (e.g. for the README) and close it."""
    atomic_write_bytes(path, _png(fig, dpi))
