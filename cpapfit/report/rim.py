"""A cushion's rim on the face as the report takes it: plain arrays, so any evaluation plugs in.

The report reads only these attributes, so an evaluation's own result objects with the same
names can be passed as they are.
"""

from dataclasses import dataclass

import numpy as np

from ..frozen import freeze_arrays

KPA_TO_MMHG = 7.50062


@dataclass(frozen=True)
class RimFit:
    """One cushion's rim seated on the face (scan frame).

    points: (K, 3) mm rim contact line, ordered around the loop (last joins first).
    gap_mm: (K,) mm between rim and skin (0 in contact; NaN where no skin was found).
    pressure_kpa: (K,) kPa contact pressure (0 where open), or None before evaluation.
    open: (K,) bool, the seal is open there (leak), or None before evaluation.
    """

    points: np.ndarray
    gap_mm: np.ndarray
    pressure_kpa: np.ndarray | None = None
    open: np.ndarray | None = None

    def __post_init__(self):
        freeze_arrays(self)


def has_pressure(rims: dict) -> bool:
    """True when every rim of {name: RimFit} carries pressure and open arrays."""
    return all(getattr(r, "pressure_kpa", None) is not None and getattr(r, "open", None) is not None for r in rims.values())


def loop_lengths(points: np.ndarray) -> np.ndarray:
    """(K,) mm length of rim attributed to each point of a closed loop (half of each adjacent segment)."""
    seg = np.linalg.norm(np.roll(points, -1, axis=0) - points, axis=1)
    return 0.5 * (seg + np.roll(seg, 1))


def longest_run_mm(points: np.ndarray, flag: np.ndarray) -> tuple[float, int]:
    """(length mm, middle index) of the longest run of consecutive flagged points around a closed loop;
    (0, -1) when none is flagged."""
    if not flag.any():
        return 0.0, -1
    if flag.all():
        return float(loop_lengths(points).sum()), 0
    start = int(np.flatnonzero(~flag)[0])  # roll so that no run wraps past the end
    order = np.roll(np.arange(len(flag)), -start)
    f, lengths = flag[order], loop_lengths(points)[order]
    best, best_mid, run, run_start = 0.0, -1, 0.0, 0
    for i, on in enumerate(f):
        if not on:
            run = 0.0
            continue
        run_start = i if run == 0.0 else run_start
        run += lengths[i]
        if run > best:
            best, best_mid = run, int(order[(run_start + i) // 2])
    return float(best), best_mid
