"""Pooling of packed BEV bytes from the 192 view to a smaller one, as strided slices (the BEV's hot spot).

``bev.BEVRenderer`` renders a smaller view (96, 64, 48, 32) by pooling k x k blocks of the 192 view's packed
bytes (``bev`` module docstring): OR of the two road bits, maximum of each of the three 2-bit light codes.
Written as numpy reductions over the block axes (``reshape(S, k, S, k)`` then ``reduce``/``max`` over the
axes of length k), each reduction pays numpy's per-row overhead on rows of k = 2..6 elements: measured
with ``cProfile`` on environment steps (``benchmarks/RESULTS.md``), those reductions took about 60 % of a
64 px environment step.

``pool_packed`` computes the same bytes from the k² strided slices ``codes[..., i::k, j::k]``, each a whole
(S, S) array: road |= slice & 3, and for each light code, max(code bits) = max(slice & mask) because a
2-bit field compared in place (its mask applied, not shifted down) orders like the field itself. Bit for
bit the same views (``tests/test_driving_pooling.py``), in k² x 4 elementwise operations.
"""

from __future__ import annotations

import numpy as np

from ibc_tutorial.utils import check_int

ROAD_MASK = 0b11
"""Bits 0-1 of a packed byte: the drivable-area and lane-boundary channels (OR-pooled)."""
LIGHT_MASKS = (0b11 << 2, 0b11 << 4, 0b11 << 6)
"""The three 2-bit light-code fields of a packed byte (channels 2, 3, 4; max-pooled)."""


def pool_packed(codes: np.ndarray, k: int) -> np.ndarray:
    """(..., k S, k S) packed uint8 bytes -> (..., S, S): OR of the road bits and maximum of each light code
    over every k x k block (``bev.BEVRenderer._pool``'s result, bit for bit)."""
    k = check_int("k", k, minimum=1)
    codes = np.asarray(codes)
    if codes.dtype != np.uint8 or codes.ndim < 2 or codes.shape[-1] % k or codes.shape[-2] % k:
        raise ValueError(
            f"codes must be uint8 of shape (..., H, W) with H and W multiples of k = {k}, got {codes.dtype} "
            f"of shape {codes.shape}"
        )
    if k == 1:
        return codes
    parts = [codes[..., i::k, j::k] for i in range(k) for j in range(k)]  # k² views (..., S, S)
    road = parts[0] & ROAD_MASK
    lights = [parts[0] & m for m in LIGHT_MASKS]
    for part in parts[1:]:
        road |= part & ROAD_MASK
        for field, m in zip(lights, LIGHT_MASKS, strict=True):
            np.maximum(field, part & m, out=field)
    return road | lights[0] | lights[1] | lights[2]
