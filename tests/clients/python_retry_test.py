#!/usr/bin/env python3
"""Unit tests of plenoxd_client's retry policy (plenoxd_client.retry) and of the Client's use of
it, with a fake clock and a fake stub: no daemon, no waiting.

    <venv>/bin/python tests/clients/python_retry_test.py

The ctest test python_retry runs it with the venv python_package installed the package into.
tests/clients/python_failover_test.py shows the same against real daemons.
"""

import os
import sys
import unittest

import grpc

import plenoxd_client
from plenoxd_client import Client, PlenoxdError, pb
from plenoxd_client.retry import IDEMPOTENT_METHODS, RetryPolicy, is_retryable


class FakeTime:
    """Time stands still except when the code under test sleeps; every sleep is recorded."""

    def __init__(self):
        self.now = 1000.0
        self.sleeps = []

    def clock(self):
        return self.now

    def sleep(self, seconds):
        self.sleeps.append(seconds)
        self.now += seconds


class FakeRpcError(grpc.RpcError):
    def __init__(self, code, details="fake"):
        super().__init__()
        self._code = code
        self._details = details

    def code(self):
        return self._code

    def details(self):
        return self._details


def policy(time, seconds=30.0, jitter=0.2, rng=None):
    return RetryPolicy(seconds, jitter=jitter, clock=time.clock, sleep=time.sleep,
                       rng=rng or (lambda: 0.5))


class FakeStub:
    """ListMaps, GetMap and CreateMap fail with `failures` (codes) in turn, then answer;
    `calls` records the methods called and `times` when."""

    def __init__(self, time, failures=()):
        self.time = time
        self.failures = list(failures)
        self.calls = []

    def _answer(self, method, reply):
        self.calls.append(method)
        if self.failures:
            raise FakeRpcError(self.failures.pop(0))
        return reply

    def ListMaps(self, request, metadata=(), timeout=None):
        return self._answer("ListMaps", pb.ListMapsResponse(maps=[pb.MapInfo(name="room")]))

    def GetMap(self, request, metadata=(), timeout=None):
        return self._answer("GetMap", pb.MapInfo(name=request.name))

    def CreateMap(self, request, metadata=(), timeout=None):
        return self._answer("CreateMap", pb.MapInfo(name=request.name))


def client_with(stub, time, reached=True, **kwargs):
    # Nothing listens there, and nothing connects: every call goes to the fake stub.
    client = Client("127.0.0.1:1", version_check="off", **kwargs)
    client._stub = stub
    client.retry = policy(time, client.retry.seconds)
    client._reached = reached
    return client


UNAVAILABLE = grpc.StatusCode.UNAVAILABLE


class RetryPolicyTest(unittest.TestCase):
    def test_runs_against_installed_copy(self):
        where = os.path.realpath(plenoxd_client.__file__)
        self.assertNotEqual(sys.prefix, sys.base_prefix, "not run in a venv")
        self.assertTrue(where.startswith(os.path.realpath(sys.prefix) + os.sep), where)

    def test_only_unavailable_of_idempotent_calls_is_retryable(self):
        self.assertTrue(is_retryable(UNAVAILABLE, "ListMaps"))
        for method in ("CreateMap", "DeleteMap", "Integrate", "Slam"):
            self.assertFalse(is_retryable(UNAVAILABLE, method), method)
        for code in (grpc.StatusCode.DEADLINE_EXCEEDED, grpc.StatusCode.RESOURCE_EXHAUSTED,
                     grpc.StatusCode.CANCELLED, grpc.StatusCode.INTERNAL,
                     grpc.StatusCode.UNKNOWN, grpc.StatusCode.NOT_FOUND,
                     grpc.StatusCode.UNAUTHENTICATED):
            self.assertFalse(is_retryable(code, "ListMaps"), code)
        self.assertIn("SaveMap", IDEMPOTENT_METHODS)
        self.assertIn("LoadMap", IDEMPOTENT_METHODS)

    def test_waits_grow_exponentially_within_the_jitter(self):
        time = FakeTime()
        draws = iter([0.0, 1.0 - 1e-12, 0.5, 0.25, 0.0, 1.0 - 1e-12, 0.5, 0.5])
        backoff = policy(time, rng=lambda: next(draws)).backoff()
        nominal = [0.1, 0.2, 0.4, 0.8, 1.6, 2.0, 2.0, 2.0]
        for n in nominal:
            self.assertAlmostEqual(backoff.nominal, n)
            self.assertTrue(backoff.wait())
        factors = [s / n for s, n in zip(time.sleeps, nominal)]
        for f, expected in zip(factors, [0.8, 1.2, 1.0, 0.9, 0.8, 1.2, 1.0, 1.0]):
            self.assertAlmostEqual(f, expected, places=6)

    def test_the_last_wait_ends_at_the_deadline(self):
        time = FakeTime()
        backoff = policy(time, seconds=3.0, jitter=0.0).backoff()
        while backoff.wait():
            pass
        self.assertAlmostEqual(sum(time.sleeps), 3.0)
        self.assertEqual(len(time.sleeps), 5)  # 0.1 0.2 0.4 0.8, then 1.5 of 1.6
        self.assertAlmostEqual(time.sleeps[-1], 1.5)
        self.assertFalse(backoff.wait())
        self.assertEqual(len(time.sleeps), 5, "no sleep once the deadline passed")

    def test_bad_settings_are_refused(self):
        for kwargs in ({"seconds": -1}, {"seconds": float("inf")}, {"seconds": float("nan")},
                       {"multiplier": 0.5}, {"jitter": 1.0}, {"initial_backoff": 0}):
            with self.assertRaises(ValueError, msg=str(kwargs)):
                RetryPolicy(**kwargs)
        with self.assertRaises(ValueError):
            Client("127.0.0.1:1", retry_seconds=-2)


class ClientRetryTest(unittest.TestCase):
    def test_a_read_rides_through_an_outage(self):
        time = FakeTime()
        stub = FakeStub(time, [UNAVAILABLE] * 4)
        client = client_with(stub, time)
        self.assertEqual([m.name for m in client.list_maps()], ["room"])
        self.assertEqual(stub.calls, ["ListMaps"] * 5)
        self.assertEqual(len(time.sleeps), 4)
        self.assertAlmostEqual(sum(time.sleeps), 0.1 + 0.2 + 0.4 + 0.8)

    def test_the_retry_gives_up_at_the_deadline_with_unavailable(self):
        time = FakeTime()
        stub = FakeStub(time, [UNAVAILABLE] * 1000)
        client = client_with(stub, time, retry_seconds=5.0)
        with self.assertRaises(PlenoxdError) as raised:
            client.get_map("room")
        self.assertEqual(raised.exception.code, UNAVAILABLE)
        self.assertAlmostEqual(sum(time.sleeps), 5.0)
        self.assertEqual(len(stub.calls), len(time.sleeps) + 1)

    def test_create_map_is_not_repeated(self):
        time = FakeTime()
        stub = FakeStub(time, [UNAVAILABLE])
        client = client_with(stub, time)
        with self.assertRaises(PlenoxdError) as raised:
            client.create_map("room")
        self.assertEqual(raised.exception.code, UNAVAILABLE)
        self.assertEqual(stub.calls, ["CreateMap"])
        self.assertEqual(time.sleeps, [])

    def test_other_codes_are_not_retried(self):
        time = FakeTime()
        stub = FakeStub(time, [grpc.StatusCode.DEADLINE_EXCEEDED])
        client = client_with(stub, time)
        with self.assertRaises(PlenoxdError) as raised:
            client.list_maps()
        self.assertEqual(raised.exception.code, grpc.StatusCode.DEADLINE_EXCEEDED)
        self.assertEqual(stub.calls, ["ListMaps"])

    def test_a_daemon_never_reached_is_reported_at_once(self):
        time = FakeTime()
        stub = FakeStub(time, [UNAVAILABLE, UNAVAILABLE])
        client = client_with(stub, time, reached=False)
        with self.assertRaises(PlenoxdError):
            client.list_maps()
        self.assertEqual(time.sleeps, [])
        # Once it answered, its going away is waited out.
        client._stub = stub = FakeStub(time)
        client.list_maps()
        stub.failures = [UNAVAILABLE]
        client.list_maps()
        self.assertEqual(stub.calls, ["ListMaps"] * 3)
        self.assertEqual(len(time.sleeps), 1)

    def test_zero_seconds_turns_retries_off(self):
        time = FakeTime()
        stub = FakeStub(time, [UNAVAILABLE])
        client = client_with(stub, time, retry_seconds=0)
        with self.assertRaises(PlenoxdError):
            client.list_maps()
        self.assertEqual(stub.calls, ["ListMaps"])
        self.assertEqual(time.sleeps, [])
        # And slam() streams do not resume then.
        self.assertNotIn("Resuming", type(client.slam("room", [])).__name__)
        self.assertIn("Resuming", type(client_with(stub, time).slam("room", [])).__name__)


if __name__ == "__main__":
    unittest.main(verbosity=2)
