"""The book's experiments, each a package or module that runs one study end to end.

- ``toy_runs``          the training runs of chapters 02-03 on the tree and side-road worlds, as
  self-contained jobs that ``ibc_tutorial.parallel`` can run side by side
- ``counter_examples``  the Part II toy experiment of chapters 04-06 (counter-examples, KDE
  weights, DFO on the junction approach)
- ``agents``            the driving agents of the DA-IBC paper (chapters 08-09): presets, the
  Fig. 2 network, training, closed-loop evaluation, checkpoints, the replication and its results

Nothing is imported here, so that loading one experiment does not load the others.
"""
