"""A synchronous client for the plenoxd.v1 gRPC API (proto/plenoxd/v1/plenoxd.proto).

    from plenoxd_client import Client
    with Client("127.0.0.1:50051", token="...") as c:
        c.create_map("room", voxel_size=0.04)
        for progress in c.integrate("room", keyframes):    # posed keyframes
            print(progress.keyframes_integrated, progress.done)
        for estimate in c.track("room", frames, initial_pose=first_pose):
            print(estimate.state, estimate.pose)
        for update in c.slam("hall", unposed_frames, initial_pose=first_pose):   # online SLAM
            print(slam_state_name(update), slam_pose(update), update.keyframe)
        color, depth = c.render("room", pose, intrinsics)

Every failed call raises PlenoxdError with the gRPC status code and the server's message. Before
its first call to the daemon's API a Client compares the daemon's version with this package's
(version.py): a difference warns (PlenoxdVersionWarning), or raises PlenoxdVersionError with
Client(..., version_check="error").
"""

from __future__ import annotations

import os
import queue
import threading
from typing import (Any, Callable, Dict, Generic, Iterable, Iterator, List, Literal, Mapping,
                    NamedTuple, Optional, Sequence, Tuple, TypeVar, Union, overload)

import grpc
import numpy as np

from . import convert
from ._proto import health_pb2, health_pb2_grpc
from ._proto import plenoxd_pb2 as pb
from ._proto import plenoxd_pb2_grpc as pb_grpc
from .errors import PlenoxdError, PlenoxdVersionError
from .retry import RetryPolicy
from .glb import read_glb_info
from .types import FrameLike, IntrinsicsLike, Pose, PoseLike
from .version import API_VERSION, VERSION_CHECKS, check_server_version, version_mismatch

__all__ = ["Client", "PlenoxdError", "TrackStream", "SlamStream", "Rendering", "MeshExport",
           "DEFAULT_MAX_MESSAGE_BYTES", "estimate_pose", "state_name", "slam_pose",
           "slam_state_name", "correct_pose", "as_dict"]

DEFAULT_MAX_MESSAGE_BYTES = 64 << 20
_END = object()
_Reply = TypeVar("_Reply")

TrackOptionsLike = Union[pb.TrackOptions, Mapping[str, Any]]
SlamOptionsLike = Union[pb.SlamOptions, Mapping[str, Any]]
IntegrateOptionsLike = Union[pb.IntegrateOptions, Mapping[str, Any]]


class MeshExport(NamedTuple):
    """What Client.export_mesh wrote: vertex and face counts, file size; for a level of detail
    the full mesh's faces and the simplification's error in metres (a GLB says them; for a PLY
    full_faces is faces)."""
    vertices: int
    faces: int
    bytes: int
    full_faces: int = 0
    lod_error_m: float = 0.0


class Rendering(NamedTuple):
    """color: HxWx3 uint8 RGB; depth: HxW float32 z-depth in metres (0 = nothing rendered);
    coverage: fraction of pixels the map renders; map_version: the version rendered."""
    color: np.ndarray
    depth: np.ndarray
    coverage: float
    map_version: int


def _drain(outbox: queue.Queue) -> Iterator[Any]:
    """Items of a queue until the _END marker (compared by identity, not ==)."""
    while True:
        item = outbox.get()
        if item is _END:
            return
        yield item


class _RequestFeed:
    """The request iterator of a streaming call. It records an exception raised while making a
    request (gRPC would otherwise only cancel the call), so the caller can re-raise it."""

    def __init__(self, requests: Iterable[Any]):
        self._requests = requests
        self.error: Optional[Exception] = None

    def __iter__(self) -> Iterator[Any]:
        try:
            for r in self._requests:
                yield r
        except Exception as e:  # noqa: BLE001 -- handed to the caller's thread
            self.error = e
            raise


class _FrameStream(Generic[_Reply]):
    """One bidirectional frames-in call (Track, Slam) as an iterator of its per-frame replies,
    in lock-step or streamed from a sender thread. Subclasses name the call, its request
    message and options conversion, and count the replies; `sent` and `received` count frames
    and per-frame replies."""

    _method = ""
    _request_type: Callable[..., Any]  # the request message: map, options, frame, initial_pose

    @staticmethod
    def _options_to_proto(options: Any) -> Any:
        """options (a message or a dict) as the request's options message."""
        raise NotImplementedError

    def __init__(self, client: Client, map_name: str, frames: Iterable[FrameLike],
                 initial_pose: Optional[PoseLike], lockstep: bool, options: Any, priors: bool,
                 fps: Optional[float]):
        self.sent = 0
        self.received = 0
        self._client = client
        self._map = map_name
        self._frames = frames
        self._initial_pose = initial_pose
        self._lockstep = lockstep
        self._options = options
        self._priors = priors
        self._fps = fps
        self._call: Any = None
        self._stop = threading.Event()
        self._started = False

    def cancel(self) -> None:
        """Ends the call early; the iteration then stops."""
        self._stop.set()
        if self._call is not None:
            self._call.cancel()

    def _request(self, frame: FrameLike, first: bool) -> Any:
        request = self._request_type(frame=convert.frame_to_proto(frame, with_pose=self._priors))
        if first:
            request.map = self._map
            if self._options is not None:
                request.options.CopyFrom(self._options_to_proto(self._options))
            if self._initial_pose is not None:
                convert.pose_to_proto(self._initial_pose, request.initial_pose)
        return request

    def _accept(self, reply: Any) -> bool:
        """Counts a reply; True when it is a frame's (and is yielded)."""
        raise NotImplementedError

    def _ended(self) -> None:
        """Called when the server ended the call without an error."""

    def _open(self, feed: _RequestFeed) -> Any:
        self._client._check_version()
        self._call = getattr(self._client._stub, self._method)(
            iter(feed), metadata=self._client.metadata_for(self._map))
        return self._call

    def __iter__(self) -> Iterator[_Reply]:
        if self._started:
            raise RuntimeError(f"a {type(self).__name__} can be iterated once")
        self._started = True
        if self._lockstep:
            return self._run_lockstep()
        return self._run_streaming()

    def _run_lockstep(self) -> Iterator[_Reply]:
        # One frame out, its reply back, then the next frame. The feed blocks on a queue the
        # response loop fills, so the server never has more than one frame waiting.
        outbox: queue.Queue = queue.Queue()
        frames = iter(self._frames)
        feed = _RequestFeed(_drain(outbox))

        def send_next(first: bool) -> bool:
            try:
                frame = next(frames)
            except StopIteration:
                outbox.put(_END)  # half-close: the server ends the stream
                return False
            outbox.put(self._request(frame, first))
            self.sent += 1
            return True

        try:
            if not send_next(True):
                return
            for reply in self._open(feed):
                if not self._accept(reply):
                    continue
                yield reply
                if self._stop.is_set():
                    break
                if self.received >= self.sent:
                    send_next(False)
            else:
                self._ended()
        except grpc.RpcError as e:
            if feed.error is not None:
                raise feed.error from None
            if self._stop.is_set() and e.code() == grpc.StatusCode.CANCELLED:
                return
            raise PlenoxdError.from_rpc_error(e, self._method) from None
        finally:
            outbox.put(_END)
            if self._call is not None and self._call.running():
                self._call.cancel()

    def _run_streaming(self) -> Iterator[_Reply]:
        # A sender thread pushes frames as they come (paced to fps when given) into a queue that
        # gRPC drains as fast as the network takes them; how the server treats frames that wait
        # is the call's (Track, realtime Slam: latest wins; Slam: backpressure).
        outbox: queue.Queue = queue.Queue()
        feed = _RequestFeed(_drain(outbox))
        period = 1.0 / self._fps if self._fps else 0.0
        sender_error: List[Exception] = []

        def sender() -> None:
            try:
                first = True
                for frame in self._frames:
                    if self._stop.is_set():
                        break
                    outbox.put(self._request(frame, first))
                    first = False
                    self.sent += 1
                    if period:
                        self._stop.wait(period)
            except Exception as e:  # noqa: BLE001 -- re-raised in the caller's thread
                sender_error.append(e)
                self._stop.set()
                if self._call is not None:
                    self._call.cancel()
            finally:
                outbox.put(_END)

        thread = threading.Thread(target=sender, name=f"plenoxd-{self._method.lower()}-sender",
                                  daemon=True)
        try:
            call = self._open(feed)
            thread.start()
            for reply in call:
                if not self._accept(reply):
                    continue
                yield reply
                if self._stop.is_set():
                    break
            else:
                if not sender_error:
                    self._ended()
        except grpc.RpcError as e:
            if sender_error:
                raise sender_error[0] from None
            if self._stop.is_set() and e.code() == grpc.StatusCode.CANCELLED:
                return
            raise PlenoxdError.from_rpc_error(e, self._method) from None
        finally:
            self._stop.set()
            if self._call is not None and self._call.running():
                self._call.cancel()
            if thread.is_alive():
                thread.join(timeout=5.0)
        if sender_error:
            raise sender_error[0]


class TrackStream(_FrameStream[pb.PoseEstimate]):
    """The estimates of one Track call, as an iterator of plenoxd.v1.PoseEstimate.

    Counters while and after iterating: sent (frames sent), received (estimates), dropped
    (frames the server skipped because newer ones arrived, the sum of PoseEstimate.dropped),
    lost / degraded (estimates in those states). cancel() ends the call early."""

    _method = "Track"
    _request_type = pb.TrackRequest

    def __init__(self, *args: Any):
        super().__init__(*args)
        self.dropped = 0
        self.lost = 0
        self.degraded = 0

    @staticmethod
    def _options_to_proto(options: Any) -> pb.TrackOptions:
        return _track_options(options)

    def _accept(self, estimate: pb.PoseEstimate) -> bool:
        self.received += 1
        self.dropped += estimate.dropped
        if estimate.state == pb.TRACKING_STATE_LOST:
            self.lost += 1
        elif estimate.state == pb.TRACKING_STATE_DEGRADED:
            self.degraded += 1
        return True


class SlamStream(_FrameStream[pb.SlamUpdate]):
    """The updates of one Slam call, as an iterator of plenoxd.v1.SlamUpdate, one per frame the
    server processed. The call's last message (done=True, no frame) is not yielded: it is kept
    as `done`, and the iteration ends only once it came, which for the last stream on a map is
    after the mapping job finished (done.mapping.finished), so a save_map() then saves every
    keyframe. A call the server ends without it raises PlenoxdError(INTERNAL).

    Counters while and after iterating: sent (frames sent), received (updates), dropped (frames
    the server skipped with options realtime=True, the sum of SlamUpdate.dropped), keyframes
    (frames handed to the mapping job), lost / degraded / relocalised / waiting (updates in
    those states; WAITING: the map has no keyframe yet and the frame had too little depth to
    start it); mapping: the SlamMapping of the latest message (its loops_accepted,
    loops_rejected, corrections and last_solve_ms: the map's loop closure); corrections: every
    SlamCorrection the stream carried, in order, those of the done message (corrections the map
    made after the last frame, as its mapping finished) last (a loop closure moved the map's
    keyframes: move what you hold in the old frame with correct_pose()). cancel() ends the call
    early."""

    _method = "Slam"
    _request_type = pb.SlamRequest

    def __init__(self, *args: Any):
        super().__init__(*args)
        self.dropped = 0
        self.keyframes = 0
        self.lost = 0
        self.degraded = 0
        self.relocalised = 0
        self.waiting = 0
        self.mapping: Optional[pb.SlamMapping] = None
        self.done: Optional[pb.SlamUpdate] = None
        self.corrections: List[pb.SlamCorrection] = []

    @staticmethod
    def _options_to_proto(options: Any) -> pb.SlamOptions:
        return _slam_options(options)

    def _accept(self, update: pb.SlamUpdate) -> bool:
        self.mapping = update.mapping
        if update.done:
            self.done = update
            self.corrections.extend(update.corrections_after)
            return False
        self.received += 1
        self.dropped += update.dropped
        self.keyframes += int(update.keyframe)
        if update.HasField("correction"):
            self.corrections.append(update.correction)
        if update.state == pb.SLAM_STATE_LOST:
            self.lost += 1
        elif update.state == pb.SLAM_STATE_DEGRADED:
            self.degraded += 1
        elif update.state == pb.SLAM_STATE_RELOCALISED:
            self.relocalised += 1
        elif update.state == pb.SLAM_STATE_WAITING:
            self.waiting += 1
        return True

    def _ended(self) -> None:
        if self.done is None:
            raise PlenoxdError(grpc.StatusCode.INTERNAL,
                               "the server ended the stream without its done message", "Slam")


def _track_options(options: TrackOptionsLike) -> pb.TrackOptions:
    if isinstance(options, pb.TrackOptions):
        return options
    o = pb.TrackOptions()
    mode = options.get("mode")
    if isinstance(mode, str):
        o.mode = {"gauss_newton": pb.TrackOptions.MODE_GAUSS_NEWTON,
                  "gn": pb.TrackOptions.MODE_GAUSS_NEWTON,
                  "adam": pb.TrackOptions.MODE_ADAM}[mode.lower()]
    elif mode is not None:
        o.mode = int(mode)
    o.rays = int(options.get("rays", 0))
    o.iterations = int(options.get("iterations", 0))
    pixels = options.get("pixels")
    if isinstance(pixels, str):
        o.pixels = {"informative": pb.TrackOptions.PIXELS_INFORMATIVE,
                    "uniform": pb.TrackOptions.PIXELS_UNIFORM}[pixels.lower()]
    elif pixels is not None:
        o.pixels = int(pixels)
    return o


# SlamOptions' fields by type: a dict may give any of them, nothing else (a misspelt key is an
# error, not an option silently left at its default).
_SLAM_FLOAT_OPTIONS = ("voxel_size", "kf_translation_m", "kf_rotation_deg", "kf_unmapped_fraction",
                       "kf_interval_s", "max_depth")
_SLAM_INT_OPTIONS = ("iterations_per_keyframe", "rays_per_iteration")
_SLAM_BOOL_OPTIONS = ("realtime", "deterministic")


def _slam_options(options: SlamOptionsLike) -> pb.SlamOptions:
    """SlamOptions from a SlamOptions or a dict of its fields (0 / absent = the server's
    default); "tracking" is a TrackOptions or a dict as track() takes (mode, rays,
    iterations)."""
    if isinstance(options, pb.SlamOptions):
        return options
    known = set(_SLAM_FLOAT_OPTIONS + _SLAM_INT_OPTIONS + _SLAM_BOOL_OPTIONS +
                ("tracking", "max_pending_keyframes", "loop_closure"))
    unknown = sorted(set(options) - known)
    if unknown:
        raise ValueError(f"unknown SlamOptions field(s) {unknown}; known: {sorted(known)}")
    o = pb.SlamOptions()
    for name in _SLAM_FLOAT_OPTIONS:
        setattr(o, name, float(options.get(name, 0.0)))
    for name in _SLAM_INT_OPTIONS:
        setattr(o, name, int(options.get(name, 0)))
    for name in _SLAM_BOOL_OPTIONS:
        setattr(o, name, bool(options.get(name, False)))
    if options.get("tracking") is not None:
        o.tracking.CopyFrom(_track_options(options["tracking"]))
    if options.get("max_pending_keyframes") is not None:  # 0 is a value here, not "default"
        o.max_pending_keyframes = int(options["max_pending_keyframes"])
    if options.get("loop_closure") is not None:  # False is a value here, not "default"
        o.loop_closure = bool(options["loop_closure"])
    return o


def _integrate_options(options: IntegrateOptionsLike) -> pb.IntegrateOptions:
    if isinstance(options, pb.IntegrateOptions):
        return options
    return pb.IntegrateOptions(
        iterations_per_keyframe=int(options.get("iterations_per_keyframe", 0)),
        rays_per_iteration=int(options.get("rays_per_iteration", 0)),
        max_depth=float(options.get("max_depth", 0.0)))


class Client:
    """A connection to one plenoxd.

    target: "host:port". token: the daemon's bearer token (--auth-token-file), sent as
    "authorization: Bearer <token>" metadata. root_certificates: PEM bytes (or a path to a PEM
    file) of the CA that signed the daemon's --tls-cert; TLS is used when given.
    max_message_bytes: the largest message sent or received (the daemon's default is 64 MiB).
    timeout: seconds for unary calls (None = no deadline).
    version_check: what to do when the daemon's version (ServerInfo.version, asked once before
    the first call to its API) is not this package's API_VERSION: "warn" (a
    PlenoxdVersionWarning naming both), "error" (every API call raises PlenoxdVersionError) or
    "off". health() and server_info() are never refused: they are how one looks at a daemon.
    retry_seconds: how long to wait for a daemon that answered before and went away (killed,
    restarted, failed over): calls safe to repeat are retried on UNAVAILABLE with backoff for
    up to this long, and slam() streams reconnect and continue their map (0: fail at once;
    plenoxd_client.retry says which calls and why). `retry`: the RetryPolicy.
    """

    def __init__(self, target: str, token: Optional[str] = None,
                 root_certificates: Union[bytes, str, None] = None,
                 max_message_bytes: int = DEFAULT_MAX_MESSAGE_BYTES,
                 timeout: Optional[float] = None, version_check: str = "warn",
                 retry_seconds: float = 30.0):
        if version_check not in VERSION_CHECKS:
            raise ValueError(f"version_check: expected one of {VERSION_CHECKS}, got "
                             f"{version_check!r}")
        self.target = target
        self.timeout = timeout
        self.version_check = version_check
        # The daemon's ServerInfo.version once it was asked (None before).
        self.server_version: Optional[str] = None
        self._version_error: Optional[PlenoxdVersionError] = None
        self._version_lock = threading.Lock()
        self.retry = RetryPolicy(retry_seconds)
        # Whether the daemon ever answered: only then is UNAVAILABLE a failover to wait out.
        self._reached = False
        # gRPC's own reconnection backoff (1 s growing to 120 s by default) kept within the
        # policy's, so a retried call finds a restarted daemon soon after it is back.
        options = [("grpc.max_send_message_length", int(max_message_bytes)),
                   ("grpc.max_receive_message_length", int(max_message_bytes)),
                   ("grpc.initial_reconnect_backoff_ms", int(self.retry.initial_backoff * 1000)),
                   ("grpc.max_reconnect_backoff_ms", int(self.retry.max_backoff * 1000)),
                   # A lost connection makes the channel resolve the address again, at most
                   # once per this (30 s by default), and it waits for that resolution.
                   ("grpc.dns_min_time_between_resolutions_ms",
                    int(self.retry.max_backoff * 1000))]
        if root_certificates is not None:
            if isinstance(root_certificates, str):
                with open(root_certificates, "rb") as f:
                    root_certificates = f.read()
            credentials = grpc.ssl_channel_credentials(root_certificates=root_certificates)
            self._channel = grpc.secure_channel(target, credentials, options=options)
        else:
            self._channel = grpc.insecure_channel(target, options=options)
        self._metadata: Tuple[Tuple[str, str], ...] = (
            (("authorization", f"Bearer {token}"),) if token else ())
        self._stub = pb_grpc.PlenoxdStub(self._channel)
        self._health = health_pb2_grpc.HealthStub(self._channel)
        self.retry.sleep = self._sleep_unless_connected

    # --- plumbing ---

    def _sleep_unless_connected(self, seconds: float) -> None:
        """The retry policy's wait: `seconds`, ended early when the channel, not connected as
        the wait begins, connects. gRPC learns whether its connection attempts succeed only
        while something polls the channel; between a failed call and the next only its backup
        poller does, every 5 s, so a daemon back after 1.5 s was found after 5 (the C++
        client's ChannelWaitClock does the same). A channel that stays connected (a proxy
        answered UNAVAILABLE for the daemon behind it) gets the whole wait."""
        connected = threading.Event()
        seen: List[grpc.ChannelConnectivity] = []

        def on_state(state: grpc.ChannelConnectivity) -> None:
            # The first call reports the state as the wait begins; only a later READY ends it.
            if seen and state is grpc.ChannelConnectivity.READY:
                connected.set()
            seen.append(state)

        self._channel.subscribe(on_state, try_to_connect=True)
        try:
            connected.wait(seconds)
        finally:
            self._channel.unsubscribe(on_state)

    def close(self) -> None:
        self._channel.close()

    def __enter__(self) -> Client:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def metadata_for(self, map_name: Optional[str] = None) -> Tuple[Tuple[str, str], ...]:
        """Call metadata: the bearer token, and the map's name as "x-plenoxd-map" (a proxy in
        front of several daemons routes on it, deploy/k8s/envoy.yaml)."""
        if not map_name:
            return self._metadata
        return self._metadata + (("x-plenoxd-map", map_name),)

    def _unary(self, method: str, request: Any, timeout: Optional[float] = None,
               check_version: bool = True) -> Any:
        if check_version:
            self._check_version()
        map_name = getattr(request, "map", None) or getattr(request, "name", None)
        try:
            return self._retried(method, lambda: getattr(self._stub, method)(
                request, metadata=self.metadata_for(map_name),
                timeout=timeout if timeout is not None else self.timeout))
        except grpc.RpcError as e:
            raise PlenoxdError.from_rpc_error(e, method) from None

    def _retried(self, method: str, call: Callable[[], Any]) -> Any:
        """call() under the retry policy once the daemon has answered (retry.py)."""
        def attempt() -> Any:
            try:
                result = call()
            except grpc.RpcError as e:
                if e.code() != grpc.StatusCode.UNAVAILABLE:
                    self._reached = True  # the daemon answered, with an error
                raise
            self._reached = True
            return result
        if not self._reached:
            return attempt()
        return self.retry.call(attempt, method)

    def wait_ready(self, timeout: float = 10.0) -> None:
        """Blocks until the channel connects, then checks the daemon's version as before a
        first call (version_check); raises PlenoxdError(UNAVAILABLE) on timeout."""
        try:
            grpc.channel_ready_future(self._channel).result(timeout=timeout)
        except grpc.FutureTimeoutError:
            raise PlenoxdError(grpc.StatusCode.UNAVAILABLE,
                               f"no connection to {self.target} within {timeout} s",
                               "connect") from None
        self._check_version()

    # --- the daemon's version ---

    def _record_server_version(self, version: str) -> None:
        """Applies version_check to the daemon's version, the first time it is known."""
        with self._version_lock:
            if self.server_version is not None:
                return
            self.server_version = version
            try:
                check_server_version(version, self.target, self.version_check)
            except PlenoxdVersionError as e:
                self._version_error = e

    def _check_version(self) -> None:
        """Before a call to the daemon's API. A daemon that could not be asked (unreachable, or
        GetServerInfo refused for want of a token) is asked again before the next call; the
        call itself then says why it fails."""
        if self.version_check == "off":
            return
        if self.server_version is None:
            try:
                info = self._unary("GetServerInfo", pb.GetServerInfoRequest(),
                                   check_version=False)
            except PlenoxdError:
                return
            self._record_server_version(info.version)
        error = self._version_error
        if error is not None:  # a new exception each time: one raised again grows its traceback
            raise PlenoxdVersionError(error.message, error.client_version, error.server_version)

    def check_version(self) -> str:
        """Asks the daemon for its version and returns it; raises PlenoxdVersionError naming
        both versions when it is not this package's API_VERSION, whatever version_check says
        (PlenoxdError when the daemon cannot be asked)."""
        version = self._unary("GetServerInfo", pb.GetServerInfoRequest(),
                              check_version=False).version
        message = version_mismatch(version, self.target)
        if message is None:
            self._record_server_version(version)
            return version
        error = PlenoxdVersionError(message, API_VERSION, version)
        with self._version_lock:  # raised here: the first check, but no warning besides
            if self.server_version is None:
                self.server_version = version
                if self.version_check == "error":
                    self._version_error = error
        raise error

    # --- health ---

    def health(self, service: str = "", timeout: float = 5.0) -> bool:
        """True when the daemon reports SERVING (the standard grpc.health.v1 service; it answers
        without a token)."""
        try:
            response = self._retried("Health.Check", lambda: self._health.Check(
                health_pb2.HealthCheckRequest(service=service), timeout=timeout))
        except grpc.RpcError as e:
            raise PlenoxdError.from_rpc_error(e, "Health.Check") from None
        return response.status == health_pb2.HealthCheckResponse.SERVING

    def server_info(self) -> pb.ServerInfo:
        """ServerInfo: version, backend, compute devices (id, kind, name, queue, streams), maps.
        Its version is checked as before any call (a warning when it differs), but this call is
        never refused for it."""
        info = self._unary("GetServerInfo", pb.GetServerInfoRequest(), check_version=False)
        if self.version_check != "off":
            self._record_server_version(info.version)
        return info

    # --- maps ---

    def create_map(self, name: str, voxel_size: float = 0.0) -> pb.MapInfo:
        """MapInfo of a new, empty map (voxel_size metres; 0 = the server default, 0.02)."""
        return self._unary("CreateMap", pb.CreateMapRequest(name=name, voxel_size=voxel_size))

    def get_map(self, name: str) -> pb.MapInfo:
        return self._unary("GetMap", pb.GetMapRequest(name=name))

    def list_maps(self) -> List[pb.MapInfo]:
        """[MapInfo] of every map the daemon holds."""
        return list(self._unary("ListMaps", pb.ListMapsRequest()).maps)

    def delete_map(self, name: str) -> None:
        self._unary("DeleteMap", pb.DeleteMapRequest(name=name))

    def save_map(self, name: str) -> pb.MapInfo:
        """Writes the map to the daemon's data directory; returns its MapInfo."""
        return self._unary("SaveMap", pb.SaveMapRequest(name=name))

    def load_map(self, name: str) -> pb.MapInfo:
        """Reads <data-dir>/<name>.plx back into the daemon; returns its MapInfo."""
        return self._unary("LoadMap", pb.LoadMapRequest(name=name))

    # --- mapping ---

    def integrate(self, map_name: str, frames: Iterable[FrameLike],
                  options: Optional[IntegrateOptionsLike] = None) -> Iterator[pb.MappingProgress]:
        """Streams posed keyframes into map_name; yields plenoxd.v1.MappingProgress messages,
        the last with done=True once the frames are all sent and the optimisation budget is
        spent. frames: dataset.Frame objects (with .pose), Frame messages (with pose), or
        dicts. options: IntegrateOptions or a dict of its fields."""
        def requests() -> Iterator[pb.IntegrateRequest]:
            head = pb.IntegrateRequest(map=map_name)
            if options is not None:
                head.options.CopyFrom(_integrate_options(options))
            first: Optional[pb.IntegrateRequest] = head
            for frame in frames:
                # A frame without a pose is the server's to reject ("frame[i].pose: required").
                message = convert.frame_to_proto(frame, with_pose=True)
                if first is not None:
                    first.frame.CopyFrom(message)
                    yield first
                    first = None
                else:
                    yield pb.IntegrateRequest(frame=message)
            if first is not None:  # no frames: still open the stream (the map is unchanged)
                yield first

        self._check_version()
        feed = _RequestFeed(requests())
        call = None
        try:
            call = self._stub.Integrate(iter(feed), metadata=self.metadata_for(map_name))
            for progress in call:
                yield progress
        except grpc.RpcError as e:
            if feed.error is not None:
                raise feed.error from None
            raise PlenoxdError.from_rpc_error(e, "Integrate") from None
        finally:
            if call is not None and call.running():
                call.cancel()

    def integrate_all(self, map_name: str, frames: Iterable[FrameLike],
                      options: Optional[IntegrateOptionsLike] = None
                      ) -> Optional[pb.MappingProgress]:
        """integrate() run to the end; returns the final MappingProgress (done=True)."""
        last = None
        for last in self.integrate(map_name, frames, options):
            pass
        return last

    def watch_job(self, job_id: str) -> Iterator[pb.JobStatus]:
        """Yields plenoxd.v1.JobStatus until the job ends."""
        self._check_version()
        call = None
        try:
            call = self._stub.WatchJob(pb.WatchJobRequest(job_id=job_id), metadata=self._metadata)
            for status in call:
                yield status
        except grpc.RpcError as e:
            raise PlenoxdError.from_rpc_error(e, "WatchJob") from None
        finally:
            if call is not None and call.running():
                call.cancel()

    # --- tracking ---

    def track(self, map_name: str, frames: Iterable[FrameLike],
              initial_pose: Optional[PoseLike] = None, lockstep: bool = True,
              options: Optional[TrackOptionsLike] = None, priors: bool = False,
              fps: Optional[float] = None) -> TrackStream:
        """Tracks frames against map_name; returns a TrackStream yielding one
        plenoxd.v1.PoseEstimate per frame served (see convert.pose_from_proto).

        initial_pose: the first frame's pose ((t, q), 4x4 or Pose); its estimate is that pose.
        lockstep=True sends a frame only after the previous one's estimate came back (no drops).
        lockstep=False streams from a sender thread (at fps frames per second when given, else
        as fast as frames come); the server then keeps only the newest waiting frame and each
        estimate's `dropped` (and TrackStream.dropped) counts the skipped ones.
        priors=True also sends dataset frames' poses, which the tracker uses as initial guesses
        (e.g. VIO poses); leave it False when the poses are ground truth.
        options: TrackOptions or a dict (mode "gauss_newton"/"adam", rays, iterations, pixels
            "informative"/"uniform")."""
        return TrackStream(self, map_name, frames, initial_pose, lockstep, options, priors, fps)

    # --- SLAM ---

    def slam(self, map_name: str, frames: Iterable[FrameLike],
             initial_pose: Optional[PoseLike] = None, options: Optional[SlamOptionsLike] = None,
             lockstep: bool = True, priors: bool = False,
             fps: Optional[float] = None, resume: Optional[bool] = None) -> SlamStream:
        """Online SLAM into map_name (created when it does not exist, bootstrapped when empty,
        extended when it has content): unposed frames in; returns a SlamStream yielding one
        plenoxd.v1.SlamUpdate per frame the server processed (slam_pose(u) for its pose), and
        ending once the server's done message came (SlamStream.done).

        initial_pose: where the camera starts ((t, q), 4x4 or Pose): a new map's first keyframe
        sits there; in a map with content the first frame relocalises from it.
        lockstep=True sends a frame only after the previous one's update came back.
        lockstep=False streams from a sender thread (at fps frames per second when given); the
        server then processes every frame in order (it stops reading while frames wait) unless
        options has realtime=True, where it keeps only the newest waiting frame and each
        update's `dropped` (and SlamStream.dropped) counts the skipped ones.
        priors=True also sends dataset frames' poses as priors (e.g. VIO poses); leave it
        False when the poses are ground truth.
        options: SlamOptions or a dict of its fields (voxel_size, tracking={mode, rays,
        iterations}, kf_translation_m, kf_rotation_deg, kf_unmapped_fraction, kf_interval_s,
        iterations_per_keyframe, rays_per_iteration, max_depth, realtime, deterministic,
        max_pending_keyframes).
        resume: reconnect a stream cut by a failover (UNAVAILABLE) within retry_seconds and go
        on in the same map, relocalising against its saved keyframes (default: when
        retry_seconds > 0). The stream then also counts `reconnects` and `frames_lost` (taken
        from `frames` but never answered); plenoxd_client.failover says more."""
        if options is not None:
            _slam_options(options)  # a bad option raises here, before the call starts
        if resume if resume is not None else self.retry.seconds > 0:
            from .failover import ResumingSlamStream  # noqa: PLC0415 -- it imports this module
            return ResumingSlamStream(self, map_name, frames, initial_pose, lockstep, options,
                                      priors, fps)
        return SlamStream(self, map_name, frames, initial_pose, lockstep, options, priors, fps)

    # --- views ---

    @overload
    def render(self, map_name: str, pose: PoseLike, intrinsics: IntrinsicsLike,
               with_info: Literal[False] = ..., timeout: Optional[float] = ...
               ) -> Tuple[np.ndarray, np.ndarray]: ...

    @overload
    def render(self, map_name: str, pose: PoseLike, intrinsics: IntrinsicsLike,
               with_info: Literal[True], timeout: Optional[float] = ...) -> Rendering: ...

    def render(self, map_name: str, pose: PoseLike, intrinsics: IntrinsicsLike,
               with_info: bool = False, timeout: Optional[float] = None
               ) -> Union[Tuple[np.ndarray, np.ndarray], Rendering]:
        """Renders the map from pose (world_T_camera) with the intrinsics' size. Returns
        (color HxWx3 uint8, depth HxW float32 metres, 0 = nothing rendered), or a Rendering
        (color, depth, coverage, map_version) when with_info=True."""
        request = pb.RenderRequest(map=map_name, color_encoding=pb.COLOR_ENCODING_RAW_RGB8,
                                   depth_encoding=pb.DEPTH_ENCODING_RAW_U16)
        convert.pose_to_proto(pose, request.pose)
        convert.intrinsics_to_proto(intrinsics, request.intrinsics)
        response = self._unary("Render", request, timeout)
        w, h = response.width, response.height
        color = convert.decode_color(response.color, response.color_encoding, w, h)
        depth = convert.decode_depth(response.depth, response.depth_encoding, w, h, 1000.0)
        if with_info:
            return Rendering(color, depth, response.coverage, response.map_version)
        return color, depth

    def export(self, map_name: str, min_density: float = 0.0) -> bytes:
        """The map's surface points as binary little-endian PLY bytes."""
        return self._export(pb.ExportRequest(map=map_name, min_density=min_density))

    def export_mesh(self, map_name: str, path: str, iso_level: float = 0.0,
                    min_component_triangles: int = 0, max_triangles: int = 0,
                    keep_unobserved: bool = False, color: str = "dc", format: str = "ply",
                    lod_triangles: int = 0,
                    bbox: Optional[Sequence[float]] = None,
                    surface: str = "auto") -> MeshExport:
        """Writes the map's triangle mesh (marching cubes on the daemon's device) to `path` as
        binary little-endian PLY (vertex x y z nx ny nz red green blue, face vertex_indices),
        which Open3D, MeshLab and Blender read, or with format="glb" as binary glTF 2.0
        (headsets, three.js, Blender; plenoxd_client.glb.read_glb_info reads its counts); the
        file appears only once complete. Returns MeshExport(vertices, faces, bytes, full_faces,
        lod_error_m).

        iso_level: surface density in 1/m (0 = the daemon's default, 50); min_component_triangles:
        drop connected pieces smaller than this (0 keeps all); max_triangles: fail with
        RESOURCE_EXHAUSTED beyond this (0 = the daemon's limit); keep_unobserved: keep surfaces
        no view saw (the backs of walls); color: "dc" (view-independent) or "normal" (as seen
        looking along the vertex normal); lod_triangles: a level of detail, the mesh simplified
        to at most this many triangles (0 = the full mesh); bbox: (xmin, ymin, zmin, xmax, ymax,
        zmax) in metres, map coordinates: only that box of the map (the triangles of the voxels
        whose centres are in it, kept whole; an empty box region gives an empty mesh);
        surface: "observed" (what the map's keyframes saw, once: no back faces, nothing
        unseen), "density" (the density's iso-surface at iso_level) or "auto" (observed when
        the map has keyframes; an observed surface of a map without them is
        FAILED_PRECONDITION). Bad
        values: PlenoxdError INVALID_ARGUMENT naming the field; a daemon whose file does not
        honour lod_triangles or bbox (older than them): PlenoxdError FAILED_PRECONDITION, and
        nothing is written."""
        colors = {"dc": pb.MESH_COLOR_DC, "normal": pb.MESH_COLOR_ALONG_NORMAL}
        if color not in colors:
            raise ValueError(f"color: expected 'dc' or 'normal', got {color!r}")
        formats = {"ply": pb.EXPORT_FORMAT_MESH, "glb": pb.EXPORT_FORMAT_MESH_GLB}
        if format not in formats:
            raise ValueError(f"format: expected 'ply' or 'glb', got {format!r}")
        surfaces = {"auto": pb.MESH_SURFACE_AUTO, "observed": pb.MESH_SURFACE_OBSERVED,
                    "density": pb.MESH_SURFACE_DENSITY}
        if surface not in surfaces:
            raise ValueError(
                f"surface: expected 'auto', 'observed' or 'density', got {surface!r}")
        request = pb.ExportRequest(
            map=map_name, format=formats[format], iso_level=iso_level,
            min_component_triangles=min_component_triangles, max_triangles=max_triangles,
            keep_unobserved=keep_unobserved, mesh_color=colors[color],
            lod_triangles=lod_triangles, mesh_surface=surfaces[surface])
        if bbox is not None:
            values = [float(v) for v in bbox]
            if len(values) != 6:
                raise ValueError(f"bbox: expected 6 numbers (xmin, ymin, zmin, xmax, ymax, "
                                 f"zmax), got {len(values)}")
            request.region.CopyFrom(pb.BoundingBox(
                min_x=values[0], min_y=values[1], min_z=values[2], max_x=values[3],
                max_y=values[4], max_z=values[5]))
        data = self._export(request)
        if format == "glb":
            info = read_glb_info(data)
            result = MeshExport(info.vertices, info.triangles, len(data), info.full_triangles,
                                info.lod_error_m)
            has_region = info.region is not None
        else:
            header = data[:data.find(b"end_header\n")].decode("ascii", "replace")
            counts = dict(line.split()[1:3] for line in header.splitlines()
                          if line.startswith("element "))
            faces = int(counts.get("face", 0))
            result = MeshExport(int(counts.get("vertex", 0)), faces, len(data), faces)
            has_region = "\ncomment plenoxd region: " in header
        if lod_triangles > 0 and result.faces > lod_triangles:
            raise PlenoxdError(grpc.StatusCode.FAILED_PRECONDITION,
                               f"the daemon sent {result.faces} triangles for a level of detail "
                               f"of at most {lod_triangles}: it is older than lod_triangles",
                               "Export")
        if bbox is not None and not has_region:
            raise PlenoxdError(grpc.StatusCode.FAILED_PRECONDITION,
                               "the daemon's file does not record the bbox region: it is older "
                               "than the region field and sent the whole map", "Export")
        temp = f"{path}.tmp.{os.getpid()}.{format}"
        with open(temp, "wb") as f:
            f.write(data)
        os.replace(temp, path)
        return result

    def _export(self, request: pb.ExportRequest) -> bytes:
        """Every chunk of an Export call, joined."""
        self._check_version()
        map_name = request.map
        parts, offset = [], 0
        call = None
        try:
            call = self._stub.Export(request, metadata=self.metadata_for(map_name))
            for chunk in call:
                if chunk.offset != offset:
                    raise PlenoxdError(grpc.StatusCode.DATA_LOSS,
                                       f"chunk at offset {chunk.offset}, expected {offset}",
                                       "Export")
                parts.append(chunk.data)
                offset += len(chunk.data)
                if chunk.last:
                    break
        except grpc.RpcError as e:
            raise PlenoxdError.from_rpc_error(e, "Export") from None
        finally:
            if call is not None and call.running():
                call.cancel()
        return b"".join(parts)


def estimate_pose(estimate: pb.PoseEstimate) -> Pose:
    """(t, q) of a PoseEstimate; convert.pose_to_matrix(*estimate_pose(e)) for a 4x4."""
    return convert.pose_from_proto(estimate.pose)


def state_name(estimate: pb.PoseEstimate) -> str:
    """"OK", "DEGRADED", "LOST" (or "UNSPECIFIED") of a PoseEstimate."""
    return pb.TrackingState.Name(estimate.state).replace("TRACKING_STATE_", "")


def slam_pose(update: pb.SlamUpdate) -> Pose:
    """(t, q) of a SlamUpdate's frame (for LOST: the prediction); convert.pose_to_matrix(*...)
    for a 4x4. A done message has no frame: ValueError."""
    if update.done:
        raise ValueError("a done SlamUpdate carries no frame and no pose")
    return convert.pose_from_proto(update.pose)


# A pose's anchor keyframe is the newest of those this near (metres plus radians of viewing
# direction) to the nearest one: the daemon's rule (core/slam/slam_correction.h).
_RECENT_KEYFRAME_MARGIN = 0.3


def correct_pose(correction: pb.SlamCorrection, pose: PoseLike) -> Pose:
    """`pose` (any form convert.as_pose() reads) held in the frame before a SlamCorrection, as
    (t, q) in the corrected frame: moved with the keyframe it is anchored to, as the daemon
    moves its cameras and keyframes. A correction without keyframes leaves it as it is."""
    t, q = convert.as_pose(pose)
    m = convert.pose_to_matrix(t, q)
    best, distances = None, []
    for move in correction.keyframes:
        bt, bq = convert.pose_from_proto(move.before)
        cos_half = min(1.0, abs(float(np.dot(bq / np.linalg.norm(bq), q / np.linalg.norm(q)))))
        distances.append(float(np.linalg.norm(bt - t)) + 2.0 * float(np.arccos(cos_half)))
    if distances:
        nearest = min(distances)
        best = max(i for i, d in enumerate(distances) if d <= nearest + _RECENT_KEYFRAME_MARGIN)
    if best is None:
        return t, q
    move = correction.keyframes[best]
    before = convert.pose_to_matrix(*convert.pose_from_proto(move.before))
    after = convert.pose_to_matrix(*convert.pose_from_proto(move.after))
    return convert.matrix_to_pose(after @ np.linalg.inv(before) @ m)


def slam_state_name(update: pb.SlamUpdate) -> str:
    """"OK", "DEGRADED", "LOST", "RELOCALISED", "WAITING" (or "UNSPECIFIED") of a SlamUpdate."""
    return pb.SlamState.Name(update.state).replace("SLAM_STATE_", "")


def as_dict(message: Any) -> Dict[str, Any]:
    """A protobuf message as a plain dict (field names as in the .proto, defaults included)."""
    from google.protobuf.json_format import MessageToDict  # noqa: PLC0415
    return MessageToDict(message, preserving_proto_field_name=True,
                         including_default_value_fields=True)

