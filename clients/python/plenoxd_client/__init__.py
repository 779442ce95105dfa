"""Python client for plenoxd, the Plenoxel RGB-D mapping, tracking and SLAM daemon.

Installed with pip (clients/python/README.md); its gRPC stubs were generated when the package
was built:

    from plenoxd_client import Client, TumDataset
    with Client("127.0.0.1:50051") as c:
        print(c.health(), c.server_info().version)

__version__ is plenoxd's version, the daemon API version this package speaks (API_VERSION).
"""

from . import convert, dataset, glb, trajectory, types
from ._proto import plenoxd_pb2 as pb
from .client import (DEFAULT_MAX_MESSAGE_BYTES, Client, MeshExport, Rendering, SlamStream,
                     TrackStream, as_dict, correct_pose, estimate_pose, slam_pose,
                     slam_state_name, state_name)
from .dataset import Frame, Intrinsics, TumDataset
from .errors import PlenoxdError, PlenoxdVersionError, PlenoxdVersionWarning
from .version import API_VERSION

__version__ = API_VERSION

__all__ = [
    "Client", "PlenoxdError", "PlenoxdVersionError", "PlenoxdVersionWarning", "TrackStream",
    "SlamStream", "Rendering", "MeshExport", "DEFAULT_MAX_MESSAGE_BYTES", "API_VERSION",
    "as_dict", "correct_pose", "estimate_pose", "state_name", "slam_pose", "slam_state_name",
    "convert", "dataset", "glb", "trajectory", "types", "pb", "Frame", "Intrinsics", "TumDataset",
]
