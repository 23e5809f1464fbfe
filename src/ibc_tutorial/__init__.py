"""ibc_tutorial: the library behind the implicit-behavioral-cloning textbook.

Chapters import what they rely on from here; every function a chapter calls is
tested in ``tests/``. Sub-packages and modules (one concern each):

- ``toy``          the small worlds of Part I (the tree, the side road, the junction)
- ``policies``     observation encoders, explicit policies and the energy model
- ``losses``       Beta NLL, InfoNCE, grid cross-entropy, smoothing
- ``negatives``    counter-example samplers (IBC uniform, DA-IBC expert-perturbed)
- ``kde``          Gaussian KDE and inverse-density weights
- ``optimizers``   finding the action of lowest energy: grid, DFO (Algorithm 1), Langevin
- ``training``     the one training loop (resumable), for the chapters and the command line
- ``parallel``     independent runs (seeds) side by side in worker processes
- ``objectives``   the losses as training objectives (likelihood, InfoNCE, grid)
- ``driving``      the pymunk town, lights, BEV, expert, Gymnasium environment, rollouts
- ``experiments``  the book's studies end to end (``agents``: the driving agents of chapters 08-09)
- ``plotting``, ``widgets``  figures and ipywidgets explorers
- ``exercises``    checkers for the exercise notebooks
- ``cli``          the ``ibc-tutorial`` command line
"""

__version__ = "0.1.0"

__all__ = ["__version__", "seed_everything"]


def __getattr__(name: str):
    """``ibc_tutorial.seed_everything``, imported on first use (PEP 562)."""
    if name == "seed_everything":
        # deferred: ``utils`` loads torch, which ``ibc-tutorial --version`` and ``--help`` do not need
        from ibc_tutorial.utils import seed_everything

        return seed_everything
    raise AttributeError(f"module 'ibc_tutorial' has no attribute {name!r}")
