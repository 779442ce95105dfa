"""Python client for plenoxd, the Plenoxel RGB-D mapping and tracking daemon.

Needs Debian's python3-grpcio (grpcio 1.51, protobuf 4.21) and python3-numpy, and the stubs the
build generates into <build>/clients/python/gen (both folders on PYTHONPATH):

    PYTHONPATH=<build>/clients/python/gen:<repo>/clients/python /usr/bin/python3 ...

    from plenoxd_client import Client, TumDataset
"""

try:
    from plenoxd.v1 import plenoxd_pb2 as _probe  # noqa: F401 -- generated at build time
    import health_pb2 as _health_probe  # noqa: F401
except ImportError as _e:  # pragma: no cover - depends on the environment
    raise ImportError(
        "plenoxd_client needs the generated gRPC stubs (plenoxd/v1/plenoxd_pb2.py, "
        "health_pb2.py): build the project (target plx_python_stubs) and put "
        "<build>/clients/python/gen on PYTHONPATH") from _e

from . import convert, dataset, trajectory
from .client import (DEFAULT_MAX_MESSAGE_BYTES, Client, MeshExport, PlenoxdError, Rendering,
                     SlamStream, TrackStream, as_dict, correct_pose, estimate_pose, slam_pose,
                     slam_state_name, state_name)
from .convert import pb
from .dataset import Frame, Intrinsics, TumDataset

__all__ = [
    "Client", "PlenoxdError", "TrackStream", "SlamStream", "Rendering", "MeshExport",
    "DEFAULT_MAX_MESSAGE_BYTES", "as_dict", "correct_pose", "estimate_pose", "state_name", "slam_pose",
    "slam_state_name", "convert", "dataset", "trajectory", "pb", "Frame", "Intrinsics", "TumDataset",
]
__version__ = "0.1.0"
