"""metrics.swerve_rate (Table 2 of the steering-EBM paper) and the side-road traces it reads."""

import math

import numpy as np
import pytest
import torch

from ibc_tutorial.metrics import swerve_rate
from ibc_tutorial.toy import SideRoadWorld


def test_swerve_rate_by_hand():
    nan = math.nan
    traces = torch.tensor(
        [
            [nan, 0.00, 0.10, 0.05],  # peak 0.10 < slight: no swerve, 0
            [nan, 0.10, 0.40, 0.20],  # peak 0.40 in [slight, clear): slight swerve, 1/2
            [0.0, 0.50, 1.20, 0.30],  # peak 1.20 >= clear: a swerve, 1
            [0.0, -0.8, -1.5, -0.2],  # away from the side road only: 0
            [0.0, 0.30, 0.30, 0.30],  # exactly at slight: 1/2
            [0.0, 1.00, 0.00, 0.00],  # exactly at clear: 1
        ]
    )
    scores = swerve_rate(traces, slight=0.3, clear=1.0, per_pass=True)
    assert scores.tolist() == [0.0, 0.5, 1.0, 0.0, 0.5, 1.0]
    # (0 + 1/2 + 1 + 0 + 1/2 + 1) / 6 = 3 / 6
    assert swerve_rate(traces, slight=0.3, clear=1.0) == pytest.approx(0.5)
    # one threshold only (slight == clear): every swerve counts whole
    assert swerve_rate(traces, slight=0.3, clear=0.3) == pytest.approx(4 / 6)
    assert swerve_rate(np.asarray(traces), slight=0.3, clear=1.0) == pytest.approx(0.5)


def test_swerve_rate_checks_its_arguments():
    ok = torch.zeros(2, 3)
    with pytest.raises(ValueError, match="slight"):
        swerve_rate(ok, slight=0.0, clear=1.0)
    with pytest.raises(ValueError, match="clear"):
        swerve_rate(ok, slight=0.5, clear=0.2)
    with pytest.raises(ValueError, match=r"\(P, T\)"):
        swerve_rate(torch.zeros(3), slight=0.3, clear=1.0)
    with pytest.raises(ValueError, match=r"\(P, T\)"):
        swerve_rate(torch.zeros(0, 3), slight=0.3, clear=1.0)
    with pytest.raises(ValueError, match="non-NaN"):
        swerve_rate(torch.tensor([[0.1, 0.2], [math.nan, math.nan]]), slight=0.3, clear=1.0)


def test_side_road_traces_agree_with_swerve():
    w = SideRoadWorld()
    ro = w.rollout(lambda obs: torch.full((len(obs), 1), 0.05), 4, seed=0)  # a slow drift right
    traces = w.swerve_traces(ro)  # (E, T+1)
    assert traces.shape == ro.states.shape[:2]
    near = ro.states[:, :, 0] >= w.config.branch_x - w.config.swerve_from
    assert torch.isnan(traces[~near]).all() and torch.isfinite(traces[near]).all()
    stay = w.stayed_on_main_road(ro)
    peak = torch.nan_to_num(traces, nan=0.0).max(dim=1).values.clamp_min(0.0)
    assert torch.allclose(w.swerve(ro)[stay], peak[stay])
    assert float(peak.min()) > 0.0  # steering right moves the car towards the side road
