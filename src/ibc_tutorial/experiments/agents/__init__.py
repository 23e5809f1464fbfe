"""The driving experiment of the DA-IBC paper (chapters 08-12): BC, IBC and DA-IBC agents in the 2-D towns.

Modules, one concern each:

- ``presets``             the settings ``paper``, ``laptop``, ``tiny``, ..., and what each method means
- ``agent``               the Fig. 2 network (``architecture``, ``build_network``) and ``Agent``, how it acts
- ``checkpoints``         saving and checked loading of agents (``load_agent``)
- ``train``               one training run's learning (``ibc-tutorial train``)
- ``training_run``        one training run's folder and what happens beside the learning: resume,
  periodic town02 evaluations, ``metrics.jsonl``, checkpoints
- ``evaluate``            the closed-loop evaluation protocol and its summaries (``ibc-tutorial evaluate``)
- ``crossings``           the junction crossings of an evaluation, and the energies where they ended
- ``figures``             the Fig. 5 (free driving) and Fig. 6 (energy landscapes) analogues
- ``replication_folder``  the replication's folder: where everything sits, aggregation, ``load_results``
- ``replicate``           the whole replication, resumable (``ibc-tutorial replicate``)
- ``claims``              the paper's five claims judged on a replication folder, two folders compared
- ``stem_drives``, ``stem_analysis``  ``ibc-tutorial stems``: free drives, and the readings at the stems
- ``route_driving``       computes: a driver on the town02 routes, with or without commands
- ``route_study``         the command ``ibc-tutorial routes``: every agent of a folder on the routes
- ``route_tables``        reads route drives: tables per method, success per command, ends at stems
- ``command_readings``    an agent's output at one state under each command (chapter 11)
- ``two_answers``         chapter 12's study (``ibc-tutorial two-answers``)

Import from the modules (``from ibc_tutorial.experiments.agents.replication_folder import load_results``):
nothing is imported here, so that ``ibc-tutorial evaluate`` does not load the training code.
"""
