"""The book's experiments, each a package or module that runs one study end to end.

- ``toy_runs``           the training runs of chapters 02-03 on the tree and side-road worlds, as
  self-contained jobs that ``ibc_tutorial.parallel`` can run side by side
- ``counter_examples``   the Part II toy experiment of chapters 04-06 (counter-examples, KDE
  weights, DFO on the junction approach)
- ``family_comparison``  Part I's policy families side by side on the junction world
- ``agents``             the driving agents of the DA-IBC paper (chapters 08-12): presets, the
  Fig. 2 network, training, closed-loop evaluation, checkpoints, the replication and its readings
- ``steering``           the steering-EBM paper's road-following study and its sweep (chapter 10)
- ``runs``               what every study's folder shares: its files, its provenance, one lifecycle
  (``StudyFolder``); the two studies never import each other
- ``settings``           ``--set FIELD=VALUE`` and the flat JSON form of both studies' settings
- ``subcommands``        each ``ibc-tutorial`` sub-command's work, from the arguments ``cli`` parsed

Nothing is imported here, so that loading one experiment does not load the others.
"""
