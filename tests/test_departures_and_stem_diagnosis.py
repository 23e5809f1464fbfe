"""experiments.agents.departures (chapter 08's table), stem_diagnosis (chapter 12's first section),
run_times (the appendix) and plotting.stems, on the folders shipped under book/results."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pytest

from ibc_tutorial.experiments.agents import departures, run_times
from ibc_tutorial.experiments.agents.presets import LAPTOP, differences, with_overrides
from ibc_tutorial.experiments.agents.presets import TEN_ROUTES as TEN_ROUTES_PRESET
from ibc_tutorial.experiments.agents.stem_diagnosis import (
    KINDS,
    change_counts,
    ended_energies,
    episode_agreement,
    stem_approaches,
    stem_crossings,
)
from ibc_tutorial.plotting.stems import plot_minority_by_change
from ibc_tutorial.stats import HOLDS

RESULTS = Path(__file__).resolve().parents[1] / "book" / "results"
TEN_ROUTES = RESULTS / "ten-routes"
LAPTOP_RUN = RESULTS / "laptop"


def _need(*folders: Path) -> None:
    for f in folders:
        if not f.exists():
            pytest.skip(f"{f} is not shipped")


def test_the_departure_table_reads_every_ablation_against_its_pair():
    _need(*(RESULTS / a.folder for a in departures.ABLATIONS), RESULTS / "laptop")
    table_rows = departures.departure_rows(RESULTS)
    rows = {r.ablation.label: r for r in table_rows}
    assert list(rows) == [a.label for a in departures.ABLATIONS]
    held = rows["held brakes"].methods
    assert set(held) == {"bc", "da-ibc"} and held["bc"].difference.estimate > 0
    assert held["bc"].standing_still[0] <= held["bc"].standing_still[1]
    epochs = rows["the epochs"].methods  # ten-routes minus half-epochs: 8 epochs minus 4
    assert epochs["ibc"].difference.estimate > 0 and epochs["ibc"].verdict == HOLDS
    table = departures.departure_table(table_rows)
    assert table.count("<tr>") == len(rows) + 1
    assert "ibc-tutorial replicate --preset laptop" in table and "--preset ten-routes" in table


def test_ten_routes_is_the_laptop_preset_with_its_three_overrides():
    assert differences(with_overrides(LAPTOP, list(departures.TEN_ROUTE_CHANGES)), TEN_ROUTES_PRESET) == {}


def test_an_ablation_whose_overrides_are_not_its_folders_settings_is_refused():
    _need(RESULTS / "ablations" / "no-held-brakes")
    wrong = replace(departures.ABLATIONS[0], overrides=("brake_noise=0",))
    with pytest.raises(ValueError, match="no-held-brakes"):
        departures.check_ablation(RESULTS, wrong)


def test_a_command_wraps_under_its_width_keeping_options_with_their_values():
    cmd = departures.ablation_command(departures.ABLATIONS[2])
    wrapped = departures.wrap_command(cmd, width=60)
    lines = wrapped.split("\n")
    assert len(lines) > 1 and all(len(line) <= 60 for line in lines)
    assert all(line.endswith(" \\") for line in lines[:-1])
    assert wrapped.replace(" \\\n    ", " ") == cmd
    assert not any(line.rstrip(" \\").endswith("--set") for line in lines)
    assert departures.effect_text(None) == "-"


def test_stem_crossings_sort_every_crossing_from_a_stem_and_every_end():
    _need(LAPTOP_RUN / "crossings")
    assert len(stem_approaches("town02")) == 8
    with pytest.raises(ValueError, match="did not drive the episodes"):  # another CPU drove some otherwise
        stem_crossings(LAPTOP_RUN, "ibc", range(7))
    c = stem_crossings(LAPTOP_RUN, "ibc", range(7), same_episodes=False)
    assert set(c.steering) == set(KINDS) and all(v.shape[1] == 2 for v in c.steering.values())
    assert c.ends["at a stem"] == len(c.steering["ended"]) == 5
    ended = ended_energies(LAPTOP_RUN, "ibc", range(7), -0.45, 0.55, same_episodes=False)
    assert len(ended) == 5 and all(e.energies.shape[1] == len(e.steer_grid) for e in ended)
    assert all(np.isclose(e.energies.min(), 0) for e in ended)  # nats above each state's minimum


def _one_crossings_file(tmp_path: Path, change) -> Path:
    """A replication folder holding one agent's table and its crossings file, changed by ``change``."""
    folder = tmp_path / "rep"
    (folder / "crossings").mkdir(parents=True)
    shutil.copytree(LAPTOP_RUN / "runs" / "ibc" / "seed2", folder / "runs" / "ibc" / "seed2",
                    ignore=shutil.ignore_patterns("*.pt", "*.npz"))  # fmt: skip
    ev = json.loads((LAPTOP_RUN / "crossings" / "ibc-seed2.json").read_text())  # the table's 10 episodes
    change(ev["episodes"])
    (folder / "crossings" / "ibc-seed2.json").write_text(json.dumps(ev))
    return folder


def test_a_crossings_file_of_other_episodes_is_refused_unless_asked_and_counted(tmp_path):
    _need(LAPTOP_RUN / "crossings")

    def a_metre_further(episodes):
        episodes[0]["distance_m"] += 1.0

    folder = _one_crossings_file(tmp_path, a_metre_further)
    with pytest.raises(ValueError, match="did not drive the episodes"):
        stem_crossings(folder, "ibc", [2])
    assert episode_agreement(folder, "ibc", [2]) == (9, 10)
    kept = stem_crossings(folder, "ibc", [2], same_episodes=False)
    assert sum(len(v) for v in kept.steering.values()) > 0


def test_a_crossings_file_from_other_starts_is_refused_even_when_asked(tmp_path):
    _need(LAPTOP_RUN / "crossings")

    def another_start(episodes):
        episodes[3]["seed"] += 100

    folder = _one_crossings_file(tmp_path, another_start)
    for read in (
        lambda: stem_crossings(folder, "ibc", [2], same_episodes=False),
        lambda: episode_agreement(folder, "ibc", [2]),
    ):
        with pytest.raises(ValueError, match="from the starts"):
            read()


def test_bad_turn_limits_and_empty_analyses_are_refused(tmp_path):
    with pytest.raises(ValueError, match="left_turn"):
        ended_energies(LAPTOP_RUN, "ibc", [2], 0.2, 0.5)
    with pytest.raises(ValueError, match="holds no agent"):
        change_counts({"nothing": (tmp_path, ("ibc",))})


def test_change_counts_read_each_change_and_the_expert():
    _need(TEN_ROUTES / "stems")
    counts = change_counts({"as trained": (TEN_ROUTES / "stems" / "analysis", ("bc", "expert"))})
    assert counts["as trained", "expert"].agents == 1 and counts["as trained", "bc"].agents == 5
    assert 0 <= counts["as trained", "bc"].minority.estimate <= 0.5


def test_run_times_add_up_to_the_replications_record():
    _need(RESULTS / "laptop" / "runs")
    runs = run_times.run_seconds(RESULTS / "laptop", ("bc", "ibc", "da-ibc"), LAPTOP.seeds)
    assert len(runs) == 21 and all(r.evaluations_during_training < r.training for r in runs.values())
    means = run_times.phase_means(runs)
    assert list(means) == list(run_times.PHASES) and means["training"]["ibc"] > means["training"]["bc"]
    shares = run_times.serial_shares(runs)
    assert shares["training"] + shares["evaluations"] == pytest.approx(1.0)
    with pytest.raises(ValueError, match="runs"):
        run_times.serial_shares({})


def test_the_minority_dot_plot_has_one_row_per_method_and_change():
    shares = {("a", "bc"): (0.1, 0.0, 0.2), ("a", "ibc"): (0.2, 0.1, 0.3), ("b", "ibc"): (0.3, 0.2, 0.4)}
    fig = plot_minority_by_change(shares, reference=0.4, reference_label="the expert")
    ax = fig.axes[0]
    assert [t.get_text() for t in ax.get_yticklabels()] == ["a", "b"]
    assert ax.get_xlabel() and fig._suptitle.get_text().startswith("The minority exit")
    plt.close(fig)
    with pytest.raises(ValueError, match="shares"):
        plot_minority_by_change({})
