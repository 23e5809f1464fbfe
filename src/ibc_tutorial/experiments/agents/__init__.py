"""The driving experiment of the DA-IBC paper (chapters 08-09): BC, IBC and DA-IBC agents in the 2-D towns.

Modules, one concern each:

- ``presets``      the settings ``paper``, ``laptop`` and ``tiny``, and what each method means
- ``agent``        the Fig. 2 network (``architecture``, ``build_network``) and ``Agent``, how it acts
- ``checkpoints``  saving and checked loading of agents (``load_agent``)
- ``train``        one training run with periodic town02 evaluations (``ibc-tutorial train``)
- ``evaluate``     the closed-loop evaluation protocol and its summaries (``ibc-tutorial evaluate``)
- ``route_eval``   agents on the town02 routes with their commands (``replicate --commands``, chapter 11)
- ``figures``      the Fig. 5 (free driving) and Fig. 6 (energy landscapes) analogues
- ``results``      the replication folder: aggregation, provenance, ``load_results`` for the chapters
- ``replicate``    the whole replication, resumable (``ibc-tutorial replicate``)
- ``ablations``    the variants of a preset (``replicate --ablation``) and ``compare_folders``
- ``claims``       the paper's five claims judged on a replication folder (``judge_claims``)

Import from the modules (``from ibc_tutorial.experiments.agents.results import load_results``):
nothing is imported here, so that ``ibc-tutorial evaluate`` does not load the training code.
"""
