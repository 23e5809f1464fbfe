"""``ibc-tutorial replicate-steering`` end to end on the tiny preset: files, resume, refusals."""

import json

import pytest

from ibc_tutorial import cli
from ibc_tutorial.experiments.steering import replicate as R
from ibc_tutorial.experiments.steering.models import MODELS
from ibc_tutorial.experiments.steering.presets import LAPTOP, TINY
from ibc_tutorial.experiments.steering.train import load_model, run_dir


def _run(*argv) -> int:
    return cli.main(["replicate-steering", *argv])


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    out = tmp_path_factory.mktemp("steering") / "study"
    assert _run("--preset", "tiny", "--out", str(out), "--threads", "1") == 0
    return out


def test_tiny_study(study):
    loaded = R.load_results(study)
    res, prov, traces = loaded["results"], loaded["provenance"], loaded["traces"]
    assert res["complete"] and res["preset"] == TINY.to_dict() and set(res["table"]) == set(MODELS)
    assert res["data"]["samples"] == int(TINY.routes * TINY.route_minutes * 600)
    assert set(res["data"]["side_roads"]) == {"straight", "side_road", "share", "stem"}
    assert res["references"]["y82-west"]["side_road_passes"] == 1
    for m in MODELS:
        run = res["runs"][m]["0"]
        (route,) = run["routes"]
        assert route["route"] == "y82-west" and len(route["swerve_score"]) == 1
        assert run["summary"]["passes"] == 1 and run["losses"][-1][0] == TINY.steps
        t = res["table"][m]
        assert t["seeds"] == 1 and t["crashes_per_km"]["n"] == 1
        assert t["w_cmd_paper_deg_s"]["mean"] == pytest.approx(250 * t["w_cmd"]["mean"], rel=1e-3)
        steps = res["fig5"]["steps"]
        assert traces[f"{m}/seed0/steer"].shape == (steps[1] - steps[0],)
        assert (f"{m}/seed0/scores" in traces) == (m != "regression")
        assert not (run_dir(study, m, 0) / "last.pt").exists()
        assert load_model(run_dir(study, m, 0) / "final.pt", m, TINY).name == m
    assert prov["complete"] and prov["runs_done"] == prov["runs_planned"] and not prov["resumed"]
    assert "replicate-steering --preset tiny" in prov["command"]
    assert "wall time" in (study / "PROVENANCE.md").read_text()
    assert res["paper"]["table2_swerve_rate"]["regression"] == 0.89


def test_resumes_and_refuses(study, tmp_path):
    before = (run_dir(study, "ebm", 0) / "eval.json").read_text()
    assert _run("--preset", "tiny", "--out", str(study)) == 0  # nothing left to do: nothing retrained
    assert (run_dir(study, "ebm", 0) / "eval.json").read_text() == before
    prov = json.loads((study / "provenance.json").read_text())
    assert prov["resumed"] and len(prov["invocations"]) == 2
    with pytest.raises(ValueError, match="another preset"):
        R.check_folder(study, LAPTOP)
    (tmp_path / "notes.txt").write_text("mine")
    with pytest.raises(ValueError, match="other files"):
        R.check_folder(tmp_path, TINY)


def test_an_interrupted_run_resumes_from_last_pt(tmp_path, monkeypatch):
    """A run stopped after its checkpoint at step 2 continues from last.pt and ends as the uninterrupted
    one."""
    import shutil

    import torch

    from ibc_tutorial.driving.dataset import DemoDataset
    from ibc_tutorial.experiments.steering import train as T
    from ibc_tutorial.experiments.steering.task import collect_demonstrations

    log = collect_demonstrations(1, 0.1, 0.15, seed=0)
    ds = DemoDataset(log, bev_size=TINY.bev_size)
    monkeypatch.setattr(T, "CHECKPOINT_EVERY", 2)
    snapshot = tmp_path / "step2.pt"
    save = T.save_model_checkpoint

    def spy(path, **kw):
        p = save(path, **kw)
        if kw["trainer"] is not None and kw["trainer"].step == 2:
            shutil.copy(p, snapshot)
        return p

    monkeypatch.setattr(T, "save_model_checkpoint", spy)
    for name in ("ebm-smooth", "mdn"):
        full, losses, _, resumed = T.train_model(
            name, 0, ds, TINY, tmp_path / name / "a", data_sha256=log.checksum()
        )
        assert resumed == 0 and [s for s, _ in losses] == [2, 4, 6]
        (tmp_path / name / "b").mkdir(parents=True)
        shutil.copy(snapshot, tmp_path / name / "b" / "last.pt")
        again, losses_b, _, resumed = T.train_model(
            name, 0, ds, TINY, tmp_path / name / "b", data_sha256=log.checksum()
        )
        assert resumed == 2 and losses_b == losses
        a, b = full.network.state_dict(), again.network.state_dict()
        assert all(torch.equal(a[k], b[k]) for k in a)  # bit for bit
    with pytest.raises(ValueError, match="other demonstrations"):
        T.train_model("mdn", 0, ds, TINY, tmp_path / "mdn" / "b", data_sha256="0" * 64)
    with pytest.raises(ValueError, match="other settings"):
        T.load_model_checkpoint(tmp_path / "mdn" / "b" / "last.pt", model="ebm", preset=TINY)
