"""A Slam stream that rides through a failover: Client.slam(..., resume=True), the default while
the Client's retry_seconds > 0 (retry.py).

When the daemon goes away mid-stream (killed, restarted, failed over to another replica: the
call ends with UNAVAILABLE), the stream waits for a daemon at the same address under the
Client's retry policy, then opens a new Slam call into the same map with the frames that are
left. The new call gives no start pose of its own but the last pose tracked in the map as the
hint: in a map reloaded from its snapshot the camera relocalises against the saved keyframes
(their features first) and its poses go on in the map's frame; a map that was never saved
starts again from that pose.

Frames: those taken from `frames` and never answered (the one in flight in lock-step; those
queued for sending when streaming) are lost, not sent again (a camera's frame from before the
outage is stale by then); `frames` is not read while disconnected, so a live source should hand
out its newest frame when next asked. The stream counts `reconnects`, `frames_lost` and
`resume_seconds` (the longest time from a call breaking to the first frame tracked on its
replacement). A stream cut after every frame was taken raises the UNAVAILABLE error: there is
nothing left to reconnect for, and every update that came was yielded.
"""

from __future__ import annotations

import itertools
import time
from typing import Any, Iterator, Optional

import grpc

from . import convert
from ._proto import plenoxd_pb2 as pb
from .client import SlamStream
from .errors import PlenoxdError
from .types import PoseLike

__all__ = ["ResumingSlamStream"]

_TRACKED = (pb.SLAM_STATE_OK, pb.SLAM_STATE_DEGRADED, pb.SLAM_STATE_RELOCALISED)


class ResumingSlamStream(SlamStream):
    """A SlamStream whose call is replaced when a failover cuts it (see the module). Its
    counters sum every call's; `reconnects`, `frames_lost`, `resume_seconds` (None before a
    reconnect tracked a frame) say what the failovers cost."""

    def __init__(self, *args: Any):
        super().__init__(*args)
        self.reconnects = 0
        self.frames_lost = 0
        self.resume_seconds: Optional[float] = None
        self._part: Optional[SlamStream] = None

    def cancel(self) -> None:
        self._stop.set()
        part = self._part
        if part is not None:
            part.cancel()

    def __iter__(self) -> Iterator[pb.SlamUpdate]:
        if self._started:
            raise RuntimeError(f"a {type(self).__name__} can be iterated once")
        self._started = True
        return self._run()

    def _run(self) -> Iterator[pb.SlamUpdate]:
        frames = iter(self._frames)
        start: Optional[PoseLike] = self._initial_pose
        last_in_map: Optional[PoseLike] = None
        broke_at: Optional[float] = None
        sent_before = 0
        while True:
            part = SlamStream(self._client, self._map, frames, start, self._lockstep,
                              self._options, self._priors, self._fps)
            self._part = part
            answered = dropped = 0
            try:
                for update in part:
                    self._client._reached = True
                    self._accept(update)
                    answered += 1
                    dropped += update.dropped
                    self.sent = sent_before + part.sent
                    if update.state in _TRACKED:
                        if update.segment == 0:
                            last_in_map = convert.pose_from_proto(update.pose)
                        if broke_at is not None:
                            waited = time.monotonic() - broke_at
                            self.resume_seconds = max(self.resume_seconds or 0.0, waited)
                            broke_at = None
                    yield update
                    if self._stop.is_set():
                        part.cancel()
                        return
            except PlenoxdError as e:
                self.sent = sent_before + part.sent
                if (e.code != grpc.StatusCode.UNAVAILABLE or self._stop.is_set()
                        or self.retry_seconds <= 0 or not self._client._reached):
                    raise
                error = e
            else:
                self.sent = sent_before + part.sent
                self.mapping = part.mapping if part.mapping is not None else self.mapping
                self.done = part.done
                return
            # Taken from `frames` and neither answered nor reported dropped: lost.
            self.frames_lost += max(0, part.sent - answered - dropped)
            sent_before = self.sent
            if broke_at is None:
                broke_at = time.monotonic()
            self._await_daemon(error)
            try:
                head = next(frames)  # taken now, once a daemon is back: a live source's newest
            except StopIteration:
                raise error from None  # every frame was sent: nothing to reconnect for
            frames = itertools.chain([head], frames)
            self.reconnects += 1
            start = last_in_map

    @property
    def retry_seconds(self) -> float:
        return self._client.retry.seconds

    def _await_daemon(self, error: PlenoxdError) -> None:
        """Waits under the retry policy until a daemon answers GetMap for the map (with it, or
        NOT_FOUND: the new call then starts it again); raises `error` when none does."""
        backoff = self._client.retry.backoff()
        while True:
            if self._stop.is_set() or not backoff.wait():
                raise PlenoxdError(error.code, f"{error.message}; no daemon answered within "
                                   f"{backoff.elapsed():.1f} s (retry_seconds "
                                   f"{self.retry_seconds:g})", error.method)
            try:
                self._client._stub.GetMap(pb.GetMapRequest(name=self._map),
                                          metadata=self._client.metadata_for(self._map),
                                          timeout=5.0)
                return
            except grpc.RpcError as e:
                if e.code() == grpc.StatusCode.NOT_FOUND:
                    return
                if e.code() != grpc.StatusCode.UNAVAILABLE:
                    raise PlenoxdError.from_rpc_error(e, "GetMap") from None
