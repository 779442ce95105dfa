"""Estimated trajectories: TUM files and the absolute trajectory error against ground truth.

Estimates are {timestamp: (t, q)} as convert.pose_from_proto returns them (t xyz, q xyzw,
world_T_camera); ground truth as TumDataset.groundtruth() returns it.
"""

from __future__ import annotations

from typing import Dict, Mapping, Optional, Tuple

import numpy as np
from numpy.typing import ArrayLike

from .types import Pose

# {timestamp: (t, q)}: what write_tum_trajectory writes and ate() compares.
Estimates = Mapping[float, Tuple[ArrayLike, ArrayLike]]


def write_tum_trajectory(path: str, estimates: Estimates, comment: Optional[str] = None) -> None:
    """Writes "timestamp tx ty tz qx qy qz qw" lines in time order, after a header line (and
    `comment` as a second one when given)."""
    with open(path, "w", encoding="utf-8") as f:
        f.write("# timestamp tx ty tz qx qy qz qw\n")
        if comment:
            f.write(f"# {comment}\n")
        for ts in sorted(estimates):
            t, q = estimates[ts]
            values = np.concatenate([np.ravel(t), np.ravel(q)])
            f.write(f"{ts:.6f} " + " ".join(f"{v:.9f}" for v in values) + "\n")


def ate(estimates: Estimates, groundtruth: Mapping[float, Pose]) -> Optional[Dict[str, float]]:
    """Position error without alignment over the timestamps both have: {"rmse", "mean", "max"}
    in metres and "matched" (frames compared); None when none match."""
    errors = [np.linalg.norm(np.asarray(t) - groundtruth[ts][0])
              for ts, (t, _) in estimates.items() if ts in groundtruth]
    if not errors:
        return None
    e = np.array(errors)
    return {"rmse": float(np.sqrt(np.mean(e ** 2))), "mean": float(e.mean()),
            "max": float(e.max()), "matched": len(e)}
