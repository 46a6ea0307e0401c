"""Closed loops of points (a seal curve, a rim): the length each point stands for, and the
longest run of flagged points around the loop."""

import numpy as np


def loop_lengths(points: np.ndarray) -> np.ndarray:
    """(K,) mm length of rim attributed to each point of a closed loop (half of each adjacent segment)."""
    seg = np.linalg.norm(np.roll(points, -1, axis=0) - points, axis=1)
    return 0.5 * (seg + np.roll(seg, 1))


def longest_run(flag: np.ndarray, lengths: np.ndarray) -> tuple[float, int]:
    """(its length, its middle index) of the longest run of consecutive flagged points of (K,) bool
    `flag` around a closed loop whose points stand for (K,) `lengths` (`loop_lengths`, or ones to
    count them); (0, -1) when none is flagged."""
    if not flag.any():
        return 0.0, -1
    if flag.all():
        return float(lengths.sum()), 0
    start = int(np.flatnonzero(~flag)[0])  # roll so that no run wraps past the end
    order = np.roll(np.arange(len(flag)), -start)
    f, lengths = flag[order], lengths[order]
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
