"""Bad files and bad command lines: each is refused with one line on stderr and exit code 2, before any
work, and leaves every file on disk as it was (issue 15)."""

import hashlib
import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from ibc_tutorial import cli
from ibc_tutorial.driving.collect import CollectConfig, collect
from ibc_tutorial.driving.dataset import FORMAT, VERSION, DemoLog
from ibc_tutorial.experiments.agents import replicate as replicate_module
from ibc_tutorial.experiments.agents import train as train_module
from ibc_tutorial.experiments.agents.presets import LAPTOP, TINY
from ibc_tutorial.experiments.agents.replication_folder import load_results

UNWRITABLE = Path("/proc/ibc-tutorial-test/out")  # no file can be created under /proc, even by root


def snapshot(*roots) -> dict:
    """Every file and folder under ``roots``: its SHA-256 (files) and mode."""
    out = {}
    for root in roots:
        root = Path(root)
        for p in [root, *sorted(root.rglob("*"))] if root.exists() else []:
            out[str(p)] = (
                hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else "dir",
                p.stat().st_mode,
            )
    return out


def refused(capsys, argv, *words, roots=()):
    """``cli.main(argv)`` gives exit code 2 and one line holding ``words``, and changes nothing under
    ``roots``."""
    before = snapshot(*roots)
    code = cli.main([str(a) for a in argv])
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert code == 2, err
    assert len(lines) == 1 and "Traceback" not in err, err
    for w in words:
        assert str(w) in lines[0], lines[0]
    assert "weights_only=False" not in err
    assert snapshot(*roots) == before
    return lines[0]


@pytest.fixture(scope="module")
def shared(tmp_path_factory, tiny_demonstrations):
    """The tiny preset's demonstrations (about 100 samples; tests/conftest.py: read, never changed) and a
    finished tiny bc run trained on them."""
    root = tmp_path_factory.mktemp("shared")
    data = tiny_demonstrations
    run = root / "run"
    assert (
        cli.main(["train", "--method", "bc", "--data", str(data), "--preset", "tiny", "--out", str(run)]) == 0
    )
    return root, data, run


def _train(data, out, *extra):
    return [
        str(a) for a in ("train", "--method", "bc", "--data", data, "--preset", "tiny", "--out", out, *extra)
    ]


# ----------------------------------------------------------------------------- demonstration files
def _resave(path, log: DemoLog, meta: dict | None = None):
    """``log`` written with a valid checksum of its content (an adversary's re-saved file)."""
    arrays = {
        k: getattr(log, k)
        for k in ("pose", "speed", "prev_action", "action", "executed", "lights", "episode", "step", "lane")
    }
    meta = dict(log.meta, town=log.town) if meta is None else meta
    np.savez(
        path,
        format=np.array(FORMAT),
        version=np.array(VERSION),
        meta=np.array(json.dumps(meta)),
        checksum=np.array(log.checksum()),
        **arrays,
    )
    return path


def _altered(data, **changes) -> DemoLog:
    log = DemoLog.load(data)
    for name, (index, value) in changes.items():
        getattr(log, name)[index] = value
    return log


BAD_DEMOS = {
    "nan_pose": (lambda log: _altered(log, pose=((3, 0), np.nan)), "pose holds NaN"),
    "off_map": (lambda log: _altered(log, pose=((5, 1), 1e6)), "off town01's map"),
    "light_9": (lambda log: _altered(log, lights=((2, 4), 9)), "lights must be codes"),
    "lane_9999": (lambda log: _altered(log, lane=(7, 9999)), "lane must index"),
    "action_1.5": (lambda log: _altered(log, action=((1, 0), 1.5)), "action must be finite and in [-1, 1]"),
}


@pytest.mark.parametrize("case", sorted(BAD_DEMOS))
def test_demonstrations_with_invalid_values(case, shared, tmp_path, capsys):
    _, data, _ = shared
    make, words = BAD_DEMOS[case]
    bad = _resave(tmp_path / f"{case}.npz", make(data))
    refused(capsys, _train(bad, tmp_path / "out"), bad, words, roots=[tmp_path])
    assert not (tmp_path / "out").exists()


def test_demonstrations_damaged_or_incomplete(shared, tmp_path, capsys):
    _, data, _ = shared
    raw = data.read_bytes()
    (tmp_path / "cut.npz").write_bytes(raw[: len(raw) // 2])
    log = DemoLog.load(data)
    _resave(tmp_path / "no_town.npz", log, meta={k: v for k, v in log.meta.items() if k != "town"})
    _resave(tmp_path / "no_config.npz", log, meta={"town": "town01"})
    with np.load(data) as z:
        np.savez(tmp_path / "no_lights.npz", **{k: z[k] for k in z.files if k != "lights"})
    (tmp_path / "folder.npz").mkdir()
    cases = {
        "cut.npz": "truncated or damaged",
        "no_town.npz": "meta",
        "no_config.npz": "meta lacks",
        "no_lights.npz": "lacks",
        "folder.npz": "is a folder",
    }
    for name, words in cases.items():
        refused(capsys, _train(tmp_path / name, tmp_path / "out"), tmp_path / name, words, roots=[tmp_path])


# ----------------------------------------------------------------------------- checkpoints
def _ckpt(shared, tmp_path, name, change):
    _, _, run = shared
    ckpt = torch.load(run / "final.pt", weights_only=True)
    change(ckpt)
    torch.save(ckpt, tmp_path / name)
    return tmp_path / name


class Foreign:
    """A pickled Python object: ``weights_only=True`` refuses it."""


def test_damaged_checkpoints(shared, tmp_path, capsys):
    _, _, run = shared
    raw = (run / "final.pt").read_bytes()
    (tmp_path / "cut.pt").write_bytes(raw[: len(raw) // 3])
    cases = {
        tmp_path / "cut.pt": "truncated or damaged",
        _ckpt(shared, tmp_path, "no_preset.pt", lambda c: c.pop("preset")): "lacks the field 'preset'",
        _ckpt(shared, tmp_path, "no_epoch.pt", lambda c: c.pop("epoch")): "lacks the field 'epoch'",
        _ckpt(
            shared, tmp_path, "nan.pt", lambda c: next(iter(c["model"].values())).fill_(float("nan"))
        ): "NaN or inf",
        _ckpt(
            shared, tmp_path, "empty_actions.pt", lambda c: c.update(expert_actions=torch.zeros(0, 2))
        ): "expert_actions",
        _ckpt(
            shared, tmp_path, "short_weights.pt", lambda c: c.update(init_weights=torch.ones(3))
        ): "init_weights",
        _ckpt(
            shared, tmp_path, "other_preset.pt", lambda c: c["preset"].update(embed_dim=99)
        ): "preset and its architecture",
        _ckpt(shared, tmp_path, "pickled.pt", lambda c: c.update(extra=Foreign())): "Python objects",
        _ckpt(shared, tmp_path, "list.pt", lambda c: c.update(metrics=7)): "metrics",
    }
    (tmp_path / "folder.pt").mkdir()
    cases[tmp_path / "folder.pt"] = "is a folder"
    for path, words in cases.items():
        refused(
            capsys, ["evaluate", "--checkpoint", path, "--steps", "3"], path, words, roots=[tmp_path, run]
        )


def test_final_checkpoint_as_last_is_not_resumed(shared, tmp_path, capsys):
    _, data, run = shared
    out = tmp_path / "run"
    shutil.copytree(run, out)
    shutil.copy(out / "final.pt", out / "last.pt")
    refused(
        capsys,
        _train(data, out, "--epochs", "3"),
        "last.pt",
        "no optimiser and generator states",
        roots=[tmp_path],
    )


# ----------------------------------------------------------------------------- reused folders
def test_train_refuses_a_folder_of_another_run(shared, tmp_path, capsys):
    root, data, run = shared
    other = tmp_path / "other.npz"
    collect(CollectConfig(routes=1, seed=5, min_minutes=0.15, max_minutes=0.2), show_progress=False).save(
        other
    )
    roots = [root, tmp_path]
    refused(
        capsys,
        ["train", "--method", "da-ibc", "--data", data, "--preset", "tiny", "--out", run],
        "method 'bc'",
        "--force",
        roots=roots,
    )
    refused(capsys, _train(data, run, "--seed", "3"), "seed 0, not 3", roots=roots)
    refused(
        capsys,
        ["train", "--method", "bc", "--data", data, "--preset", "laptop", "--out", run],
        "other settings",
        roots=roots,
    )
    refused(capsys, _train(other, run), "other demonstrations", roots=roots)
    refused(capsys, _train(data, run, "--epochs", "1"), "epoch 2 already", roots=roots)


def test_a_finished_replicated_run_is_never_overwritten(shared, tmp_path, capsys):
    """``replicate`` deletes a finished run's checkpoints; its folder still refuses another run or an
    extension."""
    _, data, run = shared
    out = tmp_path / "run"
    shutil.copytree(run, out)
    (out / "last.pt").unlink()
    (out / "final.pt").unlink()
    (out / "final_eval.json").write_text(
        json.dumps(
            {
                "method": "bc",
                "seed": 0,
                "summary": {},
                "episodes": [
                    {
                        "seed": 1000,
                        "steps": 3,
                        "distance_m": 1.0,
                        "red_light_infractions": 0,
                        "score": 1.0,
                        "termination": "",
                    }
                ],
            }
        )
    )
    refused(
        capsys,
        ["train", "--method", "ibc", "--data", data, "--preset", "tiny", "--out", out],
        "method 'bc'",
        roots=[tmp_path],
    )
    refused(capsys, _train(data, out, "--epochs", "3"), "without its resume state", roots=[tmp_path])
    (out / "run.json").unlink()  # a run of an older version: identified by its metrics
    refused(
        capsys,
        ["train", "--method", "ibc", "--data", data, "--preset", "tiny", "--out", out],
        "method 'bc'",
        roots=[tmp_path],
    )
    assert cli.main(_train(data, out)) == 0 and "nothing to do" in capsys.readouterr().out


def _replication(folder: Path, preset=TINY, data=None) -> Path:
    folder.mkdir(parents=True)
    (folder / "provenance.json").write_text(json.dumps({"preset": preset.to_dict(), "wall_seconds": 3.0}))
    if data is not None:
        (folder / "data").mkdir()
        shutil.copy(data, folder / "data" / "town01.npz")
    return folder


def test_replicate_refuses_other_settings_and_damaged_files(shared, tmp_path, capsys):
    _, data, _ = shared
    rep = _replication(tmp_path / "rep", data=data)
    refused(
        capsys,
        ["replicate", "--preset", "laptop", "--out", rep],
        "preset 'tiny', not 'laptop'",
        "--force",
        roots=[tmp_path],
    )
    only_data = tmp_path / "only_data"
    (only_data / "data").mkdir(parents=True)
    shutil.copy(data, only_data / "data" / "town01.npz")
    refused(
        capsys,
        ["replicate", "--preset", "laptop", "--out", only_data],
        "collected with other settings",
        roots=[tmp_path],
    )
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine")
    refused(
        capsys, ["replicate", "--preset", "tiny", "--out", foreign], "not a replication", roots=[tmp_path]
    )
    refused(
        capsys,
        ["replicate", "--preset", "tiny", "--out", foreign, "--force"],
        "not a replication",
        roots=[tmp_path],
    )
    damaged = {
        "results.json": (b'{"table": ', "not readable JSON"),
        "provenance.json": (b"[1, 2]", "holds a list"),
    }
    for name, (content, words) in damaged.items():
        (rep / name).write_bytes(content)
        refused(capsys, ["replicate", "--preset", "tiny", "--out", rep], rep / name, words, roots=[tmp_path])
        (rep / name).unlink()
    raw = data.read_bytes()
    (rep / "data" / "town01.npz").write_bytes(raw[:100])
    refused(
        capsys,
        ["replicate", "--preset", "tiny", "--out", rep],
        rep / "data" / "town01.npz",
        "truncated",
        roots=[tmp_path],
    )
    shutil.copy(data, rep / "data" / "town01.npz")
    run = rep / "runs" / "bc" / "seed0"
    run.mkdir(parents=True)
    (run / "final_eval.json").write_text("{")
    refused(
        capsys,
        ["replicate", "--preset", "tiny", "--out", rep],
        run / "final_eval.json",
        "damaged",
        roots=[tmp_path],
    )
    (run / "final_eval.json").unlink()
    (run / "metrics.jsonl").write_text('{"epoch": 1}\n')
    refused(
        capsys,
        ["replicate", "--preset", "tiny", "--out", rep],
        run / "metrics.jsonl",
        "line 1",
        roots=[tmp_path],
    )


def test_load_results_names_damaged_files(tmp_path):
    rep = _replication(tmp_path / "rep")
    (rep / "results.json").write_text("[1, 2]")
    with pytest.raises(ValueError, match="results.json is damaged"):
        load_results(rep)
    (rep / "results.json").write_text("{}")
    (rep / "free_driving.npz").write_bytes(b"PK\x03\x04 truncated")
    with pytest.raises(ValueError, match="free_driving.npz is truncated or damaged"):
        load_results(rep)


# ----------------------------------------------------------------------------- output paths, checked first
def test_output_paths_are_checked_before_any_work(shared, tmp_path, capsys):
    _, data, run = shared
    existing = tmp_path / "existing.npz"
    existing.write_bytes(b"precious")
    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    (tmp_path / "a_folder").mkdir()
    roots = [tmp_path, run]
    collect_args = ["collect", "--routes", "1", "--min-minutes", "0.1", "--max-minutes", "0.1", "--out"]
    refused(capsys, collect_args + [existing], "exists", "--force", roots=roots)
    refused(capsys, collect_args + [tmp_path / "a_folder"], "is a folder", roots=roots)
    refused(capsys, collect_args + [a_file / "x.npz"], "is a file, not a folder", roots=roots)
    refused(capsys, collect_args + [UNWRITABLE / "x.npz"], "cannot write", roots=roots)
    ev = ["evaluate", "--checkpoint", run / "final.pt", "--out"]
    refused(capsys, ev + [existing], "exists", roots=roots)
    refused(capsys, ev + [tmp_path / "a_folder"], "is a folder", roots=roots)
    refused(capsys, ev + [UNWRITABLE / "e.json"], "cannot write", roots=roots)
    refused(capsys, _train(data, a_file), "is a file, expected a folder", roots=roots)
    refused(capsys, _train(data, a_file / "run"), "is a file, not a folder", roots=roots)
    refused(capsys, _train(data, UNWRITABLE), "cannot write", roots=roots)
    refused(
        capsys,
        ["replicate", "--preset", "tiny", "--out", a_file],
        "is a file, expected a folder",
        roots=roots,
    )
    refused(capsys, ["replicate", "--preset", "tiny", "--out", UNWRITABLE], "cannot write", roots=roots)
    refused(
        capsys,
        _train(tmp_path / "a_folder", tmp_path / "r"),
        "is a folder, expected a demonstration file",
        roots=roots,
    )
    refused(capsys, ["evaluate", "--checkpoint", run], "is a folder", roots=roots)


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_read_only_folder(shared, tmp_path, capsys):
    _, data, _ = shared
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        refused(capsys, _train(data, ro / "run"), "cannot write", roots=[tmp_path])
    finally:
        ro.chmod(0o755)


# --------------------------------------------------------------------------- bad command lines, Ctrl-C, debug
def test_bad_command_lines_are_one_line(shared, tmp_path, capsys):
    _, data, run = shared
    roots = [tmp_path, run]
    refused(capsys, ["train", "--method", "bc", "--data", data], "--out", roots=roots)
    refused(
        capsys,
        ["train", "--method", "sgd", "--data", data, "--out", tmp_path / "x"],
        "invalid choice",
        roots=roots,
    )
    refused(capsys, _train(data, tmp_path / "x", "--epochs", "0"), "--epochs must be >= 1", roots=roots)
    refused(capsys, _train(data, tmp_path / "x", "--epochs", "two"), "invalid int value", roots=roots)
    refused(
        capsys,
        ["evaluate", "--checkpoint", run / "final.pt", "--episodes", "0"],
        "--episodes must be >= 1",
        roots=roots,
    )
    refused(
        capsys, ["collect", "--routes", "0", "--out", tmp_path / "d.npz"], "routes must be >= 1", roots=roots
    )
    refused(
        capsys,
        ["replicate", "--preset", "tiny", "--out", tmp_path / "r", "--workers", "0"],
        "--workers",
        roots=roots,
    )
    refused(
        capsys,
        ["evaluate", "--checkpoint", run / "final.pt", "--routed", "--routeless"],
        "not allowed",
        roots=roots,
    )
    refused(
        capsys,
        ["evaluate", "--checkpoint", run / "final.pt", "--crossings"],
        "--crossings needs --out",
        roots=roots,
    )


def test_interrupt_is_one_line(shared, tmp_path, capsys, monkeypatch):
    _, data, _ = shared

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(train_module, "train_agent", interrupted)
    assert cli.main(_train(data, tmp_path / "run")) == cli.INTERRUPTED
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["ibc-tutorial train: interrupted; re-run the same command to resume"]


def test_debug_shows_the_traceback(shared, tmp_path, monkeypatch):
    _, data, _ = shared
    monkeypatch.setenv(cli.DEBUG_ENV, "1")
    with pytest.raises(cli.UserError, match="no demonstration file"):
        cli.main(_train(tmp_path / "missing.npz", tmp_path / "run"))
    with pytest.raises(ValueError, match="truncated or damaged"):
        (tmp_path / "cut.npz").write_bytes(data.read_bytes()[:-50])
        cli.main(_train(tmp_path / "cut.npz", tmp_path / "run"))


def test_force_clears_only_a_replication(shared, tmp_path):
    from_tiny = _replication(tmp_path / "rep", data=shared[1])
    (from_tiny / "runs" / "bc" / "seed0").mkdir(parents=True)
    (from_tiny / ".hidden-editor-file").write_text("kept")
    replicate_module.clear_folder(from_tiny)
    assert sorted(p.name for p in from_tiny.iterdir()) == [".hidden-editor-file"]
    replicate_module.check_folder(from_tiny, LAPTOP)  # now free for another preset


def test_stems_refuses_a_folder_without_runs_before_any_work(tmp_path, capsys):
    out = tmp_path / "stems"
    code = cli.main(["stems", "drive", "--folder", str(tmp_path / "nowhere"), "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1
    assert "--folder must be a replication folder with runs/" in err
    assert not out.exists()
    assert cli.main(["stems", "sideways"]) == 2  # not a step


@pytest.mark.parametrize(
    "extra, name",
    [(["--dfo-samples", "0"], "--dfo-samples"), (["--dfo-iters", "-1"], "--dfo-iters"),
     (["--episodes", "0"], "--episodes"), (["--steps", "0"], "--steps")],
)  # fmt: skip
def test_stems_refuses_bad_counts_before_any_work(tmp_path, capsys, extra, name):
    (tmp_path / "rep" / "runs").mkdir(parents=True)
    out = tmp_path / "stems"
    code = cli.main(["stems", "drive", "--folder", str(tmp_path / "rep"), "--out", str(out), *extra])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and f"{name} must be a positive integer" in err
    assert not out.exists()
