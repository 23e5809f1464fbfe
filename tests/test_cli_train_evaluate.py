"""``ibc-tutorial train`` and ``evaluate`` on a tiny live-collected dataset (seconds each)."""

import json

import pytest
import torch

from ibc_tutorial import cli
from ibc_tutorial.driving.collect import CollectConfig, collect
from ibc_tutorial.driving.dataset import DemoLog
from ibc_tutorial.driving.sim import score
from ibc_tutorial.experiments.agents.checkpoints import load_checkpoint
from ibc_tutorial.experiments.agents.presets import TINY
from ibc_tutorial.experiments.agents.training_run import read_metrics


@pytest.fixture(scope="module")
def data(tiny_demonstrations):
    """The tiny preset's demonstrations, collected once for the session (tests/conftest.py)."""
    return tiny_demonstrations


@pytest.mark.parametrize("method", ["bc", "ibc", "da-ibc", "flow", "da-ibc-rnce"])
def test_train_then_evaluate(method, data, tmp_path, capsys):
    out = tmp_path / method
    assert (
        cli.main(
            [
                "train",
                "--method",
                method,
                "--data",
                str(data),
                "--preset",
                "tiny",
                "--seed",
                "0",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    metrics = read_metrics(out)
    assert [m["epoch"] for m in metrics] == list(range(1, TINY.epochs + 1))  # eval_every = 1
    for m in metrics:
        assert (
            m["method"] == method
            and m["eval"]["episodes"] == TINY.eval_episodes
            and len(m["episodes"]) == TINY.eval_episodes
        )
    ckpt = load_checkpoint(out / "final.pt", method=method, preset=TINY)
    assert ckpt["data_sha256"] == DemoLog.load(data).checksum() and ckpt["epoch"] == TINY.epochs
    report = tmp_path / "eval.json"
    assert (
        cli.main(
            [
                "evaluate",
                "--checkpoint",
                str(out / "final.pt"),
                "--episodes",
                "3",
                "--steps",
                "12",
                "--out",
                str(report),
            ]
        )
        == 0
    )
    printed = capsys.readouterr().out
    assert "mean score" in printed
    ev = json.loads(report.read_text())
    assert len(ev["episodes"]) == 3 and ev["method"] == method
    for r in ev["episodes"]:
        assert r["steps"] <= 12
        assert r["score"] == pytest.approx(score(r["distance_m"], r["red_light_infractions"]), abs=0.01)
    assert ev["commit"] and ev["package_version"] and ev["machine"]["nproc"] >= 1
    if method == "da-ibc":  # --crossings adds each episode's junction crossings and changes nothing else
        crossed = tmp_path / "crossings.json"
        assert (
            cli.main(
                [
                    "evaluate",
                    "--checkpoint",
                    str(out / "final.pt"),
                    "--episodes",
                    "3",
                    "--steps",
                    "12",
                    "--out",
                    str(crossed),
                    "--crossings",
                ]
            )
            == 0
        )
        rows = json.loads(crossed.read_text())["episodes"]
        assert all(isinstance(r.pop("junction_crossings"), list) for r in rows)
        assert rows == ev["episodes"]


@pytest.mark.parametrize("method", ["da-ibc", "flow"])
def test_resume_continues_exactly(method, data, tmp_path):
    whole, parts = tmp_path / "whole", tmp_path / "parts"
    base = ["train", "--method", method, "--data", str(data), "--preset", "tiny", "--seed", "1"]
    assert cli.main(base + ["--out", str(whole)]) == 0
    assert cli.main(base + ["--out", str(parts), "--epochs", "1"]) == 0  # "interrupted" after epoch 1
    assert cli.main(base + ["--out", str(parts)]) == 0  # resumes from last.pt
    a = torch.load(whole / "final.pt", weights_only=True)["model"]
    b = torch.load(parts / "final.pt", weights_only=True)["model"]
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert [m["loss"] for m in read_metrics(whole)] == [m["loss"] for m in read_metrics(parts)]
    # evaluate's policy seed defaults to the agent's training seed (1 here), as replicate's final evaluation
    reports = [tmp_path / "default.json", tmp_path / "seed1.json", tmp_path / "seed0.json"]
    for report, extra in zip(reports, ([], ["--policy-seed", "1"], ["--policy-seed", "0"]), strict=True):
        assert (
            cli.main(
                ["evaluate", "--checkpoint", str(whole / "final.pt"), "--steps", "12", "--out", str(report)]
                + extra
            )
            == 0
        )
    default, seed1, seed0 = (json.loads(r.read_text()) for r in reports)
    assert (
        default["policy_seed"] == 1 and default["episodes"] == seed1["episodes"] and seed0["policy_seed"] == 0
    )


def test_resume_accepts_the_same_demonstrations_collected_again(data, tmp_path):
    """The run records the demonstrations' content, not the file's bytes (which hold the time it was
    written)."""
    out = tmp_path / "run"
    base = ["train", "--method", "bc", "--preset", "tiny", "--seed", "0", "--out", str(out)]
    assert cli.main(base + ["--data", str(data), "--epochs", "1"]) == 0
    again = tmp_path / "again.npz"
    collect(TINY.collect_config(), show_progress=False).save(again)  # the settings that made ``data``
    assert cli.main(base + ["--data", str(again)]) == 0
    assert [m["epoch"] for m in read_metrics(out)] == list(range(1, TINY.epochs + 1))


def test_resume_refuses_another_data_file(data, tmp_path, capsys):
    out = tmp_path / "run"
    base = ["train", "--method", "bc", "--preset", "tiny", "--seed", "0", "--out", str(out)]
    assert cli.main(base + ["--data", str(data), "--epochs", "1"]) == 0
    other = tmp_path / "other.npz"
    collect(CollectConfig(routes=1, seed=5, min_minutes=0.15, max_minutes=0.2), show_progress=False).save(
        other
    )
    assert cli.main(base + ["--data", str(other)]) == 2
    assert "other demonstrations" in capsys.readouterr().err
    assert cli.main(base + ["--data", str(other), "--force"]) == 0  # --force starts over on the other data
    assert torch.load(out / "final.pt", weights_only=True)["data_sha256"] == DemoLog.load(other).checksum()


def test_epochs_below_the_run_are_refused_and_a_finished_run_is_not_retrained(data, tmp_path, capsys):
    out = tmp_path / "run"
    base = [
        "train",
        "--method",
        "bc",
        "--data",
        str(data),
        "--preset",
        "tiny",
        "--seed",
        "0",
        "--out",
        str(out),
    ]
    assert cli.main(base) == 0  # 2 epochs
    final = (out / "final.pt").read_bytes()
    capsys.readouterr()
    assert cli.main(base + ["--epochs", "1"]) == 2
    assert "trained to epoch 2 already, beyond the 1 epochs" in capsys.readouterr().err
    assert cli.main(base) == 0
    assert "nothing to do" in capsys.readouterr().out and (out / "final.pt").read_bytes() == final


def test_bad_arguments(data, tmp_path, capsys):
    assert (
        cli.main(["train", "--method", "bc", "--data", str(data), "--preset", "huge", "--out", str(tmp_path)])
        == 2
    )
    assert (
        cli.main(
            [
                "train",
                "--method",
                "bc",
                "--data",
                str(tmp_path / "none.npz"),
                "--preset",
                "tiny",
                "--out",
                str(tmp_path),
            ]
        )
        == 2
    )
    assert cli.main(["evaluate", "--checkpoint", str(tmp_path / "none.pt")]) == 2
    err = capsys.readouterr().err.splitlines()
    assert (
        len(err) == 3
        and "--preset" in err[0]
        and "no demonstration file" in err[1]
        and "no agent checkpoint" in err[2]
    )
