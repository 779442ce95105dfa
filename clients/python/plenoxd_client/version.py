"""The daemon API version this package was built for, and the check of a daemon's against it.

API_VERSION is plenoxd's version (`project(plenoxd VERSION ...)` in CMakeLists.txt), written
into the package when it is built; the daemon reports the same number in ServerInfo.version.
Client checks it once, before its first call to the daemon's API: a daemon of another version
may lack calls or fields this client uses (or send ones it does not know), so the difference is
said up front instead of surfacing later as an odd error.
"""

from __future__ import annotations

import os
import sys
import warnings
from types import FrameType
from typing import Optional

from ._proto import API_VERSION
from .errors import PlenoxdVersionError, PlenoxdVersionWarning

__all__ = ["API_VERSION", "VERSION_CHECKS", "version_mismatch", "check_server_version"]

# What a Client does when the versions differ: warn (PlenoxdVersionWarning), raise
# (PlenoxdVersionError, on every call), or nothing.
VERSION_CHECKS = ("warn", "error", "off")


def version_mismatch(server_version: str, target: str = "the daemon") -> Optional[str]:
    """None when server_version is API_VERSION; otherwise a message naming both versions."""
    if server_version == API_VERSION:
        return None
    reported = f"API version {server_version}" if server_version else "no API version"
    wheel = f"plenoxd_client-{server_version or '<version>'}-py3-none-any.whl"
    return (f"plenoxd at {target} reports {reported}, but this plenoxd_client is API version "
            f"{API_VERSION}: calls and fields may not match. Install the client of that daemon's "
            f"build (its clients/python/dist/{wheel}), or pass version_check=\"off\" to "
            "Client to accept the difference.")


def check_server_version(server_version: str, target: str, policy: str = "warn") -> bool:
    """Applies `policy` (one of VERSION_CHECKS) to a daemon's ServerInfo.version: True when
    it matches; otherwise warns and returns False ("warn"), raises PlenoxdVersionError
    ("error"), or returns False ("off")."""
    if policy not in VERSION_CHECKS:
        raise ValueError(f"version_check: expected one of {VERSION_CHECKS}, got {policy!r}")
    message = version_mismatch(server_version, target)
    if message is None:
        return True
    if policy == "error":
        raise PlenoxdVersionError(message, API_VERSION, server_version)
    if policy == "warn":
        warnings.warn(PlenoxdVersionWarning(message), stacklevel=_caller_stacklevel())
    return False


def _caller_stacklevel() -> int:
    """The warnings stacklevel of the first frame outside this package: the warning then
    names the caller's line, however deep in the client the check ran."""
    package_dir = os.path.dirname(os.path.abspath(__file__)) + os.sep
    frame: Optional[FrameType] = sys._getframe(1)
    level = 1  # the function that calls warnings.warn
    while frame is not None and os.path.abspath(frame.f_code.co_filename).startswith(package_dir):
        frame, level = frame.f_back, level + 1
    return level
