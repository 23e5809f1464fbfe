"""``--device``: the GPU path, tested on the CPU.

- ``device="cpu"`` changes nothing: training losses, weights and evaluation rows are bit-identical
  to a run without the argument;
- an absent device (CUDA, MPS) and a name that is not a device are refused with one line, exit 2;
- every random draw of a training step, a counter-example sampler and a DFO call comes from the
  generator passed in (torch's global generator is left untouched), so a GPU run, which draws from
  the same seeded CPU generator, draws the same numbers;
- "another device", simulated with torch's ``meta`` device (tensors with shapes and no values): the
  network's forward passes and the samplers put no tensor on the CPU behind the device's back. (Meta
  tensors have no values, so the argument checks' finiteness test is switched off for these tests:
  ``shape_checks_only``.)
"""

import pytest
import torch

import ibc_tutorial.negatives
import ibc_tutorial.policies.encoders
from ibc_tutorial import cli
from ibc_tutorial.driving.collect import CollectConfig, collect
from ibc_tutorial.driving.dataset import DemoDataset
from ibc_tutorial.experiments.agents.agent import Agent, build_network, dfo_config
from ibc_tutorial.experiments.agents.presets import TINY
from ibc_tutorial.experiments.agents.train import DemoBatches, objective_for, train_agent
from ibc_tutorial.negatives import ExpertSampler, UniformSampler, expert_negatives, uniform_negatives
from ibc_tutorial.optimizers.common import select_action
from ibc_tutorial.training import TrainConfig, Trainer
from ibc_tutorial.utils import check_device, check_tensor, draw_device

NO_CUDA = not torch.cuda.is_available()
NO_MPS = not torch.backends.mps.is_available()


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    path = tmp_path_factory.mktemp("demo") / "town01.npz"
    collect(CollectConfig(routes=1, seed=0, min_minutes=0.15, max_minutes=0.2), show_progress=False).save(
        path
    )
    return path


@pytest.fixture(scope="module")
def dataset(data):
    return DemoDataset(data, bev_size=TINY.bev_size, cache=True, light_encoding=TINY.light_encoding)


# --------------------------------------------------------------------------- names
def test_check_device_accepts_the_cpu():
    assert check_device("device", "cpu") == torch.device("cpu")
    assert check_device("device", torch.device("cpu")) == torch.device("cpu")
    assert draw_device(None) == torch.device("cpu") and draw_device(torch.Generator()) == torch.device("cpu")


@pytest.mark.parametrize("name", ["gpu", "cuda:x", "CPU", "", " cpu", "cuda:0:1", "meta", "xla", 0, None])
def test_malformed_or_unsupported_names_are_refused(name):
    with pytest.raises(ValueError, match="--device must be"):
        check_device("--device", name)


@pytest.mark.skipif(not NO_CUDA, reason="this machine has CUDA")
@pytest.mark.parametrize("name", ["cuda", "cuda:0", "cuda:3"])
def test_cuda_is_refused_without_cuda(name, dataset):
    with pytest.raises(ValueError, match=r"--device '.*': CUDA is not available on this machine"):
        check_device("--device", name)
    agent = Agent("bc", build_network("bc", TINY), TINY, dataset.actions)
    with pytest.raises(ValueError, match="device .*CUDA is not available"):
        agent.to(name)
    with pytest.raises(ValueError, match="device .*CUDA is not available"):
        DemoBatches(dataset, name)


@pytest.mark.skipif(not NO_MPS, reason="this machine has MPS")
def test_mps_is_refused_without_mps():
    with pytest.raises(ValueError, match="MPS is not available on this machine"):
        check_device("--device", "mps")


@pytest.mark.skipif(not NO_CUDA, reason="this machine has CUDA")
@pytest.mark.parametrize(
    "command",
    [
        ["train", "--method", "da-ibc", "--data", "missing.npz", "--out", "runs/x"],
        ["evaluate", "--checkpoint", "missing.pt"],
        ["replicate", "--out", "results/x"],
    ],
)
def test_the_commands_refuse_an_absent_device_first(command, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert cli.main(command + ["--device", "cuda"]) == cli.USER_ERROR
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "--device 'cuda': CUDA is not available" in err[0], (
        err
    )  # before the missing file
    assert cli.main(command + ["--device", "gpu"]) == cli.USER_ERROR
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "--device must be a torch device name" in err[0], err
    assert not any(tmp_path.iterdir())  # nothing was written


# --------------------------------------------------------------------------- device="cpu" changes nothing
@pytest.mark.parametrize("method", ["bc", "da-ibc"])
def test_device_cpu_is_bit_identical_to_the_default(method, dataset, tmp_path):
    runs = {}
    for name, kwargs in (("default", {}), ("cpu", {"device": "cpu"})):
        res = train_agent(method, dataset, TINY, 0, tmp_path / name, log=None, show_progress=False, **kwargs)
        runs[name] = (res, torch.load(tmp_path / name / "final.pt", weights_only=True))
    (a, ca), (b, cb) = runs["default"], runs["cpu"]
    assert [m["loss"] for m in a.metrics] == [m["loss"] for m in b.metrics]
    assert [m["episodes"] for m in a.metrics] == [m["episodes"] for m in b.metrics]  # the evaluation rows
    wa, wb = ca["model"], cb["model"]
    assert set(wa) == set(wb) and all(torch.equal(wa[k], wb[k]) for k in wa)
    assert all(v.device.type == "cpu" for v in cb["model"].values())
    assert b.agent.device == torch.device("cpu")


# --------------------------------------------------------------------------- every draw from the generator
def _trainer(method: str, dataset, seed: int = 3) -> Trainer:
    torch.manual_seed(0)  # the initial weights
    net = build_network(method, TINY)
    config = TrainConfig(steps=3, batch_size=TINY.batch_size, seed=seed, log_every=1, progress=False)
    probs = torch.full((len(dataset),), 1.0 / len(dataset))
    return Trainer(
        net, objective_for(method, net, TINY), DemoBatches(dataset, "cpu"), config, sample_probs=probs
    )


@pytest.mark.parametrize("method", ["bc", "ibc", "da-ibc"])
def test_a_training_step_draws_only_from_the_run_generator(method, dataset):
    results = []
    for global_seed in (1, 2):  # torch's global generator in two different states
        trainer = _trainer(method, dataset)
        start = trainer.generator.get_state()
        torch.manual_seed(global_seed)
        before = torch.get_rng_state()
        losses = trainer.run().losses
        assert torch.equal(torch.get_rng_state(), before), "a draw used torch's global generator"
        assert not torch.equal(
            trainer.generator.get_state(), start
        )  # the minibatches (and negatives) were drawn
        results.append((losses, trainer.model.state_dict()))
    (la, wa), (lb, wb) = results
    assert la == lb and all(torch.equal(wa[k], wb[k]) for k in wa)


@pytest.mark.parametrize("method", ["ibc", "da-ibc"])
def test_a_dfo_call_draws_only_from_the_generator(method, dataset):
    torch.manual_seed(0)
    agent = Agent(method, build_network(method, TINY), TINY, dataset.actions)
    obs, _ = dataset.batch(torch.arange(4))
    actions = []
    for global_seed in (1, 2):
        gen = torch.Generator().manual_seed(5)
        torch.manual_seed(global_seed)
        before = torch.get_rng_state()
        actions.append(agent.act(obs, gen))
        assert torch.equal(torch.get_rng_state(), before), "a draw used torch's global generator"
    assert actions[0].device.type == "cpu" and torch.equal(actions[0], actions[1])
    assert dfo_config(method, TINY).init == ("uniform" if method == "ibc" else "inverse-kde")


def test_the_samplers_draw_only_from_the_generator():
    acts = torch.rand(6, 2) * 2 - 1
    for sampler in (UniformSampler(), ExpertSampler(0.1), ExpertSampler(0.1, [-1.0, -1.0], [1.0, 1.0])):
        before = torch.get_rng_state()
        a = sampler(acts, 5, torch.Generator().manual_seed(0))
        b = sampler(acts, 5, torch.Generator().manual_seed(0))
        assert torch.equal(torch.get_rng_state(), before) and torch.equal(a, b)


# --------------------------------------------------------------------------- another device, simulated
META = torch.device("meta")


@pytest.fixture
def shape_checks_only(monkeypatch):
    """``check_tensor`` without its finiteness test (it needs values) where the meta tests go."""

    def shapes_only(name, x, **kwargs):
        return check_tensor(name, x, **dict(kwargs, finite=False))

    for module in (ibc_tutorial.policies.encoders, ibc_tutorial.negatives):
        monkeypatch.setattr(module, "check_tensor", shapes_only)


def test_the_networks_keep_their_tensors_on_the_device(dataset, shape_checks_only):
    """On the meta device, a constant built on the CPU (e.g. the state scaling of ``BEVStateEncoder``)
    fails: "Tensor on device cpu is not on the expected device meta"."""
    obs, acts = dataset.batch(torch.arange(4))
    obs = {k: v.to(META) for k, v in obs.items()}
    for method in ("bc", "da-ibc"):
        net = build_network(method, TINY).to(META)
        if method == "bc":
            alpha, beta = net(obs)
            assert alpha.device == META and beta.device == META
        else:
            cands = torch.zeros(4, 7, 2, device=META)
            e = net.energy(obs, cands)
            assert e.device == META and e.shape == (4, 7)
            assert net.energy(obs, torch.zeros(7, 2, device=META)).shape == (4, 7)


def test_the_samplers_return_on_the_actions_device_with_the_cpu_draws(shape_checks_only):
    acts = torch.rand(6, 2) * 2 - 1
    for sampler in (UniformSampler(), ExpertSampler(0.1), ExpertSampler(0.1, [-1.0, -1.0], [1.0, 1.0])):
        g_cpu, g_meta = torch.Generator().manual_seed(0), torch.Generator().manual_seed(0)
        on_cpu = sampler(acts, 5, g_cpu)
        on_meta = sampler(acts.to(META), 5, g_meta)
        assert on_cpu.device.type == "cpu" and on_meta.device == META and on_meta.shape == on_cpu.shape
        assert torch.equal(g_cpu.get_state(), g_meta.get_state())  # the same draws, from the CPU generator
    assert uniform_negatives(2, 3, -1.0, 1.0, torch.Generator(), device=META).device == META
    assert expert_negatives(acts.to(META), 2, 3, 0.1, torch.Generator()).device == META


def test_the_final_choice_stays_on_the_population_device():
    """Algorithm 1's line 14 (argmax form) indexes the population on its own device."""
    y, p = torch.zeros(3, 8, 2, device=META), torch.zeros(3, 8, device=META)
    assert select_action(y, p, "argmax", None).device == META
