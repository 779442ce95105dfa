#!/usr/bin/env python3
"""Unit tests of plenoxd_client's API version check, against a fake stub: no daemon.

    <venv>/bin/python tests/clients/python_version_check_test.py

The ctest test python_version_check runs it with the venv python_package installed the
package into (the copy it must test, which test_runs_against_installed_copy checks).
"""

import os
import sys
import unittest
import warnings

import grpc

import plenoxd_client
from plenoxd_client import (API_VERSION, Client, PlenoxdError, PlenoxdVersionError,
                            PlenoxdVersionWarning, pb)
from plenoxd_client.version import version_mismatch

OTHER = "9.8.7"  # a version no build of this project has


class FakeRpcError(grpc.RpcError):
    def __init__(self, code):
        super().__init__()
        self._code = code

    def code(self):
        return self._code

    def details(self):
        return "fake"


class FakeCall:
    """A finished streaming call that yields `replies`."""

    def __init__(self, replies):
        self._replies = iter(replies)

    def __iter__(self):
        return self._replies

    def running(self):
        return False

    def cancel(self):
        pass


class FakeStub:
    """Answers GetServerInfo with `versions` in turn (an exception instance is raised), and
    ListMaps, GetMap and Track with empty replies; `calls` records the methods called."""

    def __init__(self, *versions):
        self.versions = list(versions)
        self.calls = []

    def GetServerInfo(self, request, metadata=(), timeout=None):
        self.calls.append("GetServerInfo")
        version = self.versions.pop(0) if len(self.versions) > 1 else self.versions[0]
        if isinstance(version, Exception):
            raise version
        return pb.ServerInfo(version=version, backend="cpu")

    def ListMaps(self, request, metadata=(), timeout=None):
        self.calls.append("ListMaps")
        return pb.ListMapsResponse()

    def GetMap(self, request, metadata=(), timeout=None):
        self.calls.append("GetMap")
        return pb.MapInfo(name=request.name)

    def Track(self, requests, metadata=()):
        self.calls.append("Track")
        return FakeCall([])


def client_with(stub, **kwargs):
    # Nothing listens there, and nothing connects: every call goes to the fake stub.
    client = Client("127.0.0.1:1", **kwargs)
    client._stub = stub
    return client


class VersionCheckTest(unittest.TestCase):
    def setUp(self):
        self.caught = warnings.catch_warnings(record=True)
        self.warnings = self.caught.__enter__()
        warnings.simplefilter("always")

    def tearDown(self):
        self.caught.__exit__(None, None, None)

    def version_warnings(self):
        return [w for w in self.warnings if issubclass(w.category, PlenoxdVersionWarning)]

    def test_runs_against_installed_copy(self):
        where = os.path.realpath(plenoxd_client.__file__)
        self.assertNotEqual(sys.prefix, sys.base_prefix, "not run in a venv")
        self.assertTrue(where.startswith(os.path.realpath(sys.prefix) + os.sep), where)

    def test_message_names_both_versions(self):
        self.assertIsNone(version_mismatch(API_VERSION, "h:1"))
        message = version_mismatch(OTHER, "h:1")
        for part in ("plenoxd at h:1", f"API version {OTHER}", f"is API version {API_VERSION}",
                     f"plenoxd_client-{OTHER}-py3-none-any.whl", 'version_check="off"'):
            self.assertIn(part, message)
        self.assertIn("no API version", version_mismatch("", "h:1"))

    def test_warns_once_before_the_first_call(self):
        stub = FakeStub(OTHER)
        client = client_with(stub)
        client.list_maps()
        client.get_map("room")
        self.assertEqual(stub.calls, ["GetServerInfo", "ListMaps", "GetMap"])
        (warning,) = self.version_warnings()
        self.assertIn(OTHER, str(warning.message))
        self.assertIn(API_VERSION, str(warning.message))
        # Reported at the caller's line, not somewhere inside the client.
        self.assertEqual(os.path.realpath(warning.filename), os.path.realpath(__file__))
        self.assertEqual(client.server_version, OTHER)

    def test_a_stream_is_checked_too(self):
        stub = FakeStub(OTHER)
        client = client_with(stub)
        self.assertEqual(list(client.track("room", [pb.Frame()])), [])
        self.assertEqual(stub.calls, ["GetServerInfo", "Track"])
        (warning,) = self.version_warnings()
        self.assertEqual(os.path.realpath(warning.filename), os.path.realpath(__file__))

    def test_error_refuses_every_call_but_server_info(self):
        stub = FakeStub(OTHER)
        client = client_with(stub, version_check="error")
        for _ in range(2):
            with self.assertRaises(PlenoxdVersionError) as raised:
                client.list_maps()
            error = raised.exception
            self.assertIsInstance(error, PlenoxdError)
            self.assertEqual(error.code_name, "FAILED_PRECONDITION")
            self.assertEqual((error.client_version, error.server_version), (API_VERSION, OTHER))
            self.assertIn(OTHER, str(error))
        self.assertEqual(client.server_info().version, OTHER)
        self.assertEqual(stub.calls, ["GetServerInfo", "GetServerInfo"])
        self.assertEqual(self.version_warnings(), [])

    def test_matching_version_is_silent(self):
        stub = FakeStub(API_VERSION)
        client = client_with(stub, version_check="error")
        client.list_maps()
        self.assertEqual(stub.calls, ["GetServerInfo", "ListMaps"])
        self.assertEqual(self.version_warnings(), [])

    def test_off_never_asks(self):
        stub = FakeStub(OTHER)
        client_with(stub, version_check="off").list_maps()
        self.assertEqual(stub.calls, ["ListMaps"])
        self.assertEqual(self.version_warnings(), [])

    def test_a_daemon_that_cannot_be_asked_is_asked_again(self):
        stub = FakeStub(FakeRpcError(grpc.StatusCode.UNAUTHENTICATED), OTHER)
        client = client_with(stub)
        client.list_maps()  # the call itself goes on: it reports its own failure, if any
        self.assertEqual(self.version_warnings(), [])
        client.list_maps()
        self.assertEqual(stub.calls, ["GetServerInfo", "ListMaps"] * 2)
        self.assertEqual(len(self.version_warnings()), 1)

    def test_check_version_raises_whatever_the_policy(self):
        with self.assertRaises(PlenoxdVersionError):
            client_with(FakeStub(OTHER), version_check="off").check_version()
        self.assertEqual(client_with(FakeStub(API_VERSION)).check_version(), API_VERSION)

    def test_an_unknown_policy_is_refused(self):
        with self.assertRaises(ValueError):
            Client("127.0.0.1:1", version_check="strict")


if __name__ == "__main__":
    unittest.main(verbosity=2)
