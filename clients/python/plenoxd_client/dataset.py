"""A reader for RGB-D sequences in the TUM layout (see ../shared/data/README.md).

    rgb/<t>.png, depth/<t>.png      8-bit RGB, 16-bit depth (metres = value / depth_scale)
    associations.txt                "t_rgb rgb/<t>.png t_depth depth/<t>.png" (preferred), or
    rgb.txt + depth.txt             "timestamp filename", matched by nearest timestamp
    groundtruth.txt (optional)      "timestamp tx ty tz qx qy qz qw", camera-to-world
    intrinsics.txt                  "fx fy cx cy width height depth_scale [k1 k2 p1 p2 k3]"

The images are passed on as their file bytes (PNG/JPEG; no decoding or re-encoding), which is
what plenoxd accepts. Ground-truth poses follow the C++ reader: the samples within
max_time_difference (20 ms) of a frame are interpolated (linear translation, slerp rotation),
or the single one in range is used.
"""

from __future__ import annotations

import bisect
import os
from dataclasses import dataclass, field
from typing import Dict, Iterator, List, Optional, Sequence, Tuple, Union, overload

import numpy as np

from . import convert
from ._proto import plenoxd_pb2 as pb
from .timestamps import associate
from .types import Pose

# A ground-truth sample: (timestamp, t ndarray(3), q ndarray(4) x y z w).
GroundTruthSample = Tuple[float, np.ndarray, np.ndarray]

__all__ = ["Intrinsics", "Frame", "TumDataset", "read_intrinsics", "read_groundtruth",
           "pose_at_time", "associate"]


@dataclass
class Intrinsics:
    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    depth_scale: float
    # k1 k2 p1 p2 k3 (OpenCV order). plenoxd's API has no distortion: images must be undistorted.
    distortion: Tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0)

    def to_proto(self) -> pb.Intrinsics:
        return convert.intrinsics_to_proto(self)


@dataclass
class Frame:
    """One RGB-D frame of a sequence: encoded image bytes plus what plenoxd needs with them."""
    index: int
    timestamp: float
    intrinsics: Intrinsics
    color: bytes
    depth: bytes
    color_encoding: str = "png"       # "png" or "jpeg"
    depth_encoding: str = "png16"
    pose: Optional[Pose] = None       # ground truth (t, q xyzw), if known
    color_path: str = ""
    depth_path: str = ""
    camera_id: str = ""

    def to_proto(self, with_pose: bool = True) -> pb.Frame:
        return convert.frame_to_proto(self, with_pose=with_pose)


@dataclass
class _FrameFiles:
    timestamp: float
    color_path: str
    depth_path: str
    pose: Optional[Pose] = field(default=None)


def _rows(path):
    """(line number, fields) of the non-blank, non-'#' lines of a text file."""
    with open(path, "r", encoding="utf-8") as f:
        for number, line in enumerate(f, start=1):
            line = line.strip()
            if line and not line.startswith("#"):
                yield number, line.split()


def _floats(path, number, fields):
    try:
        return [float(v) for v in fields]
    except ValueError:
        raise ValueError(f"{path}:{number}: expected numbers, got {' '.join(fields)!r}") from None


def read_intrinsics(path: str) -> Intrinsics:
    """The calibration line of intrinsics.txt (7 or 12 numbers)."""
    for number, fields in _rows(path):
        if len(fields) not in (7, 12):
            raise ValueError(f"{path}:{number}: expected 12 numbers \"fx fy cx cy width height "
                             f"depth_scale k1 k2 p1 p2 k3\", got {len(fields)}")
        v = _floats(path, number, fields)
        k = Intrinsics(v[0], v[1], v[2], v[3], int(v[4]), int(v[5]), v[6])
        if len(v) == 12:
            k.distortion = tuple(v[7:12])
        if k.width <= 0 or k.height <= 0 or k.fx <= 0 or k.fy <= 0 or k.depth_scale <= 0:
            raise ValueError(f"{path}:{number}: sizes, focal lengths and depth_scale must be > 0")
        return k
    raise ValueError(f"{path}: no data line; expected \"fx fy cx cy width height depth_scale "
                     "k1 k2 p1 p2 k3\"")


def read_groundtruth(path: str) -> List[GroundTruthSample]:
    """Sorted list of (timestamp, t ndarray(3), q ndarray(4) xyzw)."""
    samples = []
    for number, fields in _rows(path):
        if len(fields) != 8:
            raise ValueError(f"{path}:{number}: expected 8 numbers \"timestamp tx ty tz qx qy qz "
                             f"qw\", got {len(fields)}")
        v = _floats(path, number, fields)
        q = np.array(v[4:8])
        if abs(np.linalg.norm(q) - 1.0) > 1e-2:
            raise ValueError(f"{path}:{number}: quaternion qx qy qz qw must have unit length, "
                             f"got norm {np.linalg.norm(q):.6g}")
        samples.append((v[0], np.array(v[1:4]), q / np.linalg.norm(q)))
    samples.sort(key=lambda s: s[0])
    return samples


def pose_at_time(samples: Sequence[GroundTruthSample], time: float,
                 max_difference: float = 0.02) -> Optional[Pose]:
    """The ground-truth pose (t, q) at `time`, interpolated between the samples either side
    when both are within max_difference, else the one that is; None when neither is."""
    times = [s[0] for s in samples]
    i = bisect.bisect_left(times, time)
    if i < len(samples) and samples[i][0] == time:
        return samples[i][1].copy(), samples[i][2].copy()
    has_after = i < len(samples) and samples[i][0] - time <= max_difference
    has_before = i > 0 and time - samples[i - 1][0] <= max_difference
    if has_before and has_after:
        (ta, pa, qa), (tb, pb_, qb) = samples[i - 1], samples[i]
        alpha = (time - ta) / (tb - ta)
        return (1.0 - alpha) * pa + alpha * pb_, convert.slerp(qa, qb, alpha)
    if has_before:
        return samples[i - 1][1].copy(), samples[i - 1][2].copy()
    if has_after:
        return samples[i][1].copy(), samples[i][2].copy()
    return None


class TumDataset:
    """A TUM-layout sequence. Indexable and iterable; frames are read from disk on access.

        seq = TumDataset("/data/tum_fr3_teddy")
        for frame in seq: ...            # Frame with .color/.depth PNG bytes, .pose (t, q)
        seq[0].to_proto(with_pose=False)
    """

    def __init__(self, directory: str, max_time_difference: float = 0.02,
                 intrinsics: Optional[Intrinsics] = None):
        if not os.path.isdir(directory):
            raise FileNotFoundError(f"{directory}: not a directory")
        self.directory = directory
        self.name = os.path.basename(os.path.normpath(directory))
        if intrinsics is None:
            path = os.path.join(directory, "intrinsics.txt")
            if not os.path.exists(path):
                raise FileNotFoundError(f"{path} is missing (one line \"fx fy cx cy width height "
                                        "depth_scale k1 k2 p1 p2 k3\")")
            intrinsics = read_intrinsics(path)
        self.intrinsics = intrinsics
        self._files = self._read_lists(max_time_difference)
        self._files.sort(key=lambda f: f.timestamp)
        gt_path = os.path.join(directory, "groundtruth.txt")
        self.has_groundtruth = os.path.exists(gt_path)
        if self.has_groundtruth:
            samples = read_groundtruth(gt_path)
            for f in self._files:
                f.pose = pose_at_time(samples, f.timestamp, max_time_difference)

    def _path(self, name: str) -> str:
        return os.path.join(self.directory, name)

    def _read_lists(self, max_time_difference: float) -> List[_FrameFiles]:
        assoc = self._path("associations.txt")
        if os.path.exists(assoc):
            files = []
            for number, fields in _rows(assoc):
                if len(fields) != 4:
                    raise ValueError(f"{assoc}:{number}: expected fields \"t_rgb rgb_file t_depth "
                                     "depth_file\"")
                t = _floats(assoc, number, [fields[0], fields[2]])[0]
                files.append(_FrameFiles(t, self._path(fields[1]), self._path(fields[3])))
            if not files:
                raise ValueError(f"{assoc}: lists no frames")
            return files
        rgb_list, depth_list = self._path("rgb.txt"), self._path("depth.txt")
        if not (os.path.exists(rgb_list) and os.path.exists(depth_list)):
            raise FileNotFoundError(f"{self.directory}: a TUM sequence needs associations.txt or "
                                    "rgb.txt and depth.txt")
        lists = []
        for path in (rgb_list, depth_list):
            entries = []
            for number, fields in _rows(path):
                if len(fields) != 2:
                    raise ValueError(f"{path}:{number}: expected fields \"timestamp filename\"")
                entries.append((_floats(path, number, fields[:1])[0], self._path(fields[1])))
            lists.append(entries)
        rgb, depth = lists
        pairs = associate([e[0] for e in rgb], [e[0] for e in depth], max_time_difference)
        if not pairs:
            raise ValueError(f"{self.directory}: no colour/depth pairs within "
                             f"{max_time_difference} s between rgb.txt and depth.txt")
        return [_FrameFiles(rgb[i][0], rgb[i][1], depth[j][1]) for i, j in pairs]

    def __len__(self) -> int:
        return len(self._files)

    @overload
    def __getitem__(self, index: int) -> Frame: ...

    @overload
    def __getitem__(self, index: slice) -> List[Frame]: ...

    def __getitem__(self, index: Union[int, slice]) -> Union[Frame, List[Frame]]:
        if isinstance(index, slice):
            return [self[i] for i in range(*index.indices(len(self)))]
        if index < 0:
            index += len(self)
        if not 0 <= index < len(self):
            raise IndexError(f"frame {index} of {len(self)}")
        f = self._files[index]
        with open(f.color_path, "rb") as c:
            color = c.read()
        with open(f.depth_path, "rb") as d:
            depth = d.read()
        ext = os.path.splitext(f.color_path)[1].lower()
        encoding = "jpeg" if ext in (".jpg", ".jpeg") else "png"
        pose = None if f.pose is None else (f.pose[0].copy(), f.pose[1].copy())
        return Frame(index=index, timestamp=f.timestamp, intrinsics=self.intrinsics, color=color,
                     depth=depth, color_encoding=encoding, pose=pose, color_path=f.color_path,
                     depth_path=f.depth_path)

    def __iter__(self) -> Iterator[Frame]:
        for i in range(len(self)):
            yield self[i]

    @property
    def timestamps(self) -> List[float]:
        return [f.timestamp for f in self._files]

    def groundtruth(self) -> Dict[float, Pose]:
        """{timestamp: (t, q)} of the frames that have a ground-truth pose."""
        return {f.timestamp: f.pose for f in self._files if f.pose is not None}
