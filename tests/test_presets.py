"""Presets made of the library's configs: the one map to CollectConfig, DFOConfig and TrainConfig,
validation where each setting is defined, ``--set`` overrides (checked before any work, recorded in
the provenance), and the paper's binary light channels."""

import dataclasses

import pytest

from ibc_tutorial import cli
from ibc_tutorial.driving.bev import LIGHT_ENCODINGS, SUPPORTED_SIZES
from ibc_tutorial.driving.collect import CollectConfig
from ibc_tutorial.experiments.agents import presets as P
from ibc_tutorial.experiments.runs import PROVENANCE, read_json_dict
from ibc_tutorial.experiments.steering import presets as S
from ibc_tutorial.optimizers.dfo import DFOConfig
from ibc_tutorial.training import TrainConfig


@pytest.mark.parametrize("preset", list(P.PRESETS.values()))
def test_every_config_field_maps_to_a_preset_field_and_back(preset):
    collect, dfo = preset.collect_config(), preset.dfo_config("da-ibc")
    train = preset.train_config(steps_per_epoch=7, seed=3)
    configs = {"collect": collect, "dfo": dfo, "train": train}
    for name, field in P.CONFIG_FIELDS.items():
        section, key = name.split(".")
        if section == "bev":
            continue
        assert getattr(configs[section], key) == getattr(preset, field), name
    assert isinstance(collect, CollectConfig) and collect.town == "town01"
    assert isinstance(dfo, DFOConfig) and isinstance(train, TrainConfig)
    assert train.steps == 7 * preset.epochs and train.log_every == 7 * preset.eval_every
    assert preset.dfo_config("bc") is None
    assert (preset.dfo_config("ibc").init, preset.dfo_config("ibc").select) == ("uniform", "argmax")
    assert (dfo.init, dfo.select) == ("inverse-kde", "sample")


def test_the_paper_preset_draws_the_papers_binary_lights():
    assert "flag" in LIGHT_ENCODINGS and P.PAPER.light_encoding == "flag"
    assert "light_encoding" not in P.differences(P.PAPER, P.LAPTOP)


@pytest.mark.parametrize(
    "change, words",
    [
        ({"bev_size": 100}, "bev_size must be one of"),
        ({"dfo_samples": 0}, "n_samples"),
        ({"min_minutes": 3.0, "max_minutes": 2.0}, "max_minutes"),
        ({"brake_noise": 2.0}, "brake_noise"),
        ({"lr_schedule": "step"}, "lr_schedule"),
    ],
)
def test_each_setting_is_validated_by_the_config_that_defines_it(change, words):
    with pytest.raises(ValueError, match=words):
        dataclasses.replace(P.TINY, **change)


def test_steering_presets_use_the_renderers_sizes_and_know_their_routes():
    assert S.LAPTOP.bev_size in SUPPORTED_SIZES
    with pytest.raises(ValueError, match="bev_size must be one of"):
        dataclasses.replace(S.TINY, bev_size=40)
    with pytest.raises(ValueError, match="eval_routes"):
        dataclasses.replace(S.TINY, eval_routes=("nowhere",))
    assert S.TINY.train_config(seed=1).steps == S.TINY.steps


def test_overrides_by_config_name_or_field_name():
    p = P.with_overrides(P.TINY, ["dfo.n_samples=64", "epochs=3", "cnn_channels=4,4", "train.lr=3e-4"])
    assert (p.dfo_samples, p.epochs, p.cnn_channels, p.lr) == (64, 3, (4, 4), 3e-4)
    assert p.dfo_config("da-ibc").n_samples == 64
    assert P.with_overrides(P.TINY, []) is P.TINY
    s = S.with_overrides(S.TINY, ["train.steps=4", "seeds=[0, 1]"])
    assert (s.steps, s.seeds) == (4, (0, 1))


@pytest.mark.parametrize(
    "item, words",
    [
        ("dfo.samples=4", "unknown field 'dfo.samples'"),
        ("epochs", "FIELD=VALUE"),
        ("epochs=many", "cannot read 'many' as int"),
        ("bev.size=100", "bev_size must be one of"),
        ("dfo.n_iters=0", "n_iters"),
    ],
)
def test_a_bad_override_is_a_value_error_naming_it(item, words):
    with pytest.raises(ValueError, match=words):
        P.with_overrides(P.TINY, [item])


@pytest.mark.parametrize(
    "argv, words",
    [
        (["replicate", "--preset", "tiny", "--set", "bev.size=100"], ["--set", "bev_size must be one of"]),
        (["replicate", "--preset", "tiny", "--set", "bev_size=33"], ["bev_size must be one of"]),
        (["replicate", "--preset", "tiny", "--set", "dfo.nsamples=1"], ["unknown field 'dfo.nsamples'"]),
        (["replicate-steering", "--preset", "tiny", "--set", "lr=-1"], ["lr"]),
        (["train", "--method", "bc", "--preset", "tiny", "--set", "epochs=x"], ["cannot read 'x'"]),
    ],
)
def test_bad_overrides_are_one_line_before_any_work(argv, words, tmp_path, capsys):
    out = tmp_path / "out"
    if argv[0] == "train":
        data = tmp_path / "data.npz"
        data.write_bytes(b"not read: the override is refused first")
        argv = argv + ["--data", str(data)]
    code = cli.main(argv + ["--out", str(out)])
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert code == cli.USER_ERROR and len(lines) == 1 and "Traceback" not in err, err
    assert all(w in lines[0] for w in words), lines[0]
    assert not out.exists()  # nothing was made


def test_overrides_are_recorded_in_the_provenance(tmp_path):
    out = tmp_path / "study"
    argv = ["replicate-steering", "--preset", "tiny", "--set", "train.steps=2", "--out", str(out)]
    argv += ["--set", "seeds=0", "--threads", "1"]
    assert cli.main(argv) == 0
    prov = read_json_dict(out / PROVENANCE, "")
    assert prov["overrides"] == ["train.steps=2", "seeds=0"] and prov["preset"]["steps"] == 2
    assert prov["command"] == "ibc-tutorial " + " ".join(argv)
    assert "`train.steps=2`" in (out / "PROVENANCE.md").read_text()


def test_a_preset_stored_before_light_encoding_existed_keeps_its_intensities():
    stored = {k: v for k, v in P.LAPTOP.to_dict().items() if k != "light_encoding"}
    assert P.Preset.from_dict(stored).light_encoding == "intensity"
    assert P.Preset.from_dict(P.LAPTOP.to_dict()) == P.LAPTOP


def test_differences_from_the_paper_mark_what_it_does_not_state():
    d = P.differences(P.PAPER, P.LAPTOP)
    assert d["lr_schedule"] == ("constant (not stated)", "cosine")
    assert d["brake_noise"] == ("0.0 (not stated)", 1.0)
    assert d["bev_size"] == (192, 64)  # stated: given as it is
    assert P.differences(P.LAPTOP, P.TINY)["bev_size"] == (64, 32)  # between presets: values only
    assert P.PAPER_UNSTATED <= {f.name for f in dataclasses.fields(P.Preset)}


def test_an_unknown_field_lists_each_field_once_by_the_presets_name():
    with pytest.raises(ValueError) as caught:
        P.with_overrides(P.TINY, ["dfo.samples=4"])
    listed = str(caught.value).split("the fields are ")[1].split(" (")[0].split(", ")
    fields = sorted(f.name for f in dataclasses.fields(P.TINY) if f.name != "name")
    assert listed == fields  # once each, no config alias (bev.size beside bev_size)
    assert "dfo.n_samples" not in listed and "dfo_samples" in listed
