"""The generated gRPC modules, imported in one place.

They exist only in a built package (clients/python/setup.py writes plenoxd_client/_generated/
while building it), so importing plenoxd_client from its source folder ends here with an error
that says how to install it.
"""

import os

try:
    from ._generated import API_VERSION, plenoxd_pb2, plenoxd_pb2_grpc
except ModuleNotFoundError as _missing:
    if _missing.name is None or not _missing.name.startswith(__package__ + "._generated"):
        raise  # e.g. no grpc: pip names the dependencies, this is not about the stubs
    raise ImportError(
        f"{os.path.dirname(os.path.abspath(__file__))} has no generated gRPC stubs: it is "
        "plenoxd_client's source folder, not an installed copy. Install the package (in a venv "
        "made with `/usr/bin/python3 -m venv --system-site-packages`: `python -m pip install "
        "--no-index --no-build-isolation <repo>/clients/python`) and run Python from outside "
        "clients/python, whose plenoxd_client folder would hide the installed one.") from None

try:
    # grpcio-health-checking's modules when installed: a second copy of grpc.health.v1 in the
    # same process would be refused by protobuf's descriptor pool (duplicate symbols).
    from grpc_health.v1 import health_pb2, health_pb2_grpc
except ImportError:
    from ._generated import health_pb2, health_pb2_grpc

__all__ = ["API_VERSION", "plenoxd_pb2", "plenoxd_pb2_grpc", "health_pb2", "health_pb2_grpc"]
