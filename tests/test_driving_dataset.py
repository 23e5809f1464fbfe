"""Demonstrations: the log file, the rendering Dataset, the collector and its command."""

import numpy as np
import pytest
import torch

from ibc_tutorial.cli import main
from ibc_tutorial.driving import Expert, make_env
from ibc_tutorial.driving.analysis import exit_counts, junction_visits, log_junction_visits
from ibc_tutorial.driving.collect import CollectConfig, Recorder, collect
from ibc_tutorial.driving.dataset import VERSION, DemoDataset, DemoLog


@pytest.fixture(scope="module")
def small_log():
    return collect(
        CollectConfig(town="town02", routes=3, seed=1, min_minutes=0.5, max_minutes=1.0), show_progress=False
    )


def test_collect_shapes_and_quality(small_log):
    log = small_log
    assert log.n_episodes == 3 and 900 <= len(log) <= 1800
    assert log.pose.dtype == np.float64 and log.lights.shape == (len(log), 24)
    for ep in log.meta["episodes"]:
        assert ep["end"] == "completed" and ep["red_light_infractions"] == 0
    starts = log.step == 0
    assert np.array_equal(log.prev_action[starts], np.zeros((3, 2)))
    # the previous action of a step is the action executed at the step before
    nxt = ~starts
    assert np.array_equal(log.prev_action[nxt], log.executed[np.flatnonzero(nxt) - 1])
    assert (np.abs(log.action) <= 1).all()


def test_file_round_trip(small_log, tmp_path):
    path = small_log.save(tmp_path / "demo.npz")
    back = DemoLog.load(path)
    for name in ("pose", "speed", "prev_action", "action", "executed", "lights", "episode", "step", "lane"):
        assert np.array_equal(getattr(back, name), getattr(small_log, name))
    assert back.town == "town02" and back.meta["config"]["seed"] == 1
    assert not list(tmp_path.glob(".*tmp"))  # no temporary file left behind


def test_damaged_and_foreign_files_are_refused(small_log, tmp_path):
    good = small_log.save(tmp_path / "good.npz")
    data = good.read_bytes()
    (tmp_path / "cut.npz").write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match="truncated or damaged"):
        DemoLog.load(tmp_path / "cut.npz")
    flipped = bytearray(data)
    flipped[len(data) // 3] ^= 0xFF  # one byte changed inside the compressed arrays
    (tmp_path / "flipped.npz").write_bytes(bytes(flipped))
    with pytest.raises(ValueError, match="damaged"):
        DemoLog.load(tmp_path / "flipped.npz")
    (tmp_path / "text.npz").write_text("hello")
    with pytest.raises(ValueError, match="truncated or damaged"):
        DemoLog.load(tmp_path / "text.npz")
    np.savez(tmp_path / "foreign.npz", x=np.zeros(3))
    with pytest.raises(ValueError, match="not an ibc-tutorial demonstration file"):
        DemoLog.load(tmp_path / "foreign.npz")
    with np.load(good) as z:
        arrays = {k: z[k] for k in z.files}
    altered = dict(arrays, action=arrays["action"] * 0.5)
    np.savez(tmp_path / "altered.npz", **altered)
    with pytest.raises(ValueError, match="checksum"):
        DemoLog.load(tmp_path / "altered.npz")
    np.savez(tmp_path / "old.npz", **dict(arrays, version=np.array(VERSION + 1)))
    with pytest.raises(ValueError, match="version"):
        DemoLog.load(tmp_path / "old.npz")
    np.savez(tmp_path / "partial.npz", **{k: v for k, v in arrays.items() if k != "lights"})
    with pytest.raises(ValueError, match="lacks"):
        DemoLog.load(tmp_path / "partial.npz")
    with pytest.raises(ValueError, match="no demonstration file"):
        DemoLog.load(tmp_path / "missing.npz")


def test_identical_collections_have_one_checksum(small_log, tmp_path):
    """The demonstrations' hash covers their content: no wall time in the log, whatever the file's bytes."""
    again = collect(
        CollectConfig(town="town02", routes=3, seed=1, min_minutes=0.5, max_minutes=1.0), show_progress=False
    )
    assert again.meta == small_log.meta and "seconds" not in again.meta
    assert again.checksum() == small_log.checksum()
    assert DemoLog.load(again.save(tmp_path / "again.npz")).checksum() == small_log.checksum()


def test_log_validates_its_arrays(small_log):
    with pytest.raises(ValueError, match="action"):
        DemoLog("town02", **{**_arrays(small_log), "action": np.zeros((3, 2))})
    bad_steps = _arrays(small_log)
    bad_steps["step"] = bad_steps["step"].copy()
    bad_steps["step"][5] += 1
    with pytest.raises(ValueError, match="step by step"):
        DemoLog("town02", **bad_steps)


def _arrays(log):
    return {
        k: getattr(log, k)
        for k in ("pose", "speed", "prev_action", "action", "executed", "lights", "episode", "step", "lane")
    }


def test_dataset_samples(small_log):
    ds = DemoDataset(small_log, bev_size=64)
    obs, action = ds[10]
    assert obs["bev"].shape == (5, 64, 64) and obs["bev"].dtype == torch.float32
    assert obs["state"].shape == (3,) and obs["state"].dtype == torch.float32
    assert action.shape == (2,) and action.dtype == torch.float32
    assert torch.equal(action, torch.from_numpy(small_log.action[10]))
    f = DemoDataset(small_log, bev_size=192)[10][0]["bev"]
    assert f.dtype == torch.float32 and f.shape == (5, 192, 192)
    assert torch.equal(torch.nn.functional.max_pool2d(f[None], 3)[0], obs["bev"])
    loader = torch.utils.data.DataLoader(
        ds, batch_size=16, shuffle=True, generator=torch.Generator().manual_seed(0)
    )
    (bobs, bact) = next(iter(loader))
    assert bobs["bev"].shape == (16, 5, 64, 64) and bobs["state"].shape == (16, 3) and bact.shape == (16, 2)
    with pytest.raises(IndexError):
        ds[len(ds)]
    cached = DemoDataset(small_log, bev_size=64, cache=True)
    idx = [0, 7, 300, len(ds) - 1]
    assert torch.equal(cached.batch(idx)[0]["bev"], ds.batch(idx)[0]["bev"])
    assert torch.equal(cached[7][0]["bev"], ds[7][0]["bev"])
    with pytest.raises(ValueError, match="bev_size"):
        DemoDataset(small_log, bev_size=100)


def test_dataset_renders_what_the_env_showed():
    env = make_env("town02", bev_size=64)
    obs, _ = env.reset(seed=5)
    expert = Expert(env, seed=1)
    rec = Recorder(env.sim)
    shown = []
    for _ in range(250):
        a = expert.act()
        rec.record(0, a, a, expert.current_lane)
        shown.append(obs)
        obs, *_ = env.step(a)
    ds = DemoDataset(rec.log(), bev_size=64)
    assert sum(o["bev"][2:].any() for o in shown) > 0  # some red lights were in view
    batch, _ = ds.batch(np.arange(len(ds)))
    for i, o in enumerate(shown):
        sample, _ = ds[i]
        assert np.array_equal(sample["bev"].numpy(), o["bev"]) and np.array_equal(
            sample["state"].numpy(), o["state"]
        )
        assert np.array_equal(batch["bev"][i].numpy(), o["bev"])


def test_history_is_clamped_at_episode_starts(small_log):
    idx = np.flatnonzero(small_log.step == 0)
    rows = small_log.history_rows(idx + 3)  # three steps into each episode
    assert np.array_equal(rows, np.stack([idx, idx, idx + 3], axis=1))


def test_exit_counts_follow_the_route(small_log):
    # the exits the expert took, episode by episode, are its route's turns (as many as it drove)
    total = 0
    for sl, route in zip(small_log.episodes(), small_log.meta["routes"], strict=True):
        turns = [v["turn"] for v in junction_visits(small_log.town, small_log.lane[sl], ended_inside=True)]
        assert turns == route["turns"][: len(turns)]
        total += len(turns)
    counts = exit_counts(log_junction_visits(small_log))
    assert total >= 3 and sum(sum(c.values()) for c in counts.values()) == total


def test_collect_command(tmp_path, capsys):
    out = tmp_path / "d.npz"
    assert (
        main(
            [
                "collect",
                "--town",
                "town02",
                "--routes",
                "2",
                "--seed",
                "3",
                "--min-minutes",
                "0.2",
                "--max-minutes",
                "0.3",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    log = DemoLog.load(out)
    assert log.n_episodes == 2 and 240 <= len(log) <= 360
    assert "2 episodes of town02" in capsys.readouterr().out
    assert (
        main(
            [
                "collect",
                "--routes",
                "1",
                "--min-minutes",
                "2",
                "--max-minutes",
                "1",
                "--out",
                str(tmp_path / "e.npz"),
            ]
        )
        == 2
    )
    assert main(["collect", "--town", "town09", "--out", str(tmp_path / "e.npz")]) == 2
    before = out.read_bytes()
    assert (
        main(["collect", "--town", "town02", "--routes", "1", "--out", str(out)]) == 2
    )  # exists: not overwritten
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 3 and "max_minutes" in err[0] and "town09" in err[1] and "--force" in err[2]
    assert out.read_bytes() == before


def test_paper_sized_collection():
    """The command's default: 10 routes in town01, about 21,000 samples (the paper: 21,287)."""
    log = collect(CollectConfig(), show_progress=False)
    assert 20_400 <= len(log) <= 21_600
    durations = np.array([e["steps"] for e in log.meta["episodes"]])
    assert durations.min() >= 1500 and durations.max() <= 2700
    assert all(e["end"] == "completed" and e["red_light_infractions"] == 0 for e in log.meta["episodes"])
    assert 7_000 <= sum(e["distance_m"] for e in log.meta["episodes"]) <= 11_000  # the paper: about 8 km
