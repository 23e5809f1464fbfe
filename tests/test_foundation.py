"""Tests of the foundation: package metadata, CLI, seeding, argument checks, atomic writes,
the shared training loop, the exercise-feedback core and the notebook executor."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch

import ibc_tutorial
from ibc_tutorial import utils
from ibc_tutorial.exercises import core
from ibc_tutorial.training import TrainConfig, train

ROOT = Path(__file__).resolve().parents[1]


def test_version_matches_cli():
    out = subprocess.run(
        [sys.executable, "-m", "ibc_tutorial", "--version"], capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == f"ibc-tutorial {ibc_tutorial.__version__}"


def test_cli_without_command_prints_help():
    out = subprocess.run([sys.executable, "-m", "ibc_tutorial"], capture_output=True, text=True, check=True)
    assert "usage: ibc-tutorial" in out.stdout


def test_seed_everything_reproduces_draws():
    g1 = utils.seed_everything(3)
    a = torch.rand(4), torch.rand(4, generator=g1)
    g2 = utils.seed_everything(3)
    b = torch.rand(4), torch.rand(4, generator=g2)
    assert torch.equal(a[0], b[0]) and torch.equal(a[1], b[1])


@pytest.mark.parametrize("bad", [-1, 1.5, "0", True])
def test_seed_everything_rejects_bad_seed(bad):
    with pytest.raises(ValueError, match="seed"):
        utils.seed_everything(bad)


def test_checks_name_the_argument():
    with pytest.raises(ValueError, match="n_neg must be >= 1"):
        utils.check_int("n_neg", 0, minimum=1)
    with pytest.raises(ValueError, match="sigma must be a finite number > 0"):
        utils.check_positive("sigma", float("nan"))
    with pytest.raises(ValueError, match="init must be one of"):
        utils.check_choice("init", "gaussian", ["uniform", "kde"])
    with pytest.raises(ValueError, match=r"actions must have shape \(\*, 2\), got \(3, 1\)"):
        utils.check_tensor("actions", torch.zeros(3, 1), shape=(None, 2))
    with pytest.raises(ValueError, match="obs must be finite"):
        utils.check_tensor("obs", torch.tensor([float("nan")]))
    assert utils.check_positive("h", 0, allow_zero=True) == 0.0


def test_config_checks_name_the_field():
    from dataclasses import dataclass

    @dataclass
    class Cfg:
        speed: float = 1.0
        noise: float = 0.0
        p: float = 0.5

    utils.check_positive_fields(Cfg(), ("speed",))
    utils.check_positive_fields(Cfg(), ("noise",), allow_zero=True)
    with pytest.raises(ValueError, match=r"config\.noise must be a finite number > 0"):
        utils.check_positive_fields(Cfg(), ("speed", "noise"))
    assert utils.check_probability("config.p", Cfg().p) == 0.5
    for bad in (1.5, -0.1, float("nan"), "x", "0.5"):
        with pytest.raises(ValueError, match=r"config\.p must be a probability in \[0, 1\]"):
            utils.check_probability("config.p", bad)
    assert utils.check_fraction("config.noise", 1) == 1.0
    for bad in (1.5, -0.1, float("nan"), "x", None):
        with pytest.raises(ValueError, match=r"config\.noise must be a fraction in \[0, 1\]"):
            utils.check_fraction("config.noise", bad)


@pytest.mark.parametrize(
    "make, name",
    [
        (
            lambda v: __import__("ibc_tutorial.driving.expert", fromlist=["x"]).ExpertConfig(brake_noise=v),
            "ExpertConfig.brake_noise",
        ),
        (
            lambda v: __import__("ibc_tutorial.driving.collect", fromlist=["x"]).CollectConfig(brake_noise=v),
            "CollectConfig.brake_noise",
        ),
        (
            lambda v: __import__("dataclasses").replace(
                __import__("ibc_tutorial.experiments.agents.presets", fromlist=["x"]).LAPTOP, brake_noise=v
            ),
            "CollectConfig.brake_noise",  # a preset's setting is checked by the config that defines it
        ),
    ],
)
def test_brake_noise_is_checked_as_a_fraction_wherever_it_is_set(make, name):
    make(0.5)
    for bad in (1.5, float("nan"), "1"):
        with pytest.raises(ValueError, match=name.replace(".", r"\.") + r" must be a fraction in \[0, 1\]"):
            make(bad)


def test_atomic_write_replaces_whole_file_and_leaves_no_temp(tmp_path):
    p = tmp_path / "sub" / "f.bin"
    utils.atomic_write_bytes(p, b"first")
    utils.atomic_write_bytes(p, b"second")
    assert p.read_bytes() == b"second"
    assert [q.name for q in p.parent.iterdir()] == ["f.bin"]


def test_atomic_torch_save_loads_with_weights_only(tmp_path):
    p = utils.atomic_torch_save({"w": torch.arange(3)}, tmp_path / "ckpt.pt")
    assert torch.equal(torch.load(p, weights_only=True)["w"], torch.arange(3))


def test_progress_is_silent_when_quiet(monkeypatch, capsys):
    assert utils.QUIET_ENV == "TQDM_DISABLE"  # tqdm's own switch
    monkeypatch.setenv(utils.QUIET_ENV, "1")
    assert utils.quiet()
    assert list(utils.progress(range(3))) == [0, 1, 2]
    assert capsys.readouterr().err == ""
    for off in ("", "0", "false"):
        monkeypatch.setenv(utils.QUIET_ENV, off)
        assert not utils.quiet()
    assert utils.progress(range(3), enabled=False).disable


def _line_data(n=256, seed=0):
    g = torch.Generator().manual_seed(seed)
    x = torch.rand(n, 1, generator=g) * 2 - 1
    return {"x": x, "y": 3 * x - 0.5}


def _mse(model):
    return lambda batch, gen: ((model(batch["x"]) - batch["y"]) ** 2).mean()


def test_train_fits_a_line_and_is_reproducible():
    results = []
    for _ in range(2):
        torch.manual_seed(0)
        model = torch.nn.Linear(1, 1)
        res = train(
            model, _mse(model), _line_data(), TrainConfig(steps=300, batch_size=32, lr=0.05, log_every=100)
        )
        results.append((res.losses, model.weight.item(), model.bias.item()))
    assert results[0] == results[1]
    losses, w, b = results[0]
    assert res.steps == [100, 200, 300]
    assert losses[-1] < 1e-3 < losses[0]
    assert w == pytest.approx(3.0, abs=0.02) and b == pytest.approx(-0.5, abs=0.02)


def test_train_sample_probs_draw_only_weighted_samples():
    data = {"i": torch.arange(10)}
    seen = []
    model = torch.nn.Linear(1, 1)

    def loss_fn(batch, gen):
        seen.append(batch["i"])
        return model.weight.sum() * 0.0 + model.bias.sum() * 0.0

    probs = torch.zeros(10)
    probs[[2, 7]] = 0.5
    train(model, loss_fn, data, TrainConfig(steps=20, batch_size=16), sample_probs=probs)
    drawn = torch.cat(seen)
    assert set(drawn.tolist()) == {2, 7}
    assert 0.35 < (drawn == 2).float().mean().item() < 0.65


def test_train_rejects_bad_input():
    model = torch.nn.Linear(1, 1)
    with pytest.raises(ValueError, match="share a non-zero first dimension"):
        train(model, _mse(model), {"x": torch.zeros(3, 1), "y": torch.zeros(4, 1)})
    with pytest.raises(ValueError, match="config.steps"):
        train(model, _mse(model), _line_data(), TrainConfig(steps=0))
    with pytest.raises(ValueError, match=r"sample_probs must have shape \(256\)"):
        train(model, _mse(model), _line_data(), TrainConfig(steps=1), sample_probs=torch.ones(5))
    with pytest.raises(ValueError, match="finite scalar"):
        train(model, lambda b, g: model(b["x"]).sum() * float("nan"), _line_data(), TrainConfig(steps=1))


def test_feedback_core_never_raises_on_reader_code():
    def stub():
        raise NotImplementedError

    def broken():
        return 1 / 0

    assert core.run_check(stub).status == core.NOT_ATTEMPTED
    fb = core.run_check(broken)
    assert fb.status == core.HINT and "ZeroDivisionError" in fb.message
    assert core.run_check(lambda: core.correct("yes")).correct
    assert repr(core.hint("look at the sign")) == "[hint] look at the sign"


def test_executor_runs_a_notebook_in_place(tmp_path):
    import nbformat

    nb = nbformat.v4.new_notebook()
    nb.cells = [nbformat.v4.new_code_cell("import os\nprint(os.environ.get('TQDM_DISABLE'), 1 + 1)")]
    path = tmp_path / "t.ipynb"
    nbformat.write(nb, path)
    subprocess.run(
        [sys.executable, str(ROOT / "tools" / "execute_notebooks.py"), str(path)],
        check=True,
        capture_output=True,
    )
    cell = json.loads(path.read_text())["cells"][0]
    assert cell["execution_count"] == 1
    assert "".join(cell["outputs"][0]["text"]) == "1 2\n"
    assert "execution" not in cell["metadata"]


def test_atomic_write_gives_the_usual_file_mode(tmp_path):
    mask = os.umask(0o022)
    try:
        p = utils.atomic_write_bytes(tmp_path / "f.txt", b"x")
    finally:
        os.umask(mask)
    assert p.stat().st_mode & 0o777 == 0o644


def test_version_imports_no_subcommand_module():
    code = (
        "import sys; from ibc_tutorial.cli import main\ntry: main(['--version'])\nexcept SystemExit: pass\n"
        "print('pymunk' in sys.modules, 'gymnasium' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip().endswith("False False")


def test_help_lists_every_command_without_importing_them():
    code = (
        "import sys; from ibc_tutorial.cli import main\ntry: main(['--help'])\nexcept SystemExit: pass\n"
        "print([m for m in sys.modules\n"
        "       if m.startswith(('ibc_tutorial.driving', 'ibc_tutorial.experiments'))])"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    for command in ("collect", "train", "evaluate", "replicate"):
        assert command in out.stdout
    assert out.stdout.strip().endswith("[]")


def test_likelihood_objective_is_the_policys_loss_and_rejects_non_policies():
    from ibc_tutorial.objectives import likelihood_objective
    from ibc_tutorial.policies import RegressionPolicy

    torch.manual_seed(0)
    policy = RegressionPolicy.for_vectors(2, 1)
    batch = {"obs": torch.randn(8, 2), "actions": torch.rand(8, 1) * 2 - 1}
    loss = likelihood_objective(policy)(batch, torch.Generator())
    assert torch.equal(loss, policy.loss(batch["obs"], batch["actions"]))
    with pytest.raises(ValueError, match="loss"):
        likelihood_objective(torch.nn.Linear(2, 1))
