"""Traffic lights: one head per junction approach, drawn as a stop line, and the red-light rule.

Each T-junction cycles its three heads in turn: the active head shows green for 10 s, yellow
for 3 s, then all heads are red for 2 s before the next head's turn, a 45 s cycle in which
each approach is red two thirds of the time. Every junction starts its cycle at its own,
random phase. Time is counted in control steps (10 Hz).

A red-light infraction is committed when the rear of the car crosses the stop line of its own
lane while that head is red (as in CARLA's leaderboard, which the DA-IBC paper's score uses).
A crossing happens once per passage, and the same light is never counted twice in a row
(CARLA's guard against counting one passage several times).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ibc_tutorial.driving.lanes import LANE_WIDTH, Approach, right_of
from ibc_tutorial.utils import check_int, check_positive

GREEN, YELLOW, RED = 0, 1, 2
"""Light states as stored in logs and returned by ``LightSchedule.states``."""
STATE_NAMES = ("green", "yellow", "red")

STOP_LINE_LENGTH = 0.8 * LANE_WIDTH
"""Length of a stop line across its lane (metres)."""
STOP_LINE_THICKNESS = 1.2
"""Thickness of a stop line along its lane (metres); it ends where the junction begins."""


@dataclass(frozen=True)
class LightTiming:
    """Durations of one head's turn in a junction's cycle."""

    green_s: float = 10.0
    """Seconds of green for the active head."""
    yellow_s: float = 3.0
    """Seconds of yellow that follow."""
    all_red_s: float = 2.0
    """Seconds during which every head of the junction is red, before the next head's turn."""
    control_hz: int = 10
    """Control steps per second (the clock the lights are counted in)."""

    def __post_init__(self):
        for name in ("green_s", "yellow_s", "all_red_s"):
            check_positive(f"LightTiming.{name}", getattr(self, name), allow_zero=name != "green_s")
        check_int("LightTiming.control_hz", self.control_hz, minimum=1)

    @property
    def green_steps(self) -> int:
        return round(self.green_s * self.control_hz)

    @property
    def yellow_steps(self) -> int:
        return round(self.yellow_s * self.control_hz)

    @property
    def slot_steps(self) -> int:
        """Steps of one head's turn: green + yellow + all red."""
        return round((self.green_s + self.yellow_s + self.all_red_s) * self.control_hz)


@dataclass(frozen=True)
class StopLine:
    """Where a traffic-light head stops its lane."""

    id: int
    """Index of the light (and its stop line) in ``Town.stop_lines``."""
    approach: int
    """The approach it controls (see ``lanes.Approach``)."""
    junction: int
    """Index of its junction among the town's junctions (0 .. J-1)."""
    slot: int
    """Its turn in the junction's cycle (0 .. heads-1)."""
    entry: tuple[float, float]
    """The junction entry on the lane's centre line: the far edge of the stop line (metres)."""
    direction: tuple[float, float]
    """Unit vector of travel on the lane."""

    def corners(self) -> np.ndarray:
        """(4, 2) corners of the drawn stop line: ``STOP_LINE_LENGTH`` x ``STOP_LINE_THICKNESS``."""
        e, d = np.array(self.entry), np.array(self.direction)
        r = right_of(d) * STOP_LINE_LENGTH / 2
        back = -d * STOP_LINE_THICKNESS
        return np.array([e - r, e + r, e + r + back, e - r + back])


def make_stop_lines(approaches: list[Approach], junction_nodes: list[int]) -> list[StopLine]:
    """One stop line per approach of every T-junction, in the order of ``approaches``."""
    index = {n: j for j, n in enumerate(junction_nodes)}
    slots: dict[int, int] = {}
    out: list[StopLine] = []
    for ap in approaches:
        if not ap.is_junction:
            continue
        j = index[ap.node]
        slot = slots.get(j, 0)
        slots[j] = slot + 1
        out.append(
            StopLine(len(out), ap.id, j, slot, tuple(map(float, ap.entry)), tuple(map(float, ap.direction)))
        )
    return out


class LightSchedule:
    """The state of every head at any step, given each junction's phase offset."""

    def __init__(self, stop_lines: list[StopLine], n_junctions: int, timing: LightTiming = LightTiming()):
        self.timing = timing
        self.n_junctions = check_int("n_junctions", n_junctions, minimum=0)
        self.junction = np.array([s.junction for s in stop_lines], dtype=np.int64)  # (L,)
        self.slot = np.array([s.slot for s in stop_lines], dtype=np.int64)  # (L,)
        heads = (
            np.bincount(self.junction, minlength=n_junctions)
            if len(stop_lines)
            else np.zeros(n_junctions, int)
        )
        self.heads = heads  # (J,) heads per junction
        self.cycle = np.maximum(heads, 1) * timing.slot_steps  # (J,) steps of a full cycle

    @property
    def n_lights(self) -> int:
        return len(self.junction)

    def random_offsets(self, rng: np.random.Generator) -> np.ndarray:
        """(J,) a random phase (in steps) for each junction."""
        return (rng.random(self.n_junctions) * self.cycle).astype(np.int64)

    @property
    def period(self) -> int:
        """Steps after which every junction's cycle repeats (the lcm of their cycles)."""
        return int(np.lcm.reduce(self.cycle)) if len(self.cycle) else 1

    def table(self, offsets: np.ndarray) -> np.ndarray:
        """(period, L) states over one full period: ``states(t) == table[t % period]``."""
        return self.states(np.arange(self.period), offsets)

    def offsets_red_from_start(self, light: int) -> np.ndarray:
        """(J,) offsets under which ``light`` turns red at step 0 and stays red longest (its
        junction's other heads then take their turns); other junctions start at phase 0."""
        check_int("light", light, minimum=0, maximum=self.n_lights - 1)
        offsets = np.zeros(self.n_junctions, dtype=np.int64)
        j = self.junction[light]
        offsets[j] = (
            self.slot[light] * self.timing.slot_steps + self.timing.green_steps + self.timing.yellow_steps
        ) % self.cycle[j]
        return offsets

    def offsets_green_from_start(self, light: int, steps: int, rng: np.random.Generator) -> np.ndarray:
        """(J,) random offsets (``random_offsets``), except that ``light``'s junction starts at a phase, drawn
        uniformly among those that keep ``light`` green for the first ``steps`` steps."""
        check_int("light", light, minimum=0, maximum=self.n_lights - 1)
        check_int("steps", steps, minimum=1, maximum=self.timing.green_steps)
        offsets = self.random_offsets(rng)
        j = self.junction[light]
        late = int(rng.integers(self.timing.green_steps - steps + 1))  # steps of green already gone
        offsets[j] = (self.slot[light] * self.timing.slot_steps + late) % self.cycle[j]
        return offsets

    def states(self, t, offsets: np.ndarray) -> np.ndarray:
        """Light states (L,) uint8 at step ``t`` (or (T, L) for an array of T steps)."""
        t = np.asarray(t, dtype=np.int64)
        u = (t[..., None] + offsets[self.junction]) % self.cycle[self.junction]  # (..., L)
        active = (u // self.timing.slot_steps) == self.slot
        w = u % self.timing.slot_steps
        out = np.full(u.shape, RED, dtype=np.uint8)
        out[active & (w < self.timing.green_steps + self.timing.yellow_steps)] = YELLOW
        out[active & (w < self.timing.green_steps)] = GREEN
        return out


class RedLightMonitor:
    """Detects the rear of the car crossing red stop lines of its own lane."""

    def __init__(self, stop_lines: list[StopLine]):
        self.entry = np.array([s.entry for s in stop_lines], dtype=float).reshape(-1, 2)  # (L, 2)
        self.direction = np.array([s.direction for s in stop_lines], dtype=float).reshape(-1, 2)  # (L, 2)
        self.right = np.stack([self.direction[:, 1], -self.direction[:, 0]], axis=1)  # (L, 2)
        self._axes = np.concatenate([self.direction, self.right]).T  # (2, 2L)
        self._origin = np.concatenate(
            [(self.entry * self.direction).sum(1), (self.entry * self.right).sum(1)]
        )  # (2L,)
        self.reset()

    def reset(self) -> None:
        self.last_crossed = -1
        self.count = 0

    def crossed(self, rear_before: np.ndarray, rear_after: np.ndarray) -> np.ndarray:
        """Ids of the stop lines whose line the rear point crossed, going forward, within the lane."""
        # along-lane position of both rear points and lateral offset of the second, for all lines at once
        proj = np.array([rear_before, rear_after], dtype=float) @ self._axes - self._origin  # (2, 2L)
        L = len(self.entry)
        s0, s1, lateral = proj[0, :L], proj[1, :L], proj[1, L:]
        return np.flatnonzero((s0 < 0) & (s1 >= 0) & (np.abs(lateral) <= LANE_WIDTH / 2))

    def update(self, rear_before: np.ndarray, rear_after: np.ndarray, states: np.ndarray) -> list[int]:
        """Count the red lights run between two rear positions; return their ids."""
        ran = []
        for i in self.crossed(rear_before, rear_after):
            if states[i] == RED and i != self.last_crossed:
                ran.append(int(i))
                self.count += 1
            self.last_crossed = int(i)
        return ran
