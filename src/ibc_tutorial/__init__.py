"""ibc_tutorial: the library behind the implicit-behavioral-cloning textbook.

Chapters import what they rely on from here; every function a chapter calls is
tested in ``tests/``. Sub-packages and modules (one concern each):

- ``toy``        the small worlds of Part I (the tree, the side road)
- ``policies``   explicit policies and the energy model
- ``losses``     Beta NLL, InfoNCE, grid cross-entropy, smoothing
- ``negatives``  counter-example samplers (IBC uniform, DA-IBC expert-perturbed)
- ``kde``        Gaussian KDE and inverse-density weights
- ``inference``  derivative-free optimisation (Algorithm 1), grid argmin, Langevin
- ``driving``    the pymunk town, lights, BEV, expert and Gymnasium environment
- ``training``   the training loop shared by chapters and the command line
- ``plotting``, ``widgets``  figures and ipywidgets explorers
- ``exercises``  checkers for the exercise notebooks
"""

__version__ = "0.1.0"

from ibc_tutorial.utils import seed_everything  # noqa: E402

__all__ = ["__version__", "seed_everything"]
