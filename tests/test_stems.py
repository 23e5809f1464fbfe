"""The stem measures (driving.stems), the energy-profile readings (driving.energy_profiles) and the
pooled-share bootstrap (stats.ratio_of_sums_interval), on hand-made traces and curves with known answers."""

import numpy as np
import pytest

from ibc_tutorial import stats
from ibc_tutorial.driving.energy_profiles import beta_cdf, beta_shape, boltzmann_sides, low_range, valleys
from ibc_tutorial.driving.stems import (
    circling,
    decision_window,
    episode_measures,
    kept_states,
    red_stops,
    steering_onset,
    stem_approaches,
    stem_crossings,
    stem_exit_counts,
)
from ibc_tutorial.driving.towns import get_town

TOWN = get_town("town02")


def through(approach: int, turn: str, n: int = 3) -> list[int]:
    """Lanes of one pass: ``n`` states on the approach lane, then ``n`` on the connector, then the exit."""
    ap = TOWN.approaches[approach]
    conn = ap.exits[turn]
    return [ap.lane] * n + [conn] * n + [TOWN.lanes[conn].successors[0]] * n


def not_stem_junction() -> int:
    return next(a.id for a in TOWN.approaches if a.is_junction and "straight" in a.exits)


# --------------------------------------------------------------------------- stems and their exits
def test_town02_has_eight_stems_each_left_and_right():
    stems = stem_approaches("town02")
    assert len(stems) == 8
    assert all(set(TOWN.approaches[a].exits) == {"left", "right"} for a in stems)


def test_stem_crossings_and_exit_counts_known_sequence():
    s0, s1 = stem_approaches(TOWN)[:2]
    other = not_stem_junction()
    lanes = through(s0, "left") + through(other, "straight") + through(s0, "right") + through(s1, "right")
    cs = stem_crossings(TOWN, lanes)
    assert [(c["approach"], c["turn"]) for c in cs] == [(s0, "left"), (s0, "right"), (s1, "right")]
    assert stem_exit_counts(cs) == {s0: {"left": 1, "right": 1}, s1: {"left": 0, "right": 1}}


def test_unfinished_crossing_is_not_counted_as_an_exit():
    s0 = stem_approaches(TOWN)[0]
    ap = TOWN.approaches[s0]
    lanes = through(s0, "right") + [ap.lane] * 2 + [ap.exits["left"]] * 4  # ends inside the junction
    cs = stem_crossings(TOWN, lanes)
    assert [c["finished"] for c in cs] == [True, False]
    assert stem_exit_counts(cs) == {s0: {"left": 0, "right": 1}}


# --------------------------------------------------------------------------- circling
@pytest.mark.parametrize(
    ("seq", "period"),
    [
        ([1, 2, 3, 4] * 3, 4),  # one block, three laps
        ([7, 7, 7], 1),  # a loop through one approach
        ([1, 2, 3, 1, 2, 3, 9], 3),  # two laps are 6 of 7 passes
        ([], 0),  # no junction at all
        ([5], 0),  # one pass
        ([1, 2, 3, 4, 5, 6, 7, 8], 0),  # a tour, no repeat
        ([1, 2, 1, 3] * 2, 0),  # a figure eight: approach 1 twice per loop, not one block
        ([9, 8, 7, 6, 5, 1, 2, 1, 2], 0),  # two laps of a loop, but under half the passes
        ([9, 8, 7, 1, 2, 1, 2], 2),  # the same loop, now 4 of 7 passes
        ([1, 2, 3, 4, 5, 1, 2, 3, 4, 5], 0),  # a loop of 5 is more than one block
    ],
)
def test_circling_rule(seq, period):
    assert circling(seq) == period


def test_circling_checks_arguments():
    with pytest.raises(ValueError, match="min_laps"):
        circling([1, 1], min_laps=1)


# --------------------------------------------------------------------------- per-episode measures
def _poses(n: int) -> np.ndarray:
    return np.zeros((n, 3))


def test_episode_measures_mode_coverage_and_approaches():
    s0, s1, s2 = stem_approaches(TOWN)[:3]
    lanes = (
        through(s0, "left")
        + through(s0, "right")  # s0 twice, both exits
        + through(s1, "right")
        + through(s1, "right")  # s1 twice, one exit
        + through(s2, "left")  # s2 once: not in mode coverage
    )
    m = episode_measures(TOWN, lanes, _poses(len(lanes)), np.zeros(len(lanes) - 1), terminated=False)
    assert m["distinct_approaches"] == 3
    assert (m["left"], m["right"], m["stem_crossings"]) == (2, 3, 5)
    assert (m["stems_twice"], m["stems_both"]) == (2, 1)
    assert not m["ended_at_stem"]
    assert m["circling"] == 0


def test_episode_measures_without_junction_and_ending_at_a_stem():
    road = TOWN.road_lanes[0]
    lanes = [road] * 20
    m = episode_measures(TOWN, lanes, _poses(20), np.zeros(19), terminated=True)
    assert (m["distinct_approaches"], m["stem_crossings"], m["stems_twice"], m["circling"]) == (0, 0, 0, 0)
    assert not m["ended_at_stem"]
    s0 = stem_approaches(TOWN)[0]
    ap = TOWN.approaches[s0]
    lanes = [ap.lane] * 3 + [ap.exits["left"]] * 3
    ended = episode_measures(TOWN, lanes, _poses(6), np.zeros(5), terminated=True)
    timed_out = episode_measures(TOWN, lanes, _poses(6), np.zeros(5), terminated=False)
    assert ended["ended_at_stem"] and not timed_out["ended_at_stem"]


def test_lanes_covered_counts_driven_waypoints():
    lane = TOWN.road_lanes[0]
    sel = TOWN.wp_lane == lane
    poses = np.c_[TOWN.wp_xy[sel], TOWN.wp_heading[sel]]
    m = episode_measures(TOWN, [lane] * len(poses), poses, np.zeros(len(poses) - 1), terminated=False)
    assert 0 < m["lanes_covered"] < 0.2
    back = poses.copy()
    back[:, 2] += np.pi  # the same places against the lane's direction cover nothing of it
    m2 = episode_measures(TOWN, [lane] * len(poses), back, np.zeros(len(poses) - 1), terminated=False)
    assert m2["lanes_covered"] < m["lanes_covered"]


# --------------------------------------------------------------------------- decision window, onset
def test_decision_window_ends_where_steering_passes_threshold():
    c = {"start": 5, "stop": 12, "turn": "left", "finished": True}
    steer = np.zeros(15)
    steer[8] = -0.35
    assert decision_window(c, steer).tolist() == [5, 6, 7, 8]
    assert decision_window(c, np.zeros(15)).tolist() == list(range(5, 12))  # never passes: whole crossing
    steer[5] = 0.5
    assert decision_window(c, steer).tolist() == [5]  # already turning at the entry


def test_steering_onset_signed_distance():
    xy = np.c_[np.arange(20.0), np.zeros(20), np.zeros(20)]  # 1 m per state
    steer = np.zeros(19)
    steer[12] = -0.4  # a left turn that begins 2 m after the entry at state 10
    left = {"start": 10, "stop": 18, "turn": "left", "finished": True}
    assert steering_onset(left, xy, steer) == pytest.approx(2.0)
    steer2 = np.zeros(19)
    steer2[7:] = 0.5  # a right turn begun 3 m before the entry
    right = dict(left, turn="right")
    assert steering_onset(right, xy, steer2) == pytest.approx(-3.0)
    assert np.isnan(steering_onset(right, xy, steer))  # steering the other way is no onset of this turn
    assert np.isnan(steering_onset(dict(left, finished=False, turn=""), xy, steer))


# --------------------------------------------------------------------------- red stops and kept states
def test_red_stops_one_per_spell_where_the_car_rests():
    red = np.array([0, 1, 1, 1, 1, 0, 0, 1, 1, 0, 1, 1], dtype=bool)
    speed = np.array([5, 3, 0.4, 0.0, 0.0, 2, 5, 4, 4, 3, 0.1, 0.0])
    dist = np.array([20, 10, 6, 6, 6, np.inf, 20, 10, 5, np.inf, 30, 30])
    assert red_stops(red, speed, dist).tolist() == [2]  # spell 2 never stops; spell 3 stops too far away
    with pytest.raises(ValueError, match="one value per state"):
        red_stops(red, speed[:-1], dist)


def test_kept_states_cover_stem_crossings_with_lead():
    s0 = stem_approaches(TOWN)[0]
    lanes = [TOWN.road_lanes[0]] * 12 + through(s0, "left")
    n = len(lanes)
    kept = kept_states(TOWN, lanes, np.full(n, 5.0), np.zeros(n, bool), np.full(n, np.inf), lead=4)
    start = stem_crossings(TOWN, lanes)[0]["start"]
    assert kept.tolist() == list(range(start - 4, start + 3))


# --------------------------------------------------------------------------- energy profiles
S = np.linspace(-1, 1, 41)


def two_wells(barrier: float) -> np.ndarray:
    """Valleys at -0.5 (0 nats) and +0.5 (0.2 nats) with a ridge at 0 rising ``barrier`` above the higher."""
    e = np.where(S < 0, 20 * (S + 0.5) ** 2, 20 * (S - 0.5) ** 2 + 0.2)
    return np.minimum(e, 0.2 + barrier)


def test_one_valley():
    (v,) = valleys(S, 10 * (S - 0.2) ** 2)
    assert v["steer"] == pytest.approx(0.2) and v["prominence"] == np.inf


def test_two_valleys_need_a_barrier_of_one_nat():
    assert len(valleys(S, two_wells(0.5))) == 1  # a 0.5-nat barrier: one valley
    two = valleys(S, two_wells(2.0))
    assert [round(v["steer"], 2) for v in two] == [-0.5, 0.5]
    assert two[1]["prominence"] == pytest.approx(2.0)


def test_valley_beyond_depth_does_not_count():
    e = np.where(S < 0, 20 * (S + 0.5) ** 2, 20 * (S - 0.5) ** 2 + 4.0)  # second valley 4 nats up
    assert len(valleys(S, e)) == 1
    assert len(valleys(S, e, depth=5.0)) == 2


def test_plateaus():
    assert len(valleys(S, np.zeros(41))) == 1  # flat: one valley, at the middle
    assert valleys(S, np.zeros(41))[0]["steer"] == pytest.approx(0.0)
    e = np.full(41, 5.0)
    e[5:10] = 0.0  # flat-bottomed valley
    e[30:35] = 0.0  # an equally deep one, 5 nats of ridge between
    vs = valleys(S, e)
    assert len(vs) == 2 and vs[0]["steer"] == pytest.approx(S[7]) and vs[1]["steer"] == pytest.approx(S[32])
    e[30:35] = 4.5  # now 0.5 nat below the ridge: not separate, and beyond 3 nats anyway
    assert len(valleys(S, e, depth=10.0)) == 1


def test_valley_at_the_grid_edge():
    e = np.full(41, 5.0)
    e[:2] = 2.0  # a flat valley at the left edge, 2 nats up
    e[-1] = 0.0  # the minimum at the right edge
    vs = valleys(S, e)
    assert [v["steer"] for v in vs] == [pytest.approx(-0.975), pytest.approx(1.0)]
    assert vs[0]["prominence"] == pytest.approx(3.0)


def test_boltzmann_sides():
    sym = boltzmann_sides(S, S**2)
    assert sym["left"] == pytest.approx(0.5) and sym["right"] == pytest.approx(0.5)
    right = boltzmann_sides(S, np.where(S > 0, 0.0, 50.0))
    assert right["right"] > 0.999
    p = np.exp(-two_wells(2.0))
    assert boltzmann_sides(S, two_wells(2.0))["left"] == pytest.approx(
        (p[S < 0].sum() + 0.5 * p[S == 0].sum()) / p.sum()
    )

    # a float32 grid whose middle value is -1.5e-8 (torch.linspace's with AVX2 kernels) reads as straight
    nudged = S.astype(np.float32).astype(np.float64)
    nudged[len(S) // 2] = -1.49e-8
    assert boltzmann_sides(nudged, S**2)["left"] == pytest.approx(0.5)
    # ... but a value a hundredth of a step left of straight is left
    nudged[len(S) // 2] = -0.01 * (S[1] - S[0])
    assert boltzmann_sides(nudged, S**2)["left"] > 0.5 + 1e-3


def test_low_range():
    r = low_range(S, 10 * S**2)  # within 3 nats: |s| <= sqrt(0.3) = 0.548 -> grid values -0.5 .. 0.5
    assert (r["low"], r["high"]) == (pytest.approx(-0.5), pytest.approx(0.5))
    assert r["extent"] == pytest.approx(1.0) and r["measure"] == pytest.approx(21 * 0.05)
    r2 = low_range(S, two_wells(5.0))
    assert r2["extent"] > r2["measure"]  # two separate valleys: the extent spans the gap


def test_profile_checks():
    with pytest.raises(ValueError, match="equal length"):
        valleys(S, S[:-1])
    with pytest.raises(ValueError, match="increasing"):
        low_range(S[::-1], S)
    with pytest.raises(ValueError, match="finite"):
        boltzmann_sides(S, np.r_[S[:-1], np.nan])


def test_beta_shape():
    assert beta_shape(3, 3)["shape"] == "single-peaked" and beta_shape(3, 3)["mean"] == pytest.approx(0)
    u = beta_shape(0.4, 0.6)
    assert u["shape"] == "U-shaped" and u["mode"] is None and u["mean"] == pytest.approx(-0.2)
    assert beta_shape(0.5, 2)["shape"] == "J-shaped" and beta_shape(1, 1)["shape"] == "flat"
    assert beta_shape(2, 6)["mode"] == pytest.approx(2 * (1 / 6) - 1)


def test_beta_cdf_against_scipy():
    sp = pytest.importorskip("scipy.stats")
    for a, b, x in [
        (0.5, 0.5, 0.5),
        (0.3, 2, 0.5),
        (5, 2, 0.5),
        (2, 7, 0.3),
        (40, 30, 0.5),
        (0.9, 0.4, 0.99),
    ]:
        assert beta_cdf(x, a, b) == pytest.approx(sp.beta.cdf(x, a, b), rel=1e-10, abs=1e-12)
    assert beta_cdf(0.0, 2, 3) == 0.0 and beta_cdf(1.0, 2, 3) == 1.0


# --------------------------------------------------------------------------- pooled shares
def test_ratio_of_sums_interval_pools_events_and_resamples_agents():
    num = np.array([[1, 0, 2], [3, 3, 3]])
    den = np.array([[4, 0, 4], [3, 3, 3]])
    iv = stats.ratio_of_sums_interval(num, den, n_resamples=2000, seed=1)
    assert iv.estimate == pytest.approx(12 / 17)
    assert iv.low < 0.4 and iv.high == pytest.approx(1.0)  # resampling agent 2 twice gives 1
    minority = stats.ratio_of_sums_interval(
        num, den, transform=lambda p: np.minimum(p, 1 - p), n_resamples=500
    )
    assert minority.estimate == pytest.approx(5 / 17) and minority.high <= 0.5
    same = stats.ratio_of_sums_interval(np.full((3, 4), 2), np.full((3, 4), 4), n_resamples=200)
    assert (same.low, same.high) == (0.5, 0.5)
    with pytest.raises(ValueError, match="one shape"):
        stats.ratio_of_sums_interval(num, den[:, :2])
    with pytest.raises(ValueError, match="positive sum"):
        stats.ratio_of_sums_interval(num, np.zeros((2, 3)))


def test_ratio_of_sums_difference_decides_known_cases_and_refuses_bad_input():
    minority = lambda p: np.minimum(p, 1 - p)  # noqa: E731
    den = np.full((4, 5), 3.0)  # 4 agents x 5 episodes, 3 stem crossings each
    half = np.tile([1.0, 2.0], (4, 3))[:, :5]  # left in about half the crossings
    never = np.zeros((4, 5))  # always right
    d = stats.ratio_of_sums_difference(half, den, never, den, transform=minority, n_resamples=500)
    assert d.estimate == pytest.approx(minority(half.sum() / den.sum())) and d.low > 0.3
    assert stats.verdict(d) == stats.HOLDS
    same = stats.ratio_of_sums_difference(never, den, never, den, n_resamples=100)
    assert same.estimate == same.low == same.high == 0.0
    # agents that differ from each other widen the interval: one of four agents turns left always
    split = np.zeros((4, 5))
    split[0] = 3.0
    wide = stats.ratio_of_sums_difference(split, den, never, den, n_resamples=2000, seed=2)
    assert wide.estimate == pytest.approx(0.25) and wide.low <= 0.0 and wide.high > 0.5
    with pytest.raises(ValueError, match="denominators_b"):
        stats.ratio_of_sums_difference(half, den, never, -den)
    with pytest.raises(ValueError, match="one shape"):
        stats.ratio_of_sums_difference(half, den, never[:2], den)


def test_beta_density_against_scipy_and_checks():
    from scipy.stats import beta as scipy_beta

    from ibc_tutorial.driving.energy_profiles import beta_density

    s = np.linspace(-0.99, 0.99, 41)
    for a, b in ((2.0, 5.0), (0.6, 0.7), (30.0, 28.0)):
        np.testing.assert_allclose(beta_density(s, a, b), scipy_beta.pdf((s + 1) / 2, a, b) / 2, rtol=1e-9)
    assert abs(np.trapezoid(beta_density(np.linspace(-1, 1, 20001), 3.0, 4.0), dx=2 / 20000) - 1) < 1e-6
    with pytest.raises(ValueError, match="alpha"):
        beta_density(s, 0.0, 1.0)
    with pytest.raises(ValueError, match="steer must"):
        beta_density([1.5], 2.0, 2.0)
