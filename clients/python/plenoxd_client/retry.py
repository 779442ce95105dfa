"""Riding through a failover (a daemon killed or restarted, a map moved to another replica):
when and how long a Client waits before it calls a daemon again, and which calls it repeats.
The same policy as the C++ CLI's (app/retry_policy.h, plenox --retry-seconds).

    Client(target, retry_seconds=30.0)     # the default; 0 turns retries off

- Exponential backoff with jitter under an overall deadline: waits of 0.1, 0.2, 0.4, ... s up to
  2 s, each times a factor drawn from [0.8, 1.2] (the clients of a daemon that died all lost
  it at the same moment; without jitter they would come back to its replacement together), for
  at most `retry_seconds` from the first failure of an outage; the last wait ends at the
  deadline and the last attempt is made there.
- Only UNAVAILABLE is retried: the daemon was not there (connection refused or lost, a daemon
  draining on SIGTERM: "retry on another instance"), so another attempt can find its
  replacement. DEADLINE_EXCEEDED is not (the call may still run on the daemon, its time is
  spent), nor RESOURCE_EXHAUSTED (a limit refuses the same call again), CANCELLED, INTERNAL /
  UNKNOWN (a bug a retry would hide) or the caller's own errors.
- Only calls that are safe to repeat (IDEMPOTENT_METHODS): reads, SaveMap (the same file written
  again) and LoadMap (read again). CreateMap and DeleteMap are not: done before the connection
  was lost, they would fail on their own success (ALREADY_EXISTS, NOT_FOUND). Streams that
  carry frames into a map (Integrate) are not repeated; a Slam stream reconnects instead
  (Client.slam(..., resume=True), plenoxd_client.failover).
- Only once the client has had an answer from the daemon: a target never reached is a wrong
  address or a daemon not started yet, reported at once (Client.wait_ready waits for one).
"""

from __future__ import annotations

import random
import time
from typing import Any, Callable, Optional, TypeVar

import grpc

__all__ = ["RetryPolicy", "Backoff", "IDEMPOTENT_METHODS", "is_retryable"]

_T = TypeVar("_T")

# The unary calls a Client repeats after UNAVAILABLE (Health.Check: the health service's).
IDEMPOTENT_METHODS = frozenset({"GetMap", "ListMaps", "GetServerInfo", "SaveMap", "LoadMap",
                                "Render", "Health.Check"})


def is_retryable(code: Any, method: str) -> bool:
    """Whether a call of `method` that failed with `code` (a grpc.StatusCode) may be made
    again: UNAVAILABLE of a call that is safe to repeat."""
    return code == grpc.StatusCode.UNAVAILABLE and method in IDEMPOTENT_METHODS


class RetryPolicy:
    """The waits of a Client. seconds: the overall deadline of one outage (0: no retries);
    initial_backoff, multiplier, max_backoff (seconds): the waits' growth; jitter: each wait
    times a factor from [1 - jitter, 1 + jitter]. clock, sleep, rng: time.monotonic, time.sleep
    and random.random, replaced by tests."""

    def __init__(self, seconds: float = 30.0, initial_backoff: float = 0.1,
                 multiplier: float = 2.0, max_backoff: float = 2.0, jitter: float = 0.2,
                 clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep,
                 rng: Callable[[], float] = random.random):
        seconds = float(seconds)
        if not seconds >= 0.0 or seconds == float("inf"):
            raise ValueError(f"retry_seconds: expected a finite number >= 0, got {seconds!r}")
        if not (initial_backoff > 0 and multiplier >= 1 and max_backoff >= initial_backoff
                and 0 <= jitter < 1):
            raise ValueError("the backoff must grow from a positive first wait to a larger "
                             "last one, with jitter in [0, 1)")
        self.seconds = seconds
        self.initial_backoff = float(initial_backoff)
        self.multiplier = float(multiplier)
        self.max_backoff = float(max_backoff)
        self.jitter = float(jitter)
        self.clock = clock
        self.sleep = sleep
        self.rng = rng

    def backoff(self) -> Backoff:
        """The waits of an outage that begins now."""
        return Backoff(self)

    def call(self, fn: Callable[[], _T], method: str,
             on_wait: Optional[Callable[[grpc.RpcError, int], None]] = None) -> _T:
        """fn() until it returns, raises something is_retryable refuses, or the deadline
        passed; re-raises the last grpc.RpcError then. on_wait(error, attempt) before each
        wait."""
        try:
            return fn()
        except grpc.RpcError as e:
            if not is_retryable(_code(e), method) or self.seconds <= 0:
                raise
            error = e
        backoff = self.backoff()
        attempt = 1
        while True:
            if backoff.spent():
                raise error
            if on_wait is not None:
                on_wait(error, attempt)
            backoff.wait()
            attempt += 1
            try:
                return fn()
            except grpc.RpcError as e:
                if not is_retryable(_code(e), method):
                    raise
                error = e


class Backoff:
    """The waits of one outage, from its first failure: wait() sleeps before the next attempt
    and returns False (without sleeping) once the deadline passed."""

    def __init__(self, policy: RetryPolicy):
        self._policy = policy
        self.started = policy.clock()
        self.deadline = self.started + policy.seconds
        self.nominal = policy.initial_backoff
        self.waits = 0

    def spent(self) -> bool:
        return self._policy.clock() >= self.deadline

    def elapsed(self) -> float:
        return self._policy.clock() - self.started

    def wait(self) -> bool:
        p = self._policy
        now = p.clock()
        if now >= self.deadline:
            return False
        factor = 1.0 - p.jitter + 2.0 * p.jitter * p.rng()
        delay = min(self.nominal * factor, self.deadline - now)
        self.nominal = min(self.nominal * p.multiplier, p.max_backoff)
        self.waits += 1
        p.sleep(delay)
        return True


def _code(error: Any) -> Any:
    return error.code() if hasattr(error, "code") else grpc.StatusCode.UNKNOWN
