"""Agent checkpoints: round trip, weights_only loading, refusal of foreign files
(ibc_tutorial.experiments.agents.checkpoints)."""

import dataclasses
from pathlib import Path
from types import SimpleNamespace

import pytest
import torch

from ibc_tutorial import __version__
from ibc_tutorial.experiments.agents.agent import build_network
from ibc_tutorial.experiments.agents.checkpoints import FORMAT, load_agent, load_checkpoint, save_checkpoint
from ibc_tutorial.experiments.agents.presets import LAPTOP, TINY


def _agent(method, preset, network, expert_actions, init_weights=None):
    """What ``save_checkpoint`` reads of an ``Agent`` (any object with these attributes)."""
    return SimpleNamespace(
        method=method,
        preset=preset,
        network=network,
        expert_actions=expert_actions,
        init_weights=init_weights,
    )


SHIPPED = Path(__file__).resolve().parents[1] / "book" / "results" / "laptop" / "runs"


@pytest.fixture
def saved(tmp_path):
    torch.manual_seed(0)
    net = build_network("da-ibc", TINY)
    actions = torch.rand(30, 2) * 2 - 1
    path = save_checkpoint(
        tmp_path / "a.pt",
        _agent(
            method="da-ibc",
            preset=TINY,
            network=net,
            expert_actions=actions,
            init_weights=torch.full((30,), 1 / 30),
        ),
        data_sha256="ab" * 32,
        epoch=3,
    )
    return path, net, actions


def test_round_trip(saved):
    path, net, actions = saved
    raw = torch.load(path, weights_only=True)  # plain data only
    assert raw["format"] == FORMAT and raw["package_version"] == __version__ and raw["epoch"] == 3
    assert raw["data_sha256"] == "ab" * 32 and raw["preset"]["name"] == "tiny"
    agent, ckpt = load_agent(path)
    for k, v in net.state_dict().items():
        assert torch.equal(agent.network.state_dict()[k], v)
    assert torch.equal(agent.expert_actions, actions)
    obs = {"bev": torch.randint(0, 2, (2, 5, 32, 32)).float(), "state": torch.rand(2, 3)}
    assert torch.allclose(agent.network.energy(obs, actions[:5]), net.energy(obs, actions[:5]))


def test_a_network_on_a_gpu_is_stored_as_cpu_copies(monkeypatch):
    """A GPU simulated with torch's fake tensors (a device, no data): the stored tensors are CPU copies
    and the caller's tensors stay where they were."""
    fake_tensor = pytest.importorskip("torch._subclasses.fake_tensor")
    import ibc_tutorial.experiments.agents.checkpoints as checkpoints

    stored = {}
    monkeypatch.setattr(checkpoints, "atomic_torch_save", lambda obj, path: stored.update(obj))
    cpu_net = build_network("da-ibc", TINY)
    save_checkpoint(
        "unused.pt",
        _agent(method="da-ibc", preset=TINY, network=cpu_net, expert_actions=torch.zeros(30, 2)),
        data_sha256="ab" * 32,
        epoch=1,
    )
    assert all(
        stored["model"][k].data_ptr() != v.data_ptr() for k, v in cpu_net.state_dict().items()
    )  # on the CPU too
    shapes = {k: (v.shape, v.dtype) for k, v in cpu_net.state_dict().items()}

    class OnGPU(torch.nn.Module):
        def __init__(self, state):
            super().__init__()
            self.state = state

        def state_dict(self):
            return self.state

    with fake_tensor.FakeTensorMode():
        net = OnGPU(
            {k: torch.zeros(shape, dtype=dtype, device="cuda") for k, (shape, dtype) in shapes.items()}
        )
        actions, weights = torch.zeros(30, 2, device="cuda"), torch.ones(30, device="cuda")
        for half in (False, True):
            save_checkpoint(
                "unused.pt",
                _agent(
                    method="da-ibc", preset=TINY, network=net, expert_actions=actions, init_weights=weights
                ),
                data_sha256="ab" * 32,
                epoch=1,
                half=half,
            )
            model = stored["model"]
            assert set(model) == set(shapes) and all(v.device.type == "cpu" for v in model.values())
            assert all(
                v.dtype == (torch.float16 if half and shapes[k][1].is_floating_point else shapes[k][1])
                for k, v in model.items()
            )
            assert (
                stored["expert_actions"].device.type == "cpu" and stored["init_weights"].device.type == "cpu"
            )
        assert all(v.device.type == "cuda" for v in net.state_dict().values())  # copied, not moved
        assert actions.device.type == "cuda" and weights.device.type == "cuda"


def _rewrite(path, **changes):
    ckpt = torch.load(path, weights_only=True)
    ckpt.update(changes)
    torch.save(ckpt, path)


def test_refuses_foreign_files(tmp_path, saved):
    path, _, _ = saved
    other = tmp_path / "other.pt"
    torch.save({"weights": torch.zeros(3)}, other)
    with pytest.raises(ValueError, match="not an ibc-tutorial agent checkpoint"):
        load_checkpoint(other)
    (tmp_path / "junk.pt").write_bytes(b"not a torch file")
    with pytest.raises(ValueError, match="not a readable agent checkpoint"):
        load_checkpoint(tmp_path / "junk.pt")
    with pytest.raises(ValueError, match="no checkpoint"):
        load_checkpoint(tmp_path / "missing.pt")


def test_refuses_other_versions(saved):
    path, _, _ = saved
    _rewrite(path, package_version="9.9.0")
    with pytest.raises(ValueError, match="written by ibc_tutorial 9.9.0"):
        load_checkpoint(path)
    _rewrite(path, package_version=__version__, format_version=99)
    with pytest.raises(ValueError, match="format version 99"):
        load_checkpoint(path)


def test_refuses_other_architectures(saved):
    path, _, _ = saved
    with pytest.raises(ValueError, match="another architecture"):
        load_checkpoint(path, preset=dataclasses.replace(TINY, embed_dim=32))
    with pytest.raises(ValueError, match="method 'da-ibc', expected 'bc'"):
        load_checkpoint(path, method="bc")
    load_checkpoint(
        path, method="da-ibc", preset=dataclasses.replace(TINY, epochs=9)
    )  # training length is not architecture
    ckpt = torch.load(path, weights_only=True)
    ckpt["model"]["obs_proj.weight"] = torch.zeros(3, 3)
    torch.save(ckpt, path)
    with pytest.raises(ValueError, match="weights do not fit"):
        load_agent(path)


@pytest.mark.parametrize("method", ["bc", "da-ibc"])
def test_the_shipped_checkpoints_still_load(method):
    path = SHIPPED / method / "seed0" / "final.pt"
    if not path.exists():
        pytest.skip("no shipped results")
    agent, ckpt = load_agent(path, method=method, preset=LAPTOP)
    assert agent.preset == LAPTOP and ckpt["epoch"] == LAPTOP.epochs
