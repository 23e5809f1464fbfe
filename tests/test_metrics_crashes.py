"""metrics.crashes_per_km against hand-computed cases."""

import numpy as np
import pytest

from ibc_tutorial.metrics import crashes_per_km


def test_crashes_per_km_by_hand():
    assert crashes_per_km(3, 1500.0) == pytest.approx(2.0)  # 3 crashes in 1.5 km
    assert crashes_per_km(0, 800.0) == 0.0
    # runs are pooled, not averaged: (1 + 2) / (0.5 + 1.5 km) = 1.5, not (2 + 4/3) / 2
    assert crashes_per_km([1, 2], [500.0, 1500.0]) == pytest.approx(1.5)
    assert crashes_per_km(np.array([4]), np.array([250.0])) == pytest.approx(16.0)
    # a run that drove nowhere adds its crashes, no distance
    assert crashes_per_km([1, 1], [0.0, 1000.0]) == pytest.approx(2.0)


@pytest.mark.parametrize(
    "crashes, distance, match",
    [
        (-1, 100.0, "crashes"),
        (1.5, 100.0, "crashes"),
        (1, 0.0, "distance_m"),
        (1, -5.0, "distance_m"),
        (1, float("nan"), "distance_m"),
        ([1, 2], [100.0], "equally long"),
    ],
)
def test_crashes_per_km_checks_its_arguments(crashes, distance, match):
    with pytest.raises(ValueError, match=match):
        crashes_per_km(crashes, distance)
