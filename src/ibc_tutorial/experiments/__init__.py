"""The book's experiments, each a package or module that runs one study end to end.

- ``counter_examples``  the Part II toy experiment of chapters 04-06 (counter-examples, KDE
  weights, DFO on the junction approach)
- ``agents``            the driving agents of the DA-IBC paper (chapters 08-09): presets, the
  Fig. 2 network, training, closed-loop evaluation, checkpoints, the replication and its results

Nothing is imported here, so that loading one experiment does not load the others.
"""
