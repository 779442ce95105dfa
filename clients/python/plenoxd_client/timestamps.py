"""Matching and interpolating timestamped samples: associate() pairs two lists of timestamps
(TUM's associate.py), slerp() interpolates rotations between two samples.

numpy only: neither grpc nor the generated stubs, so that bench/bench_common.py can load this
file by its path (the one Python copy of these; the C++ one is core/datasets/tum_dataset.cc).
dataset.associate and convert.slerp are these functions.
"""

from __future__ import annotations

import bisect
from typing import List, Sequence, Tuple

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["associate", "slerp"]


def associate(first: Sequence[float], second: Sequence[float],
              max_difference: float = 0.02) -> List[Tuple[int, int]]:
    """Pairs (i, j) of timestamps first[i], second[j] at most max_difference apart, closest
    first, each index used once (TUM's associate.py); sorted by first[i]."""
    order = sorted(range(len(second)), key=lambda j: second[j])
    sorted_second = [second[j] for j in order]
    candidates = []
    for i, t in enumerate(first):
        k = bisect.bisect_left(sorted_second, t - max_difference)
        while k < len(sorted_second) and sorted_second[k] <= t + max_difference:
            j = order[k]
            candidates.append((abs(t - second[j]), i, j))
            k += 1
    candidates.sort()
    used_first, used_second, pairs = set(), set(), []
    for _, i, j in candidates:
        if i in used_first or j in used_second:
            continue
        used_first.add(i)
        used_second.add(j)
        pairs.append((i, j))
    pairs.sort(key=lambda p: (first[p[0]], p[0]))
    return pairs


def slerp(q0: ArrayLike, q1: ArrayLike, alpha: float) -> np.ndarray:
    """Spherical interpolation between quaternions (x, y, z, w), the shorter way round."""
    q0 = np.asarray(q0, dtype=np.float64) / np.linalg.norm(q0)
    q1 = np.asarray(q1, dtype=np.float64) / np.linalg.norm(q1)
    d = float(np.dot(q0, q1))
    if d < 0.0:
        q1, d = -q1, -d
    if d > 1.0 - 1e-9:  # nearly identical: linear is exact enough and avoids 0/0
        q = (1.0 - alpha) * q0 + alpha * q1
        return q / np.linalg.norm(q)
    theta = np.arccos(min(d, 1.0))
    s = np.sin(theta)
    return (np.sin((1.0 - alpha) * theta) / s) * q0 + (np.sin(alpha * theta) / s) * q1
