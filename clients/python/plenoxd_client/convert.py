"""numpy <-> plenoxd.v1 messages.

Poses are world_T_camera (camera-to-world), OpenCV camera axes, metres. In Python a pose is either
a pair ``(t, q)`` -- translation ``(x, y, z)`` and Hamilton quaternion ``(x, y, z, w)`` -- or a
4x4 homogeneous matrix. Depth images are z-depth; on the wire they are integers with
``depth_scale`` units per metre, in numpy they are ``uint16`` in those units or float metres.
"""

from __future__ import annotations

from typing import Any, Callable, Optional, Union

import numpy as np
from numpy.typing import ArrayLike

from ._proto import plenoxd_pb2 as pb
from .timestamps import slerp
from .types import FrameLike, IntrinsicsLike, Pose, PoseLike

__all__ = [
    "pb",
    "quat_to_matrix",
    "matrix_to_quat",
    "slerp",
    "pose_to_matrix",
    "matrix_to_pose",
    "as_pose",
    "pose_to_proto",
    "pose_from_proto",
    "intrinsics_to_proto",
    "frame_from_arrays",
    "frame_to_proto",
    "decode_color",
    "decode_depth",
]


# --- rotations ---------------------------------------------------------------------------------

def quat_to_matrix(q: ArrayLike) -> np.ndarray:
    """3x3 rotation of the quaternion (x, y, z, w); normalised first."""
    x, y, z, w = np.asarray(q, dtype=np.float64) / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def matrix_to_quat(r: ArrayLike) -> np.ndarray:
    """Quaternion (x, y, z, w) with w >= 0 of a 3x3 rotation matrix (Shepperd's method)."""
    r = np.asarray(r, dtype=np.float64)
    trace = r[0, 0] + r[1, 1] + r[2, 2]
    if trace > 0:
        s = 2.0 * np.sqrt(trace + 1.0)
        q = [(r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s, 0.25 * s]
    elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
        s = 2.0 * np.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2])
        q = [0.25 * s, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s, (r[2, 1] - r[1, 2]) / s]
    elif r[1, 1] > r[2, 2]:
        s = 2.0 * np.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2])
        q = [(r[0, 1] + r[1, 0]) / s, 0.25 * s, (r[1, 2] + r[2, 1]) / s, (r[0, 2] - r[2, 0]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1])
        q = [(r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, 0.25 * s, (r[1, 0] - r[0, 1]) / s]
    unit = np.array(q) / np.linalg.norm(q)
    return -unit if unit[3] < 0 else unit


# --- poses -------------------------------------------------------------------------------------

def pose_to_matrix(t: ArrayLike, q: ArrayLike) -> np.ndarray:
    """4x4 world_T_camera of translation t and quaternion q (x, y, z, w)."""
    m = np.eye(4)
    m[:3, :3] = quat_to_matrix(q)
    m[:3, 3] = np.asarray(t, dtype=np.float64)
    return m


def matrix_to_pose(m: ArrayLike) -> Pose:
    """(t, q) of a 4x4 (or 3x4) rigid transform."""
    m = np.asarray(m, dtype=np.float64)
    return m[:3, 3].copy(), matrix_to_quat(m[:3, :3])


def as_pose(pose: PoseLike) -> Pose:
    """Normalises any pose form -- (t, q), a 4x4/3x4 matrix, a dict with t/q, or a Pose message --
    to (t ndarray(3), q ndarray(4) x y z w)."""
    if isinstance(pose, pb.Pose):
        return pose_from_proto(pose)
    if isinstance(pose, dict):
        return (np.asarray(pose["t"], dtype=np.float64), np.asarray(pose["q"], dtype=np.float64))
    if isinstance(pose, np.ndarray) and pose.ndim == 2:
        return matrix_to_pose(pose)
    if isinstance(pose, (tuple, list)) and len(pose) == 2:
        t = np.asarray(pose[0], dtype=np.float64).reshape(-1)
        q = np.asarray(pose[1], dtype=np.float64).reshape(-1)
        if t.shape != (3,) or q.shape != (4,):
            raise ValueError("a pose (t, q) needs 3 translation and 4 quaternion values (x y z w)")
        return t, q
    arr = np.asarray(pose, dtype=np.float64)
    if arr.shape in ((4, 4), (3, 4)):
        return matrix_to_pose(arr)
    if arr.shape == (7,):  # flat tx ty tz qx qy qz qw, the TUM line order
        return arr[:3].copy(), arr[3:].copy()
    raise ValueError(f"cannot read a pose from {type(pose).__name__} of shape {arr.shape}; "
                     "use (t_xyz, q_xyzw), a 4x4 matrix or a Pose message")


def pose_to_proto(pose: PoseLike, out: Optional[pb.Pose] = None) -> pb.Pose:
    """A plenoxd.v1.Pose from any pose form accepted by as_pose(), with the wire's convention
    (as the C++ proto/pose_codec.h): a unit quaternion with qw >= 0."""
    t, q = as_pose(pose)
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(q))):
        raise ValueError("pose is not finite")
    norm = np.linalg.norm(q)
    if norm < 1e-6:  # the daemon's threshold for "the quaternion is zero"
        raise ValueError("the quaternion is zero")
    q = q / norm
    if q[3] < 0.0:  # q and -q are the same rotation; one sign makes equal poses equal messages
        q = -q
    out = pb.Pose() if out is None else out
    out.tx, out.ty, out.tz = (float(v) for v in t)
    out.qx, out.qy, out.qz, out.qw = (float(v) for v in q)
    return out


def pose_from_proto(p: pb.Pose) -> Pose:
    """(t ndarray(3), q ndarray(4) x y z w) of a plenoxd.v1.Pose."""
    return (np.array([p.tx, p.ty, p.tz], dtype=np.float64),
            np.array([p.qx, p.qy, p.qz, p.qw], dtype=np.float64))


# --- intrinsics and frames ---------------------------------------------------------------------

_INTRINSICS_FIELDS = ("fx", "fy", "cx", "cy", "width", "height", "depth_scale")


def intrinsics_to_proto(k: IntrinsicsLike,
                        out: Optional[pb.Intrinsics] = None) -> pb.Intrinsics:
    """A plenoxd.v1.Intrinsics from a message, a dict, or an object with fx fy cx cy width
    height [depth_scale] attributes (e.g. dataset.Intrinsics)."""
    out = pb.Intrinsics() if out is None else out
    if isinstance(k, pb.Intrinsics):
        out.CopyFrom(k)
        return out
    get = k.get if isinstance(k, dict) else (lambda name, default=None: getattr(k, name, default))
    for name in _INTRINSICS_FIELDS:
        value = get(name, None)
        if value is None:
            if name == "depth_scale":
                continue
            raise ValueError(f"intrinsics: {name} is missing")
        setattr(out, name, int(value) if name in ("width", "height") else float(value))
    return out


_COLOR_ENCODINGS = {
    "png": pb.COLOR_ENCODING_PNG,
    "jpeg": pb.COLOR_ENCODING_JPEG,
    "jpg": pb.COLOR_ENCODING_JPEG,
    "raw_rgb8": pb.COLOR_ENCODING_RAW_RGB8,
}
_DEPTH_ENCODINGS = {"png16": pb.DEPTH_ENCODING_PNG16, "png": pb.DEPTH_ENCODING_PNG16,
                    "raw_u16": pb.DEPTH_ENCODING_RAW_U16}


def _color_encoding(value: Union[str, int]) -> int:
    if isinstance(value, str):
        try:
            return _COLOR_ENCODINGS[value.lower()]
        except KeyError:
            raise ValueError(f"unknown colour encoding {value!r}") from None
    return int(value)


def _depth_encoding(value: Union[str, int]) -> int:
    if isinstance(value, str):
        try:
            return _DEPTH_ENCODINGS[value.lower()]
        except KeyError:
            raise ValueError(f"unknown depth encoding {value!r}") from None
    return int(value)


def frame_from_arrays(color: ArrayLike, depth: ArrayLike, intrinsics: IntrinsicsLike,
                      timestamp: float = 0.0, pose: Optional[PoseLike] = None,
                      camera_id: str = "", depth_scale: Optional[float] = None) -> pb.Frame:
    """A raw plenoxd.v1.Frame (RAW_RGB8 + RAW_U16) from numpy images, for live cameras.

    color: HxWx3 uint8 RGB (HxW grey is expanded). depth: HxW uint16 in depth_scale units per
    metre, or float metres (converted with depth_scale; NaN, inf and <= 0 become 0 = no
    measurement). depth_scale defaults to the intrinsics' (or 1000 when that is unset).
    """
    k = intrinsics_to_proto(intrinsics)
    color = np.asarray(color)
    depth = np.asarray(depth)
    if color.ndim == 2:
        color = np.repeat(color[:, :, None], 3, axis=2)
    if color.ndim != 3 or color.shape[2] != 3:
        raise ValueError(f"color must be HxWx3 RGB, got shape {color.shape}")
    if color.dtype != np.uint8:
        raise ValueError(f"color must be uint8, got {color.dtype}")
    if depth.ndim != 2:
        raise ValueError(f"depth must be HxW, got shape {depth.shape}")
    h, w = color.shape[:2]
    if depth.shape != (h, w):
        raise ValueError(f"depth is {depth.shape[1]}x{depth.shape[0]}, colour is {w}x{h}")
    if k.width == 0 and k.height == 0:
        k.width, k.height = w, h
    if (k.width, k.height) != (w, h):
        raise ValueError(f"images are {w}x{h}, the intrinsics say {k.width}x{k.height}")
    scale = float(depth_scale if depth_scale is not None else (k.depth_scale or 1000.0))
    k.depth_scale = scale
    if np.issubdtype(depth.dtype, np.floating):
        d = np.where(np.isfinite(depth) & (depth > 0), depth, 0.0) * scale
        depth_u16 = np.clip(np.rint(d), 0, 65535).astype("<u2")
    elif depth.dtype == np.uint16:
        depth_u16 = depth.astype("<u2", copy=False)
    else:
        raise ValueError(f"depth must be uint16 or float metres, got {depth.dtype}")
    frame = pb.Frame(camera_id=camera_id, timestamp=float(timestamp), intrinsics=k,
                     color=np.ascontiguousarray(color).tobytes(),
                     color_encoding=pb.COLOR_ENCODING_RAW_RGB8,
                     depth=np.ascontiguousarray(depth_u16).tobytes(),
                     depth_encoding=pb.DEPTH_ENCODING_RAW_U16)
    if pose is not None:
        pose_to_proto(pose, frame.pose)
    return frame


def frame_to_proto(frame: FrameLike, with_pose: bool = True) -> pb.Frame:
    """A plenoxd.v1.Frame from a Frame message (returned as is), a dataset.Frame, or a dict with
    the same keys (timestamp, intrinsics, color, color_encoding, depth, depth_encoding, pose,
    camera_id). with_pose=False leaves a dataset frame's ground-truth pose out (Track treats a
    frame's pose as a prior, so replaying a dataset must not send it)."""
    if isinstance(frame, pb.Frame):
        return frame
    get: Callable[..., Any] = frame.get if isinstance(frame, dict) else (
        lambda name, default=None: getattr(frame, name, default))
    color, depth = get("color"), get("depth")
    for name, value in (("color", color), ("depth", depth), ("intrinsics", get("intrinsics"))):
        if value is None:
            raise ValueError(f"frame: {name} is missing (a frame needs color, depth, intrinsics)")
    if isinstance(color, np.ndarray) or isinstance(depth, np.ndarray):
        return frame_from_arrays(color, depth, get("intrinsics"), get("timestamp", 0.0) or 0.0,
                                 get("pose") if with_pose else None, get("camera_id", "") or "")
    out = pb.Frame(camera_id=get("camera_id", "") or "", timestamp=float(get("timestamp", 0.0)),
                   color=bytes(color), color_encoding=_color_encoding(get("color_encoding", "png")),
                   depth=bytes(depth),
                   depth_encoding=_depth_encoding(get("depth_encoding", "png16")))
    intrinsics_to_proto(get("intrinsics"), out.intrinsics)
    pose = get("pose")
    if with_pose and pose is not None:
        pose_to_proto(pose, out.pose)
    return out


# --- images coming back ------------------------------------------------------------------------

def _cv2() -> Any:
    try:
        import cv2  # noqa: PLC0415 (optional: only PNG/JPEG decoding needs it)
    except ImportError as e:
        raise RuntimeError("decoding PNG/JPEG needs python3-opencv; ask for the RAW encodings "
                           "instead (Client.render does)") from e
    return cv2


def decode_color(data: bytes, encoding: Union[str, int], width: int,
                 height: int) -> np.ndarray:
    """HxWx3 uint8 RGB from the bytes of a RenderResponse (or Frame) colour image."""
    encoding = _color_encoding(encoding)
    if encoding == pb.COLOR_ENCODING_RAW_RGB8:
        arr = np.frombuffer(data, dtype=np.uint8)
        if arr.size != width * height * 3:
            raise ValueError(f"raw RGB8: {arr.size} bytes for {width}x{height}")
        return arr.reshape(height, width, 3).copy()
    if encoding in (pb.COLOR_ENCODING_PNG, pb.COLOR_ENCODING_JPEG):
        cv2 = _cv2()
        img = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_COLOR)
        if img is None:
            raise ValueError("colour image does not decode")
        return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    raise ValueError(f"unknown colour encoding {encoding}")


def decode_depth(data: bytes, encoding: Union[str, int], width: int, height: int,
                 depth_scale: float = 1000.0) -> np.ndarray:
    """HxW float32 metres (0 = nothing) from depth bytes; rendered depth is in millimetres
    (depth_scale 1000)."""
    encoding = _depth_encoding(encoding)
    if encoding == pb.DEPTH_ENCODING_RAW_U16:
        arr = np.frombuffer(data, dtype="<u2")
        if arr.size != width * height:
            raise ValueError(f"raw uint16 depth: {len(data)} bytes for {width}x{height}")
        raw = arr.reshape(height, width)
    elif encoding == pb.DEPTH_ENCODING_PNG16:
        cv2 = _cv2()
        raw = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
        if raw is None or raw.ndim != 2:
            raise ValueError("depth image does not decode to one channel")
    else:
        raise ValueError(f"unknown depth encoding {encoding}")
    return raw.astype(np.float32) / np.float32(depth_scale)
