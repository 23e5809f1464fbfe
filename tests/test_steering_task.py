"""The road-following study's task: demonstrations with rare side-road turns, the steering observation."""

import numpy as np
import pytest
import torch

from ibc_tutorial.driving.dataset import DemoDataset
from ibc_tutorial.driving.towns import get_town
from ibc_tutorial.experiments.steering.models import (
    MODELS,
    SteeringModel,
    build_network,
    objective_for,
    uses_pairs,
)
from ibc_tutorial.experiments.steering.presets import LAPTOP, TINY, SteeringPreset, book_temperature
from ibc_tutorial.experiments.steering.task import (
    SteeringBatches,
    collect_demonstrations,
    demo_route,
    longitudinal_config,
    side_road_counts,
    steering_observation,
)
from ibc_tutorial.training import TrainConfig, Trainer


def _choices(town, route):
    """(had a straight exit, turn) at every junction the route's turns are taken."""
    out, lane = [], route.start_lane
    for turn in route.turns:
        while not (
            lane in town.approach_of_lane and town.approaches[town.approach_of_lane[lane]].is_junction
        ):
            lane = town.next_lane(lane)
        out.append(("straight" in town.approaches[town.approach_of_lane[lane]].exits, turn))
        lane = town.next_lane(lane, turn)
    return out


def test_demo_routes_take_side_roads_at_the_asked_share():
    town = get_town("town01")
    rng = np.random.default_rng(0)
    choices = [c for _ in range(40) for c in _choices(town, demo_route(town, rng, 0.15))]
    through = [t for s, t in choices if s]
    stem = [t for s, t in choices if not s]
    share = np.mean([t != "straight" for t in through])
    assert len(through) > 1000 and abs(share - 0.15) < 0.03  # binomial sd about 0.01
    assert "straight" not in stem and abs(np.mean([t == "left" for t in stem]) - 0.5) < 0.06
    assert all(t == "straight" for s, t in _choices(town, demo_route(town, rng, 0.0)) if s)
    with pytest.raises(ValueError, match="side_road_share"):
        demo_route(town, rng, 1.5)


def test_speed_does_not_tell_the_route():
    c = longitudinal_config(6.0)
    assert c.cruise_speed == c.turn_speed == 6.0 and c.min_throttle_scale == 1.0
    with pytest.raises(ValueError, match="speed"):
        longitudinal_config(0.0)


def test_steering_observation_keeps_only_the_speed():
    state = np.array([[5.0, 0.7, -0.3], [2.0, -1.0, 1.0]], dtype=np.float32)
    bev = np.zeros((2, 5, 8, 8), dtype=np.float32)
    out = steering_observation({"bev": bev, "state": state})
    assert out["bev"] is bev and out["state"].tolist() == [[5.0, 0.0, 0.0], [2.0, 0.0, 0.0]]
    t = steering_observation({"bev": torch.from_numpy(bev), "state": torch.from_numpy(state)})
    assert torch.equal(t["state"], torch.tensor([[5.0, 0.0, 0.0], [2.0, 0.0, 0.0]]))
    assert state[0, 1] == np.float32(0.7)  # the input is not changed


@pytest.fixture(scope="module")
def demos():
    return collect_demonstrations(2, 0.3, 0.5, seed=0)


def test_collected_demonstrations_and_their_counts(demos):
    assert len(demos) == 2 * 180 and demos.n_episodes == 2
    assert demos.meta["config"]["side_road_share"] == 0.5
    c = side_road_counts(demos)
    assert c["straight"] + c["side_road"] >= 0 and set(c["stem"]) == {"left", "right"}
    assert (demos.speed <= 6.5).all()


def test_batches_steering_only_and_pairs(demos):
    ds = DemoDataset(demos, bev_size=32)
    b = SteeringBatches(ds).batch(torch.tensor([0, 5]))
    assert b["actions"].shape == (2, 1) and b["obs"]["state"][:, 1:].abs().sum() == 0
    assert torch.equal(b["actions"][:, 0], ds.actions[[0, 5], 0])
    pairs = SteeringBatches(ds, pairs=True)
    assert len(pairs) == len(demos) - 2  # one frame per episode has no successor
    last = 179  # the first episode's last frame is never a first frame of a pair
    assert last not in pairs.index and (pairs.index + 1 < len(demos)).all()
    p = pairs.batch(torch.tensor([0]))
    assert torch.equal(p["next_actions"][:, 0], ds.actions[pairs.index[[0]] + 1, 0])


@pytest.mark.parametrize("name", MODELS)
def test_every_model_trains_and_steers(demos, name):
    ds = DemoDataset(demos, bev_size=TINY.bev_size)
    torch.manual_seed(0)
    net = build_network(name, TINY)
    Trainer(
        net,
        objective_for(name, net, TINY),
        SteeringBatches(ds, pairs=uses_pairs(name)),
        TrainConfig(steps=2, batch_size=4, progress=False),
    ).run()
    m = SteeringModel(name, net, TINY)
    obs = SteeringBatches(ds).batch(torch.arange(3))["obs"]
    steer = m.steer(obs)
    assert steer.shape == (3,) and (steer.abs() <= 1).all()
    scores = m.scores(obs)
    assert (scores is None) == (name == "regression")
    if scores is not None:
        assert scores.shape == (3, TINY.n_bins) and torch.isfinite(scores).all()


def test_presets():
    assert LAPTOP.n_bins == 512 and LAPTOP.smoothing_alpha == 1.0 and LAPTOP.seeds == (0, 1, 2)
    # T of eq. 5: 2.5e-3 rad^2 over (250 degrees in radians)^2
    assert book_temperature() == pytest.approx(2.5e-3 / np.radians(250.0) ** 2)
    assert SteeringPreset.from_dict(LAPTOP.to_dict()) == LAPTOP
    with pytest.raises(ValueError, match="eval_routes"):
        SteeringPreset(name="x", eval_routes=("nowhere",))
    with pytest.raises(ValueError, match="side_road_share"):
        SteeringPreset(name="x", side_road_share=2.0)
