"""``ibc-tutorial sweep-steering`` end to end on the tiny preset: files, measures recomputed from the
traces, sessions, kill-and-rerun, refusals."""

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from ibc_tutorial import cli
from ibc_tutorial.experiments.steering import evaluate as ev
from ibc_tutorial.experiments.steering import sweep as S
from ibc_tutorial.experiments.steering.presets import LAPTOP, TINY

ARGS = (
    "--preset",
    "tiny",
    "--shares",
    "0.3,0.5",
    "--models",
    "ebm,regression",
    "--seeds",
    "0",
    "--sessions",
    "2",
)
RUNS = [f"share{p}/{m}/seed0" for p in ("0.3", "0.5") for m in ("ebm", "regression")]


def _run(*argv) -> int:
    return cli.main(["sweep-steering", *argv])


@pytest.fixture(scope="module")
def swept(tmp_path_factory):
    out = tmp_path_factory.mktemp("sweep") / "sweep"
    assert _run(*ARGS, "--out", str(out), "--threads", "1") == 0
    return out


def test_tiny_sweep_files_and_tables(swept):
    loaded = S.load_results(swept)
    res, prov = loaded["results"], loaded["provenance"]
    assert res["complete"] and prov["complete"] and prov["runs_done"] == RUNS == prov["runs_planned"]
    assert res["settings"]["shares"] == [0.3, 0.5] and res["settings"]["sessions"] == 2
    assert res["preset"] == TINY.to_dict() and set(res["data"]) == {"share0.3", "share0.5"}
    assert "sweep-steering --preset tiny --shares 0.3,0.5" in prov["command"] and prov["commit"]
    assert prov["preset"]["sweep"] == res["settings"] and prov["machine"]["nproc"] >= 1
    for share in ("share0.3", "share0.5"):
        for m in ("ebm", "regression"):
            t = res["table"][share][m]
            assert t["seeds"] == 1 and len(t["peak_m"]["values"][0]) == 2  # one seed, two sessions
            assert (t["side_mass"]["mean"] is None) == (m == "regression")  # the regression has no density
            run = res["runs"][share][m]["0"]
            assert [s["session"] for s in run["sessions"]] == [0, 1]
    # each share trained on its own demonstrations
    d3 = (swept / "share0.3" / "data" / "town01.npz").read_bytes()
    assert d3 != (swept / "share0.5" / "data" / "town01.npz").read_bytes()


def test_measures_are_recomputed_from_the_traces(swept):
    for share in (0.3, 0.5):
        d = S.FOLDER.run_dir(swept, S.sweep_run(share, "ebm", 0))
        r = S.read_sweep_eval(d / S.EVAL)
        with np.load(d / S.PASSES) as z:
            arrays = {k: z[k] for k in z.files}
        for s in r["sessions"]:
            for route in s["routes"]:
                for p, peak in enumerate(route["swerve_peak_m"]):
                    off = arrays[f"s{s['session']}/{route['route']}/p{p}/offset"]
                    if peak is None:
                        assert off.size == 0
                        continue
                    assert off[0] == 0 and peak == pytest.approx(float(off.max()), abs=1e-3)
                    mass = arrays[f"s{s['session']}/{route['route']}/p{p}/mass"]
                    assert route["side_mass"][p] == pytest.approx(float(mass.mean()), abs=1e-4)
                    assert ((mass >= 0) & (mass <= 1)).all()


def test_sessions_start_further_on_with_their_own_lights(swept):
    refs, _ = ev.read_references(swept / ev.REFERENCES, TINY.eval_routes, sessions=2)
    (r0,), (r1,) = refs
    assert (r0.name, r0.session, r1.session) == ("y82-west", 0, 1)
    a, b = ev.build_route("y82-west", 0), ev.build_route("y82-west", 1)
    assert b.start_lane == a.start_lane and b.start_s == pytest.approx(a.start_s + ev.SESSION_SHIFT_M)
    assert not np.array_equal(r0.poses[:5], r1.poses[:5])
    assert len(r0.sections) == len(r1.sections) == 1  # the same side road in both sessions


def test_bad_shares_are_refused_before_any_work(tmp_path, capsys):
    for bad in ("0.3,abc", "0", "1.5", "0.3,0.3", ","):
        out = tmp_path / "never"
        assert _run("--preset", "tiny", "--shares", bad, "--out", str(out)) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "--shares" in err, err
        assert not out.exists()
    assert _run("--preset", "tiny", "--models", "ebm,tree", "--out", str(tmp_path / "never")) == 2
    assert "models" in capsys.readouterr().err
    assert _run("--preset", "tiny", "--set", "side_road_share=0.2", "--out", str(tmp_path / "never")) == 2
    assert "--shares" in capsys.readouterr().err
    assert not (tmp_path / "never").exists()


def test_other_settings_in_the_folder_are_refused(swept, capsys):
    before = (swept / "results.json").read_text()
    assert _run(*ARGS[:-1], "3", "--out", str(swept)) == 2  # --sessions 3
    assert "other settings" in capsys.readouterr().err
    assert (swept / "results.json").read_text() == before
    with pytest.raises(ValueError, match="other settings"):
        S.check_folder(
            swept,
            S.SweepSettings(shares=(0.3, 0.5), models=("ebm", "regression"), seeds=(0,), sessions=2),
            LAPTOP,
        )


def test_kill_and_rerun_skips_the_finished_runs(tmp_path):
    out = tmp_path / "sweep"
    env = dict(os.environ, OMP_NUM_THREADS="1", TQDM_DISABLE="1")
    cmd = [sys.executable, "-m", "ibc_tutorial.cli", "sweep-steering", *ARGS, "--out", str(out)]
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    first = S.FOLDER.run_dir(out, S.sweep_run(0.3, "ebm", 0)) / S.EVAL
    t0 = time.monotonic()
    while not first.exists() and proc.poll() is None and time.monotonic() - t0 < 300:
        time.sleep(0.05)
    assert first.exists() and proc.poll() is None, "the first run did not finish before the sweep ended"
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    settings = S.SweepSettings(shares=(0.3, 0.5), models=("ebm", "regression"), seeds=(0,), sessions=2)
    done = [r for r in S.planned(settings) if S.FOLDER.is_done(out, r)]
    assert S.FOLDER.finished(out, S.planned(settings)) == [r.name for r in done]
    assert 1 <= len(done) < len(RUNS)
    kept = {r: (S.FOLDER.run_dir(out, r) / S.EVAL).read_text() for r in done}
    assert _run(*ARGS, "--out", str(out)) == 0
    prov = json.loads((out / "provenance.json").read_text())
    assert prov["complete"] and prov["resumed"] and len(prov["invocations"]) == 2
    assert prov["runs_done"] == RUNS
    for r, text in kept.items():  # finished runs were skipped, not made again
        assert (S.FOLDER.run_dir(out, r) / S.EVAL).read_text() == text


def test_drive_route_measures_the_mass_of_a_scorer_at_the_junction():
    """A straight-driving policy with hand-made scores: two equal valleys at full left and full right put
    half the mass on the side road, whichever side it is on; one valley at straight ahead puts none."""
    ref, _ = ev.expert_reference("y82-west", TINY)
    grid = np.linspace(-1.0, 1.0, 21)
    both = np.where(np.abs(grid) == 1.0, 0.0, 40.0)[None]  # (1, G)
    straight = np.where(grid == 0.0, 0.0, 40.0)[None]
    r2 = ev.drive_route(lambda obs: 0.0, ref, TINY, scorer=lambda obs: both, grid=grid)
    r0 = ev.drive_route(lambda obs: 0.0, ref, TINY, scorer=lambda obs: straight, grid=grid)
    assert len(r2["side_mass"]) == len(ref.sections) == 1 and len(r2["pass_mass"][0]) >= 10
    assert r2["side_mass"][0] == pytest.approx(0.5, abs=1e-6)
    assert r0["side_mass"][0] == pytest.approx(0.0, abs=1e-6)
    assert r0["section_w_cmd"] == 0.0 and r0["section_changes"] >= 10  # a constant command does not jitter
    assert "side_mass" not in ev.drive_route(lambda obs: 0.0, ref, TINY)  # no scorer, no mass


def test_the_shipped_sweep_is_complete_and_a_clean_run_of_an_ancestor_commit():
    import json
    import re
    import subprocess
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    folder = root / "book" / "results" / "steering-sweep"
    prov = json.loads((folder / "provenance.json").read_text())
    res = json.loads((folder / "results.json").read_text())
    assert prov["complete"] and res["complete"] and len(prov["runs_done"]) == len(prov["runs_planned"]) == 36
    assert len(prov["invocations"]) == 1 and re.fullmatch(r"[0-9a-f]{40}", prov["commit"])
    if (root / ".git").exists():
        ancestor = subprocess.run(
            ["git", "-C", str(root), "merge-base", "--is-ancestor", prov["commit"], "HEAD"]
        )
        assert ancestor.returncode == 0
