"""Losses of the book, each citing the equation it implements.

Explicit policies (chapter 02): Beta negative log-likelihood (eq. 1 of the DA-IBC paper),
mixture-density NLL, classification over bins. Energy models (chapters 03-04): InfoNCE
(eqs. 2-3 of the DA-IBC paper, weighted: its eq. 5), cross-entropy over a fixed grid with
soft targets (eq. 5 of the steering-EBM paper) and temporal smoothing (its eq. 4).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F  # noqa: F401

from ibc_tutorial.utils import check_tensor  # noqa: F401
