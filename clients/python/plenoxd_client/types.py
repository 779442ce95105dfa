"""Type aliases of what the client's calls accept, for annotations in code that uses it.

    from plenoxd_client.types import FrameLike, PoseLike
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Mapping, Sequence, Tuple, Union

import numpy as np
from numpy.typing import ArrayLike

if TYPE_CHECKING:  # only for type checkers: dataset imports convert, which uses these
    from ._proto import plenoxd_pb2 as pb
    from .dataset import Frame, Intrinsics

__all__ = ["Pose", "PoseLike", "IntrinsicsLike", "FrameLike"]

# (t, q): translation x y z and Hamilton quaternion x y z w, world_T_camera, metres.
Pose = Tuple[np.ndarray, np.ndarray]

# What convert.as_pose() reads: (t, q), a 4x4 or 3x4 matrix, 7 numbers in TUM order
# (tx ty tz qx qy qz qw), a dict with "t" and "q", or a plenoxd.v1.Pose.
PoseLike = Union[Tuple[ArrayLike, ArrayLike], np.ndarray, Sequence[float], Mapping[str, ArrayLike],
                 "pb.Pose"]

# A dataset.Intrinsics, a plenoxd.v1.Intrinsics, or a dict of fx fy cx cy width height
# [depth_scale].
IntrinsicsLike = Union["Intrinsics", "pb.Intrinsics", Mapping[str, float]]

# A dataset.Frame, a plenoxd.v1.Frame, or a dict with the same keys (convert.frame_to_proto).
FrameLike = Union["Frame", "pb.Frame", Mapping[str, Any]]
