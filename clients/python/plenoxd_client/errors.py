"""What a failed call raises: PlenoxdError; and for a daemon of another API version,
PlenoxdVersionWarning or (Client(version_check="error")) PlenoxdVersionError."""

from __future__ import annotations

from typing import Any, Union

import grpc

__all__ = ["PlenoxdError", "PlenoxdVersionError", "PlenoxdVersionWarning"]


class PlenoxdError(Exception):
    """A call failed. code: grpc.StatusCode (e.g. grpc.StatusCode.NOT_FOUND); message: the
    server's explanation (INVALID_ARGUMENT names the field, e.g. "frame.color: ...");
    method: the RPC."""

    def __init__(self, code: Union[grpc.StatusCode, str], message: str, method: str = ""):
        self.code = code
        self.message = message or ""
        self.method = method
        prefix = f"{method} failed: " if method else ""
        super().__init__(f"{prefix}{self.code_name}: {self.message}")

    @property
    def code_name(self) -> str:
        """The status code's name, e.g. "INVALID_ARGUMENT"."""
        return self.code.name if isinstance(self.code, grpc.StatusCode) else str(self.code)

    @classmethod
    def from_rpc_error(cls, error: Any, method: str) -> PlenoxdError:
        code = error.code() if hasattr(error, "code") else grpc.StatusCode.UNKNOWN
        details = error.details() if hasattr(error, "details") else str(error)
        return cls(code, details, method)


class PlenoxdVersionError(PlenoxdError):
    """The daemon's API version is not this package's (raised with version_check="error").
    client_version, server_version: the two; code FAILED_PRECONDITION."""

    def __init__(self, message: str, client_version: str, server_version: str):
        super().__init__(grpc.StatusCode.FAILED_PRECONDITION, message, "GetServerInfo")
        self.client_version = client_version
        self.server_version = server_version


class PlenoxdVersionWarning(UserWarning):
    """The daemon's API version is not this package's (version_check="warn", the default)."""
