"""The benchmark scripts (``benchmarks/``) run end to end at a tiny size.

They are not part of the library and no test reads their figures (speed is measured, not asserted:
CONTRIBUTING). But they call the library, and a script that no test runs falls behind its API unseen
(one once called ``rollout`` with an older signature). These runs check that each script still runs and
prints its rows; they take a few seconds each.
"""

import os
import subprocess
import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"

RUNS = {
    "bench_replicate": (
        [
            "bench_replicate.py",
            "--preset",
            "tiny",
            "--limits",
            "--sample",
            "64",
            "--reps",
            "1",
        ]
        + ["--train-steps", "2", "--eval-episodes", "1", "--eval-steps", "5"],
        ("share = time at the measured peaks",),
    ),
    "bench_dfo": (
        ["bench_dfo.py", "--samples", "64", "--iters", "2", "--decisions", "2", "--warmup", "1"]
        + ["--experts", "50", "--threads", "1"],
        ("decisions/s", "goal of 10 decisions/s"),
    ),
    "bench_inference": (
        ["bench_inference.py", "--preset", "tiny", "--dfo-samples", "64", "--dfo-iters", "2"]
        + [
            "--langevin-samples",
            "16",
            "--langevin-iters",
            "2",
            "--flow-steps",
            "1,2",
            "--flow-samples",
            "1,4",
        ]
        + ["--decisions", "2", "--warmup", "1", "--experts", "50", "--threads", "1"],
        ("decisions/s", "flow, K = 2, N = 4", "Langevin (16 chains x 2 steps)"),
    ),
    "bench_sim": (["bench_sim.py", "--steps", "50"], ("steps/s", "Dataset rendering, 192x192")),
}


@pytest.mark.parametrize("name", sorted(RUNS))
def test_the_benchmark_runs_end_to_end_at_a_tiny_size(name, tmp_path):
    args, expected = RUNS[name]
    env = dict(os.environ, OMP_NUM_THREADS="1", TQDM_DISABLE="1", MPLBACKEND="Agg")
    done = subprocess.run(
        [sys.executable, *args], cwd=BENCHMARKS, env=env, capture_output=True, text=True, timeout=600
    )
    assert done.returncode == 0, done.stderr[-2000:]
    for text in expected:
        assert text in done.stdout, f"{name} printed no {text!r}:\n{done.stdout[-2000:]}"
