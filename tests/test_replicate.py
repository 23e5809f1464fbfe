"""``ibc-tutorial replicate`` wired end to end on the tiny preset."""

import json
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import torch

from ibc_tutorial import cli
from ibc_tutorial.experiments.agents.checkpoints import load_agent
from ibc_tutorial.experiments.agents.presets import (
    LAPTOP,
    METHODS,
    TEN_ROUTES,
    TINY,
    Preset,
    differences,
    with_overrides,
)
from ibc_tutorial.experiments.agents.replication_folder import collect_results, load_results, run_dir
from ibc_tutorial.experiments.runs import machine

SHIPPED = Path(__file__).resolve().parents[1] / "book" / "results" / "laptop"


@pytest.fixture
def replicated(tiny_replication):
    """The session's tiny replication (tests/conftest.py), which every test here only reads."""
    return tiny_replication


def test_replicate_tiny(replicated, tmp_path):
    out = tmp_path / "rep"
    shutil.copytree(replicated, out)  # run again below: a copy, the shared folder stays as it is
    res = json.loads((out / "results.json").read_text())
    assert res["complete"] and res["preset"]["name"] == "tiny"
    assert set(res["table"]) == set(METHODS) | {"expert"} and set(res["heldout"]) == set(METHODS) | {"expert"}
    assert res["table"]["expert"]["episodes"] == TINY.final_episodes
    assert res["heldout"]["bc"]["episodes"] == TINY.heldout_episodes * len(TINY.seeds)
    for m in METHODS:
        t = res["table"][m]
        assert t["episodes"] == TINY.final_episodes * len(TINY.seeds) and t["agents"] == len(TINY.seeds)
        assert res["curves"][m]["0"]["epoch"] == list(range(1, TINY.epochs + 1))
    assert set(res["free_driving"]) == {"bc", "da-ibc"}
    assert 0.0 <= res["free_driving"]["bc"]["coverage_all"] <= 1.0
    assert (out / "free_driving.npz").exists() and (out / "landscapes.npz").exists()
    # every agent is kept, its weights in float16; no optimiser states
    for m in METHODS:
        ckpt = torch.load(run_dir(out, m, 0) / "final.pt", weights_only=True)
        assert ckpt["optimizer"] is None and all(
            v.dtype == torch.float16 for v in ckpt["model"].values() if v.is_floating_point()
        )
        held = json.loads((run_dir(out, m, 0) / "heldout_eval.json").read_text())
        assert (
            held["start_seed"]
            != json.loads((run_dir(out, m, 0) / "final_eval.json").read_text())["start_seed"]
        )
    assert not list(out.glob("runs/*/*/last.pt"))
    prov = json.loads((out / "provenance.json").read_text())
    assert prov["complete"] and prov["runs_done"] == prov["runs_planned"] and prov["machine"]["nproc"] >= 1
    assert "replicate --preset tiny" in prov["command"] and "wall time" in (out / "PROVENANCE.md").read_text()
    # running again resumes: nothing is retrained, the results stay the same
    before = {m: (run_dir(out, m, 0) / "final_eval.json").read_text() for m in METHODS}
    assert cli.main(["replicate", "--preset", "tiny", "--out", str(out)]) == 0
    assert before == {m: (run_dir(out, m, 0) / "final_eval.json").read_text() for m in METHODS}
    assert collect_results(out, TINY)["table"] == res["table"]
    # wall time: the sum of both invocations, each with its start and last heartbeat
    prov2 = json.loads((out / "provenance.json").read_text())
    assert len(prov2["invocations"]) == 2
    assert prov2["wall_seconds"] == pytest.approx(sum(i["seconds"] for i in prov2["invocations"]), abs=0.2)
    assert prov2["wall_seconds"] >= prov["wall_seconds"]


def test_evaluate_defaults_are_the_replication_protocol(replicated, tmp_path):
    """``ibc-tutorial evaluate --checkpoint final.pt`` with no other option remakes the run's
    final_eval.json."""
    out = replicated
    for method in METHODS:
        d = run_dir(out, method, 0)
        report = tmp_path / f"{method}.json"
        assert cli.main(["evaluate", "--checkpoint", str(d / "final.pt"), "--out", str(report)]) == 0
        ev = json.loads(report.read_text())
        assert ev["routeless"] and ev["policy_seed"] == 0 and ev["steps"] == TINY.final_steps
        assert ev["episodes"] == json.loads((d / "final_eval.json").read_text())["episodes"]


def test_machine_description(monkeypatch):
    m = machine()
    assert m["nproc"] >= 1 and m["torch_threads"] >= 1
    assert m["cpu_capability"] == torch.backends.cpu.get_cpu_capability()
    for k in ("ATEN_CPU_CAPABILITY", "MKL_ENABLE_INSTRUCTIONS", "ONEDNN_MAX_CPU_ISA", "OMP_NUM_THREADS"):
        monkeypatch.delenv(k, raising=False)
    assert machine()["cpu_environment"] == {}
    monkeypatch.setenv("ATEN_CPU_CAPABILITY", "default")  # what an emulated older CPU's run records
    assert machine()["cpu_environment"] == {"ATEN_CPU_CAPABILITY": "default"}


def test_the_shipped_results_load():
    if not (SHIPPED / "results.json").exists():
        pytest.skip("no shipped results")
    shipped = load_results(SHIPPED)
    res = shipped["results"]
    assert Preset.from_dict(res["preset"]) == LAPTOP and res["complete"]
    assert shipped["provenance"]["complete"] and set(res["table"]) == set(METHODS) | {"expert"}
    assert shipped["free_driving"] and "junction_energy" in shipped["landscapes"]
    assert (
        collect_results(SHIPPED, LAPTOP)["table"] == res["table"]
    )  # the aggregation reads the shipped runs alike


SHIPPED_RUNS = [
    "laptop",
    "ten-routes",
    "ten-routes-emulated",
    "ablations/no-held-brakes",
    "ablations/constant-schedule",
    "ablations/intensity-lights",
    "steering-laptop",
    "commands-branched",
    "commands-input",
]
"""Every replication folder the book ships (each made by one clean run of a committed state)."""


@pytest.mark.parametrize("name", SHIPPED_RUNS)
def test_the_shipped_results_are_a_clean_run_of_an_ancestor_commit(name):
    """PROVENANCE's commit has no uncommitted changes and is an ancestor of the commit that ships it."""
    folder = SHIPPED.parent / name
    if not (folder / "provenance.json").exists():
        pytest.skip(f"{folder} is not shipped")
    root = SHIPPED.parents[2]
    prov = json.loads((folder / "provenance.json").read_text())
    commit = prov["commit"]
    assert "uncommitted" not in commit and re.fullmatch(r"[0-9a-f]{40}", commit), commit
    if not (root / ".git").exists():
        pytest.skip("not a git checkout: the ancestry cannot be read")
    ancestor = subprocess.run(["git", "-C", str(root), "merge-base", "--is-ancestor", commit, "HEAD"])
    assert ancestor.returncode == 0, f"the shipped results' commit {commit} is not an ancestor of HEAD"


def test_the_shipped_route_drives_cover_every_shipped_agent_from_a_clean_ancestor_commit():
    """Chapter 11's route drives: every agent of the laptop replication and the expert on the six town02
    routes, without commands, from clean ancestor commits, each driver's every route once."""
    from ibc_tutorial.driving.route_following import ROUTES
    from ibc_tutorial.experiments.agents.route_study import load_route_drives

    folder = SHIPPED / "on-routes"
    if not folder.exists():
        pytest.skip("no shipped route drives")
    drives = load_route_drives(folder)
    assert set(drives) == {f"{m}-seed{s}" for m in METHODS for s in LAPTOP.seeds} | {"expert"}
    for name, d in drives.items():
        assert d["commands"] is False and sorted(r["route"] for r in d["episodes"]) == sorted(ROUTES), name
    prov = json.loads((folder / "provenance.json").read_text())
    assert prov["protocol"]["folder"] == "laptop" and prov["protocol"]["max_steps"] is None
    root = SHIPPED.parents[2]
    for inv in prov["invocations"]:
        commit = inv["commit"]
        assert "uncommitted" not in commit and re.fullmatch(r"[0-9a-f]{40}", commit), commit
        if (root / ".git").exists():
            ancestor = subprocess.run(["git", "-C", str(root), "merge-base", "--is-ancestor", commit, "HEAD"])
            assert ancestor.returncode == 0, f"commit {commit} is not an ancestor of HEAD"


def test_the_shipped_crossings_are_clean_runs_of_an_ancestor_commit():
    """Chapter 12's ``evaluate --crossings`` files: one per agent of the laptop replication, each from a
    clean ancestor commit."""
    files = sorted((SHIPPED / "crossings").glob("*.json"))
    assert [f.name for f in files] == sorted(f"{m}-seed{s}.json" for m in METHODS for s in LAPTOP.seeds)
    root = SHIPPED.parents[2]
    for f in files:
        commit = json.loads(f.read_text())["commit"]
        assert "uncommitted" not in commit and re.fullmatch(r"[0-9a-f]{40}", commit), (f.name, commit)
        if (root / ".git").exists():
            ancestor = subprocess.run(["git", "-C", str(root), "merge-base", "--is-ancestor", commit, "HEAD"])
            assert ancestor.returncode == 0, f"{f.name}: commit {commit} is not an ancestor of HEAD"


ABLATION = ["methods=bc,da-ibc", "seeds=0,1,2", "heldout_episodes=0", "routeless_episodes=0"]
"""What the smaller ablations of chapter 08 set: BC and DA-IBC, three seeds, the table's evaluation only."""
VARIANTS = {  # folder -> the --set overrides of its variant of the laptop preset, beside ``ABLATION``
    "no-held-brakes": ["brake_noise=0"],
    "intensity-lights": ["light_encoding=intensity"],
    "constant-schedule": ["lr_schedule=constant"],
}


@pytest.mark.parametrize("folder", sorted(VARIANTS))
def test_the_shipped_ablation_folders_are_the_laptop_preset_with_overrides(folder):
    """Chapter 08 compares each of these ablation folders with the canonical replication: the folder's
    preset must be ``LAPTOP`` with its ``--set`` overrides in every setting (its name aside)."""
    prov = json.loads((SHIPPED.parent / "ablations" / folder / "provenance.json").read_text())
    stored = prov["preset"]
    variant = with_overrides(LAPTOP, ABLATION + VARIANTS[folder])
    assert prov["overrides"] == ABLATION + VARIANTS[folder]
    assert differences(Preset.from_dict(stored), variant) == {}


def test_an_ablation_is_a_replication_with_overrides_recorded_in_its_provenance(tmp_path):
    out = tmp_path / "intensity"
    sets = ["light_encoding=intensity", "methods=bc,da-ibc", "heldout_episodes=0", "routeless_episodes=0"]
    argv = ["replicate", "--preset", "tiny", *[w for o in sets for w in ("--set", o)], "--out", str(out)]
    assert cli.main(argv) == 0
    res = json.loads((out / "results.json").read_text())
    preset = Preset.from_dict(res["preset"])
    assert TINY.light_encoding == "flag"
    assert preset == with_overrides(TINY, sets) and preset.light_encoding == "intensity"
    assert (
        set(res["table"]) == {"bc", "da-ibc", "expert"} and not res["heldout"] and "free_driving" not in res
    )
    assert len(res["final_per_seed"]["bc"]) == len(TINY.seeds)
    agent, ckpt = load_agent(run_dir(out, "da-ibc", 0) / "final.pt")
    assert agent.preset.light_encoding == "intensity"
    prov = json.loads((out / "provenance.json").read_text())
    assert prov["overrides"] == sets and all(f"`{o}`" in (out / "PROVENANCE.md").read_text() for o in sets)
    assert (
        cli.main(["replicate", "--preset", "tiny", "--out", str(out)]) == 2
    )  # the folder holds another preset
    assert cli.main(["replicate", "--preset", "tiny", "--ablation", "x", "--out", str(tmp_path / "n")]) == 2


def _folder_of_episodes(
    root: Path, method: str, per_seed: dict[int, list[tuple[float, int]]], starts=(1000, 1001)
):
    """A replication folder holding only final evaluations: per seed, (distance, red lights) per episode."""
    for seed, eps in per_seed.items():
        d = run_dir(root, method, seed)
        d.mkdir(parents=True)
        rows = [
            {
                "seed": s,
                "steps": 3000,
                "distance_m": dist,
                "red_light_infractions": reds,
                "score": dist * 0.7**reds,
                "termination": None,
            }
            for s, (dist, reds) in zip(starts, eps, strict=True)
        ]
        (d / "final_eval.json").write_text(json.dumps({"summary": {}, "episodes": rows}))
    return root


def test_compare_folders_reads_shared_seeds_and_counts_standstills(tmp_path):
    from ibc_tutorial.experiments.agents.claims import STILL_M, compare_folders

    var = _folder_of_episodes(tmp_path / "var", "bc", {0: [(500, 0), (600, 1)], 1: [(400, 0), (5, 0)]})
    ref = _folder_of_episodes(
        tmp_path / "ref", "bc", {0: [(100, 0), (2, 0)], 1: [(3, 0), (200, 2)], 7: [(900, 0), (900, 0)]}
    )  # seed 7: not shared
    (row,) = compare_folders(var, ref, methods=("bc",))
    assert row.seeds == (0, 1)
    v_scores = [500, 600 * 0.7, 400, 5]
    r_scores = [100, 2, 3, 200 * 0.49]
    assert row.score == pytest.approx((np.mean(v_scores), np.mean(r_scores)))
    assert row.red_lights == pytest.approx((0.25, 0.5))
    assert row.standing_still == (1, 2) and STILL_M == 10.0
    assert row.difference.estimate == pytest.approx(np.mean(v_scores) - np.mean(r_scores))
    assert row.difference.low <= row.difference.estimate <= row.difference.high
    other = _folder_of_episodes(tmp_path / "other", "bc", {0: [(1, 0), (1, 0)]}, starts=(5, 6))
    with pytest.raises(ValueError, match="other starts"):
        compare_folders(var, other, methods=("bc",))
    lone = _folder_of_episodes(tmp_path / "lone", "bc", {3: [(1, 0), (1, 0)]})
    with pytest.raises(ValueError, match="share no seed"):
        compare_folders(var, lone, methods=("bc",))


@pytest.mark.parametrize("replication", ["laptop", "ten-routes"])
def test_the_shipped_stem_analysis_is_complete_and_from_clean_ancestor_commits(replication):
    """``book/results/<replication>/stems``: a drive (its own, or the one ``replicate`` recorded) and an
    analysis file for every shipped agent and the expert, every invocation (drives, their resumption, the
    analyses) from a clean commit that is an ancestor."""
    from ibc_tutorial.experiments.agents.stem_drives import drive_file

    root_folder = SHIPPED.parent / replication
    folder = root_folder / "stems"
    if not (folder / "summary.json").exists():
        pytest.skip("no shipped stem analysis")
    preset = {"laptop": LAPTOP, "ten-routes": TEN_ROUTES}[replication]
    names = sorted([f"{m}-seed{s}" for m in METHODS for s in preset.seeds] + ["expert"])
    assert all(drive_file(root_folder, folder, n) is not None for n in names)
    assert sorted(f.stem for f in (folder / "analysis").glob("*.json") if f.stem != "provenance") == names
    summary = json.loads((folder / "summary.json").read_text())
    assert all(summary["methods"][m]["agents"] == len(preset.seeds) for m in METHODS)
    root = SHIPPED.parents[2]
    files = sorted(folder.glob("provenance*.json")) + [folder / "analysis" / "provenance.json"]
    commits = {i["commit"] for f in files for i in json.loads(f.read_text())["invocations"]}
    assert commits
    for commit in commits:
        assert "uncommitted" not in commit and re.fullmatch(r"[0-9a-f]{40}", commit), commit
        if (root / ".git").exists():
            ancestor = subprocess.run(["git", "-C", str(root), "merge-base", "--is-ancestor", commit, "HEAD"])
            assert ancestor.returncode == 0, f"commit {commit} is not an ancestor of HEAD"


def test_the_replication_records_its_table_episodes_for_the_stem_analysis(replicated, tmp_path):
    """Every run (and the expert) writes ``stem_drive.npz``: the same episodes as its ``final_eval.json``;
    ``stems analyse`` reads them without a second drive."""
    from ibc_tutorial.experiments.agents.replication_folder import STEM_DRIVE, expert_dir
    from ibc_tutorial.experiments.agents.stem_analysis import run_analysis
    from ibc_tutorial.experiments.agents.stem_drives import drive_file, load_drive

    out = replicated
    for d in [run_dir(out, m, 0) for m in METHODS] + [expert_dir(out)]:
        rec = load_drive(d / STEM_DRIVE)
        assert rec["rows"] == json.loads((d / "final_eval.json").read_text())["episodes"]
        assert len(rec["episodes"]) == TINY.final_episodes
        assert len(rec["episodes"][0]["lane"]) == rec["rows"][0]["steps"] + 1  # states, the last included
        assert (rec["obs"] is None) == (d == expert_dir(out))
    assert drive_file(out, tmp_path, "ibc-seed0") == run_dir(out, "ibc", 0) / STEM_DRIVE
    assert drive_file(out, tmp_path, "ibc-seed7") is None
    done = run_analysis(out, tmp_path, log=None)
    assert done == [f"{m}-seed0" for m in METHODS] + ["expert"]
    assert run_analysis(out, tmp_path, log=None) == []  # resumable: nothing left to do


def test_stem_drives_with_a_changed_dfo(replicated, tmp_path):
    """``stems drive --dfo-select sample``: the IBC agent draws its action instead of taking the lowest
    energy; the change is part of the folder's protocol, and BC and the expert are not changed."""
    from ibc_tutorial.experiments.agents.stem_drives import DriveProtocol, run_drives, with_dfo

    out = tmp_path / "sampled"
    sampled = DriveProtocol(episodes=1, steps=5, dfo={"select": "sample", "samples": 16})
    done = run_drives(replicated, out, sampled, only=["ibc-seed0", "bc-seed0"], log=None)
    assert done == ["bc-seed0", "ibc-seed0"]
    prov = json.loads((out / "provenance.json").read_text())
    assert prov["protocol"]["dfo"] == {"samples": 16, "select": "sample"}
    with pytest.raises(ValueError, match="another protocol"):
        run_drives(replicated, out, DriveProtocol(episodes=1, steps=5), only=["ibc-seed0"], log=None)
    agent = load_agent(run_dir(replicated, "ibc", 0) / "final.pt")[0]
    assert agent.dfo_config.select == "argmax"
    assert with_dfo(agent, {"select": "sample"}).dfo_config.select == "sample"
    bc = load_agent(run_dir(replicated, "bc", 0) / "final.pt")[0]
    assert with_dfo(bc, {"select": "sample"}) is bc and bc.dfo_config is None
    with pytest.raises(ValueError, match="dfo must hold"):
        with_dfo(agent, {"temperature": 2})
    with pytest.raises(ValueError, match="dfo must hold"):
        DriveProtocol(dfo={"temperature": 2})
    with pytest.raises(ValueError, match="episodes must be"):
        DriveProtocol(episodes=0)
    with pytest.raises(ValueError, match="table_seeds must be True or False"):
        DriveProtocol(table_seeds="yes")
    with pytest.raises(ValueError, match="protocol must be a DriveProtocol"):
        run_drives(replicated, out, {"episodes": 1})


def test_stem_drives_with_the_table_seeds_repeat_the_recorded_table_episodes(replicated, tmp_path):
    """``stems drive --table-seeds``: each agent's DFO draws seeded with its training seed, so that a second
    drive of the table's starts repeats, on the same machine, the episodes ``replicate`` recorded."""
    from ibc_tutorial.experiments.agents.replication_folder import STEM_DRIVE
    from ibc_tutorial.experiments.agents.stem_drives import DriveProtocol, run_drives, table_policy_seed

    assert table_policy_seed("da-ibc-seed3") == 3 and table_policy_seed("expert") == 0
    for bad in ("da-ibc", "ibc-seedx", "dqn-seed1"):
        with pytest.raises(ValueError, match="name must be 'expert' or '<method>-seed<k>'"):
            table_policy_seed(bad)
    out = tmp_path / "again"
    table = DriveProtocol(episodes=TINY.final_episodes, steps=TINY.final_steps, table_seeds=True)
    done = run_drives(replicated, out, table, only=["da-ibc-seed0"], log=None)
    assert done == ["da-ibc-seed0"]
    assert json.loads((out / "provenance.json").read_text())["protocol"]["policy_seed"] == "training seed"
    with (
        np.load(out / "drives" / "da-ibc-seed0.npz") as again,
        np.load(run_dir(replicated, "da-ibc", 0) / STEM_DRIVE) as recorded,
    ):
        assert sorted(again.files) == sorted(recorded.files)
        for k in recorded.files:
            assert np.array_equal(again[k], recorded[k]), k


def test_observation_and_landscape_at_a_kept_state(replicated, tmp_path):
    from ibc_tutorial.experiments.agents.stem_analysis import landscape_at, observation_at
    from ibc_tutorial.experiments.agents.stem_drives import TRACE
    from ibc_tutorial.experiments.runs import write_npz

    agent = load_agent(run_dir(replicated, "da-ibc", 0) / "final.pt")[0]
    s = agent.preset.bev_size
    bev = (np.arange(5 * s * s).reshape(5, s, s) % 3 == 0).astype(np.float32)  # (5, S, S) of 0 and 1
    arrays = {f"e0_{k}": np.zeros(3) for k in TRACE}
    arrays["rows"] = np.array(json.dumps([{"termination": ""}]))
    arrays["obs_episode"], arrays["obs_t"] = np.array([0, 0], np.int16), np.array([4, 7], np.int32)
    arrays["obs_state"] = np.array([[1, 0, 0], [2, 0.1, 0.2]], np.float32)
    arrays["obs_bev"] = np.packbits(np.stack([bev * 0, bev]).astype(np.uint8), axis=-1)  # (2, 5, S, S / 8)
    path = write_npz(tmp_path / "drive.npz", arrays)
    got_bev, got_state = observation_at(path, 0, 7)
    assert np.array_equal(got_bev, bev) and got_state.tolist() == pytest.approx([2, 0.1, 0.2])
    with pytest.raises(ValueError, match="episode 0, state 5"):
        observation_at(path, 0, 5)
    land = landscape_at(agent, got_bev, got_state, n_grid=9, draws=4)
    assert land["energy"].shape == (9, 9) and land["energy"].min() == 0.0 and land["points"].shape == (4, 2)
    assert (np.abs(land["points"]) <= 1).all() and land["steer"][0] == -1.0


STEM_ABLATIONS = {  # folder -> (its --set overrides, its seeds)
    "turn-hold": (
        ["turn_hold_m=0.5", "seeds=0,1,2", "heldout_episodes=0", "routeless_episodes=0"],
        (0, 1, 2),
    ),
    "half-epochs": (
        ["epochs=4", "heldout_episodes=0", "routeless_episodes=0"],
        (0, 1, 2, 3, 4),
    ),
}


@pytest.mark.parametrize("name", sorted(STEM_ABLATIONS))
def test_the_shipped_stem_ablations_are_the_ten_routes_preset_with_their_overrides(name):
    folder = SHIPPED.parent / "ablations" / name
    if not (folder / "provenance.json").exists():
        pytest.skip(f"no shipped {name} ablation")
    prov = json.loads((folder / "provenance.json").read_text())
    overrides, seeds = STEM_ABLATIONS[name]
    assert prov["overrides"] == overrides
    assert differences(Preset.from_dict(prov["preset"]), with_overrides(TEN_ROUTES, prov["overrides"])) == {}
    assert prov["complete"] and "uncommitted" not in prov["commit"] and len(prov["invocations"]) == 1
    analysed = sorted(p.stem for p in (folder / "stems" / "analysis").glob("*-seed*.json"))
    assert analysed == sorted(f"{m}-seed{s}" for m in METHODS for s in seeds)


def _is_clean_ancestor(commit: str) -> None:
    root = SHIPPED.parents[2]
    assert "uncommitted" not in commit and re.fullmatch(r"[0-9a-f]{40}", commit), commit
    if (root / ".git").exists():
        ancestor = subprocess.run(["git", "-C", str(root), "merge-base", "--is-ancestor", commit, "HEAD"])
        assert ancestor.returncode == 0, f"commit {commit} is not an ancestor of HEAD"


def test_the_shipped_older_cpu_stem_drives_repeat_the_table_protocol():
    """``laptop/stems-emulated``: every agent and the expert driven again on the table's starts with the
    table's DFO seeds, under the older CPU's environment, from clean ancestor commits; each one analysed."""
    folder = SHIPPED / "stems-emulated"
    if not (folder / "summary.json").exists():
        pytest.skip("no shipped older-CPU stem drives")
    names = sorted([f"{m}-seed{s}" for m in METHODS for s in LAPTOP.seeds] + ["expert"])
    driven = []
    for part in sorted(folder.glob("provenance_drive_*.json")):
        prov = json.loads(part.read_text())
        assert prov["protocol"] == {
            "episodes": LAPTOP.final_episodes,
            "steps": LAPTOP.final_steps,
            "town": "town02",
            "seed": 1000,
            "policy_seed": "training seed",
        }
        for inv in prov["invocations"]:
            assert inv["machine"]["cpu_capability"] == "DEFAULT"
            assert inv["machine"]["cpu_environment"]["ATEN_CPU_CAPABILITY"] == "default"
            _is_clean_ancestor(inv["commit"])
            driven += list(inv["cpu_seconds"])
    assert sorted(driven) == names
    analysed = sorted(p.stem for p in (folder / "analysis").glob("*.json") if p.stem != "provenance")
    assert analysed == names


def test_the_shipped_reevaluations_are_the_seed0_agents_here_and_on_the_older_cpu():
    files = sorted((SHIPPED / "reevaluated").glob("*.json"))
    if not files:
        pytest.skip("no shipped re-evaluations")
    assert [f.stem for f in files] == sorted(f"{m}_{w}" for m in METHODS for w in ("native", "emulated_cpu"))
    for f in files:
        ev = json.loads(f.read_text())
        assert ev["checkpoint"].endswith(f"runs/{f.stem.split('_')[0]}/seed0/final.pt")
        assert (ev["machine"]["cpu_capability"] == "DEFAULT") == f.stem.endswith("emulated_cpu")
        _is_clean_ancestor(ev["commit"])


def test_a_drive_protocol_checks_its_dfo_values_before_any_drive():
    """``DriveProtocol(dfo=...)``: a bad value is refused when the protocol is built, by ``DFOConfig``'s own
    check, not when the first energy agent drives."""
    from ibc_tutorial.experiments.agents.stem_drives import DriveProtocol

    dfo = {"samples": 64, "select": "sample"}
    assert DriveProtocol(dfo=dfo).record()["dfo"] == dfo
    with pytest.raises(ValueError, match="n_samples"):
        DriveProtocol(dfo={"samples": 0})
    with pytest.raises(ValueError, match="select"):
        DriveProtocol(dfo={"select": "best"})


def test_the_progress_lines_say_how_many_runs_and_how_long():
    from ibc_tutorial.experiments.agents.replicate import run_plan, time_left
    from ibc_tutorial.utils import plural

    assert (
        plural(1, "episode") == "1 episode" and plural(3, "run") == "3 runs" and plural(0, "run") == "0 runs"
    )
    assert run_plan(15, 15, 2) == "15 training runs to do of 15, 2 at a time"
    assert run_plan(1, 15, 2) == "1 training run to do of 15, 1 at a time"
    assert time_left(600.0, 2, 6) == "10.0 min elapsed, about 20 min left"  # 5 min per run, 4 runs left
    assert time_left(600.0, 6, 6) == "10.0 min elapsed, none left"
    assert time_left(20.0, 1, 2) == "0.3 min elapsed, under a minute left"


def test_a_finished_replication_run_again_says_nothing_was_left_to_do(tiny_replication, tmp_path, capsys):
    out = tmp_path / "rep"
    shutil.copytree(tiny_replication, out)
    assert cli.main(["replicate", "--preset", "tiny", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "nothing left to do: all 3 training runs of this replication were already finished" in printed
    assert "training run to do" not in printed and "run 1 of" not in printed


@pytest.mark.parametrize("name", ["commands-branched", "commands-input"])
def test_the_shipped_heldout_route_drives_cover_every_command_agent_from_a_clean_ancestor_commit(name):
    """Chapter 11's routes drawn afresh: every agent of the command folder and the expert drove every one of
    the routes its protocol draws, with commands exactly when the agent takes them, from clean commits."""
    from ibc_tutorial.driving.route_following import heldout_routes
    from ibc_tutorial.experiments.agents.route_study import load_route_drives

    folder = SHIPPED.parent / name
    if not (folder / "heldout-routes").exists():
        pytest.skip("no shipped held-out route drives")
    prov = json.loads((folder / "heldout-routes" / "provenance.json").read_text())
    protocol = prov["protocol"]
    assert protocol["folder"] == name and protocol["max_steps"] is None
    routes = sorted(n for n, _ in heldout_routes(protocol["heldout_seed"], protocol["heldout_count"]))
    drives = load_route_drives(folder / "heldout-routes")
    seeds = json.loads((folder / "results.json").read_text())["preset"]["seeds"]
    assert set(drives) == {f"{m}-seed{s}" for m in METHODS for s in seeds} | {"expert"}
    for driver, d in drives.items():
        assert d["commands"] is (driver != "expert") and sorted(r["route"] for r in d["episodes"]) == routes
    root = SHIPPED.parents[2]
    for inv in prov["invocations"]:
        assert "uncommitted" not in inv["commit"] and re.fullmatch(r"[0-9a-f]{40}", inv["commit"])
        if (root / ".git").exists():
            ancestor = subprocess.run(
                ["git", "-C", str(root), "merge-base", "--is-ancestor", inv["commit"], "HEAD"]
            )
            assert ancestor.returncode == 0, f"commit {inv['commit']} is not an ancestor of HEAD"
