"""The steering-EBM paper's road-following study in the town (chapter 10, ``ibc-tutorial
replicate-steering``).

- ``presets``: the ``laptop`` and ``tiny`` settings;
- ``task``: the steering-only task, its demonstrations (side roads rarely taken) and minibatches;
- ``models``: the paper's six models from the library's heads and losses;
- ``evaluate``: fixed town02 routes (in driving sessions), crashes with restarts (VISTA's protocol), W_cmd,
  swerve rate;
- ``train``: one run (train, evaluate, trace) with resumable checkpoints;
- ``replicate``: the command, its results and provenance, ``load_results`` for the chapter;
- ``junctions``: the sweep's measures at a side-road junction (probability on the side road, whiteness);
- ``sweep``: ``ibc-tutorial sweep-steering``, the study at several side-road shares, each model driven in
  several sessions: its settings (``SweepSettings``), its folder, its work and its tables.

Both commands' folders go through the lifecycle every study's folder does (``experiments.runs``).
"""
