"""A synchronous client for the plenoxd.v1 gRPC API (proto/plenoxd/v1/plenoxd.proto).

    from plenoxd_client import Client
    with Client("127.0.0.1:50051", token="...") as c:
        c.create_map("room", voxel_size=0.04)
        for progress in c.integrate("room", keyframes):    # posed keyframes
            print(progress.keyframes_integrated, progress.done)
        for estimate in c.track("room", frames, initial_pose=first_pose):
            print(estimate.state, estimate.pose)
        color, depth = c.render("room", pose, intrinsics)

Every failed call raises PlenoxdError with the gRPC status code and the server's message.
"""

import queue
import threading
from collections import namedtuple

import grpc

import health_pb2
import health_pb2_grpc
from plenoxd.v1 import plenoxd_pb2 as pb
from plenoxd.v1 import plenoxd_pb2_grpc as pb_grpc

from . import convert

__all__ = ["Client", "PlenoxdError", "TrackStream", "Rendering", "DEFAULT_MAX_MESSAGE_BYTES",
           "estimate_pose", "state_name", "as_dict"]

DEFAULT_MAX_MESSAGE_BYTES = 64 << 20
_END = object()


class PlenoxdError(Exception):
    """A call failed. code: grpc.StatusCode (e.g. grpc.StatusCode.NOT_FOUND); message: the
    server's explanation (INVALID_ARGUMENT names the field, e.g. "frame.color: ...");
    method: the RPC."""

    def __init__(self, code, message, method=""):
        self.code = code
        self.message = message or ""
        self.method = method
        name = code.name if isinstance(code, grpc.StatusCode) else str(code)
        prefix = f"{method} failed: " if method else ""
        super().__init__(f"{prefix}{name}: {self.message}")

    @property
    def code_name(self):
        return self.code.name if isinstance(self.code, grpc.StatusCode) else str(self.code)

    @classmethod
    def from_rpc_error(cls, error, method):
        code = error.code() if hasattr(error, "code") else grpc.StatusCode.UNKNOWN
        details = error.details() if hasattr(error, "details") else str(error)
        return cls(code, details, method)


Rendering = namedtuple("Rendering", "color depth coverage map_version")
Rendering.__doc__ = """color: HxWx3 uint8 RGB; depth: HxW float32 z-depth in metres (0 = nothing
rendered); coverage: fraction of pixels the map renders; map_version: the version rendered."""


def _drain(outbox):
    """Items of a queue until the _END marker (compared by identity, not ==)."""
    while True:
        item = outbox.get()
        if item is _END:
            return
        yield item


class _RequestFeed:
    """The request iterator of a streaming call. It records an exception raised while making a
    request (gRPC would otherwise only cancel the call), so the caller can re-raise it."""

    def __init__(self, requests):
        self._requests = requests
        self.error = None

    def __iter__(self):
        try:
            for r in self._requests:
                yield r
        except Exception as e:  # noqa: BLE001 -- handed to the caller's thread
            self.error = e
            raise


class TrackStream:
    """The estimates of one Track call, as an iterator of plenoxd.v1.PoseEstimate.

    Counters while and after iterating: sent (frames sent), received (estimates), dropped
    (frames the server skipped because newer ones arrived, the sum of PoseEstimate.dropped),
    lost / degraded (estimates in those states). cancel() ends the call early."""

    def __init__(self, client, map_name, frames, initial_pose, lockstep, options, priors, fps):
        self.sent = 0
        self.received = 0
        self.dropped = 0
        self.lost = 0
        self.degraded = 0
        self._client = client
        self._map = map_name
        self._frames = frames
        self._initial_pose = initial_pose
        self._lockstep = lockstep
        self._options = options
        self._priors = priors
        self._fps = fps
        self._call = None
        self._stop = threading.Event()
        self._started = False

    def cancel(self):
        self._stop.set()
        if self._call is not None:
            self._call.cancel()

    def _request(self, frame, first):
        request = pb.TrackRequest(frame=convert.frame_to_proto(frame, with_pose=self._priors))
        if first:
            request.map = self._map
            if self._options is not None:
                request.options.CopyFrom(_track_options(self._options))
            if self._initial_pose is not None:
                convert.pose_to_proto(self._initial_pose, request.initial_pose)
        return request

    def _count(self, estimate):
        self.received += 1
        self.dropped += estimate.dropped
        if estimate.state == pb.TRACKING_STATE_LOST:
            self.lost += 1
        elif estimate.state == pb.TRACKING_STATE_DEGRADED:
            self.degraded += 1

    def __iter__(self):
        if self._started:
            raise RuntimeError("a TrackStream can be iterated once")
        self._started = True
        if self._lockstep:
            return self._run_lockstep()
        return self._run_streaming()

    def _run_lockstep(self):
        # One frame out, its estimate back, then the next frame. The feed blocks on a queue the
        # response loop fills, so the server never has more than one frame waiting.
        outbox = queue.Queue()
        frames = iter(self._frames)
        feed = _RequestFeed(_drain(outbox))

        def send_next(first):
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
            self._call = self._client._stub.Track(
                iter(feed), metadata=self._client.metadata_for(self._map))
            for estimate in self._call:
                self._count(estimate)
                yield estimate
                if self._stop.is_set():
                    break
                if self.received >= self.sent:
                    send_next(False)
        except grpc.RpcError as e:
            if feed.error is not None:
                raise feed.error from None
            if self._stop.is_set() and e.code() == grpc.StatusCode.CANCELLED:
                return
            raise PlenoxdError.from_rpc_error(e, "Track") from None
        finally:
            outbox.put(_END)
            if self._call is not None and self._call.running():
                self._call.cancel()

    def _run_streaming(self):
        # A sender thread pushes frames as they come (paced to fps when given) into a queue that
        # gRPC drains as fast as the network takes them; when frames arrive faster than the
        # server tracks, the server keeps the newest (latest wins) and reports the rest dropped.
        outbox = queue.Queue()
        feed = _RequestFeed(_drain(outbox))
        period = 1.0 / self._fps if self._fps else 0.0
        sender_error = []

        def sender():
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

        thread = threading.Thread(target=sender, name="plenoxd-track-sender", daemon=True)
        try:
            self._call = self._client._stub.Track(
                iter(feed), metadata=self._client.metadata_for(self._map))
            thread.start()
            for estimate in self._call:
                self._count(estimate)
                yield estimate
                if self._stop.is_set():
                    break
        except grpc.RpcError as e:
            if sender_error:
                raise sender_error[0] from None
            if self._stop.is_set() and e.code() == grpc.StatusCode.CANCELLED:
                return
            raise PlenoxdError.from_rpc_error(e, "Track") from None
        finally:
            self._stop.set()
            if self._call is not None and self._call.running():
                self._call.cancel()
            if thread.is_alive():
                thread.join(timeout=5.0)
        if sender_error:
            raise sender_error[0]


def _track_options(options):
    if isinstance(options, pb.TrackOptions):
        return options
    o = pb.TrackOptions()
    mode = options.get("mode")
    if isinstance(mode, str):
        o.mode = {"gauss_newton": pb.TrackOptions.MODE_GAUSS_NEWTON, "gn":
                  pb.TrackOptions.MODE_GAUSS_NEWTON, "adam": pb.TrackOptions.MODE_ADAM}[mode.lower()]
    elif mode is not None:
        o.mode = int(mode)
    o.rays = int(options.get("rays", 0))
    o.iterations = int(options.get("iterations", 0))
    return o


def _integrate_options(options):
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
    """

    def __init__(self, target, token=None, root_certificates=None,
                 max_message_bytes=DEFAULT_MAX_MESSAGE_BYTES, timeout=None):
        self.target = target
        self.timeout = timeout
        options = [("grpc.max_send_message_length", int(max_message_bytes)),
                   ("grpc.max_receive_message_length", int(max_message_bytes))]
        if root_certificates is not None:
            if isinstance(root_certificates, str):
                with open(root_certificates, "rb") as f:
                    root_certificates = f.read()
            credentials = grpc.ssl_channel_credentials(root_certificates=root_certificates)
            self._channel = grpc.secure_channel(target, credentials, options=options)
        else:
            self._channel = grpc.insecure_channel(target, options=options)
        self._metadata = (("authorization", f"Bearer {token}"),) if token else ()
        self._stub = pb_grpc.PlenoxdStub(self._channel)
        self._health = health_pb2_grpc.HealthStub(self._channel)

    # --- plumbing ---

    def close(self):
        self._channel.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def metadata_for(self, map_name=None):
        """Call metadata: the bearer token, and the map's name as "x-plenoxd-map" (a proxy in
        front of several daemons routes on it, deploy/k8s/envoy.yaml)."""
        if not map_name:
            return self._metadata
        return self._metadata + (("x-plenoxd-map", map_name),)

    def _unary(self, method, request, timeout=None):
        map_name = getattr(request, "map", None) or getattr(request, "name", None)
        try:
            return getattr(self._stub, method)(
                request, metadata=self.metadata_for(map_name),
                timeout=timeout if timeout is not None else self.timeout)
        except grpc.RpcError as e:
            raise PlenoxdError.from_rpc_error(e, method) from None

    def wait_ready(self, timeout=10.0):
        """Blocks until the channel connects; raises PlenoxdError(UNAVAILABLE) on timeout."""
        try:
            grpc.channel_ready_future(self._channel).result(timeout=timeout)
        except grpc.FutureTimeoutError:
            raise PlenoxdError(grpc.StatusCode.UNAVAILABLE,
                               f"no connection to {self.target} within {timeout} s",
                               "connect") from None

    # --- health ---

    def health(self, service="", timeout=5.0):
        """True when the daemon reports SERVING (the standard grpc.health.v1 service; it answers
        without a token)."""
        try:
            response = self._health.Check(health_pb2.HealthCheckRequest(service=service),
                                          timeout=timeout)
        except grpc.RpcError as e:
            raise PlenoxdError.from_rpc_error(e, "Health.Check") from None
        return response.status == health_pb2.HealthCheckResponse.SERVING

    def server_info(self):
        """ServerInfo: version, backend, compute devices (id, kind, name, queue, streams), maps."""
        return self._unary("GetServerInfo", pb.GetServerInfoRequest())

    # --- maps ---

    def create_map(self, name, voxel_size=0.0):
        """MapInfo of a new, empty map (voxel_size metres; 0 = the server default, 0.02)."""
        return self._unary("CreateMap", pb.CreateMapRequest(name=name, voxel_size=voxel_size))

    def get_map(self, name):
        return self._unary("GetMap", pb.GetMapRequest(name=name))

    def list_maps(self):
        """[MapInfo] of every map the daemon holds."""
        return list(self._unary("ListMaps", pb.ListMapsRequest()).maps)

    def delete_map(self, name):
        self._unary("DeleteMap", pb.DeleteMapRequest(name=name))

    def save_map(self, name):
        """Writes the map to the daemon's data directory; returns its MapInfo."""
        return self._unary("SaveMap", pb.SaveMapRequest(name=name))

    def load_map(self, name):
        """Reads <data-dir>/<name>.plx back into the daemon; returns its MapInfo."""
        return self._unary("LoadMap", pb.LoadMapRequest(name=name))

    # --- mapping ---

    def integrate(self, map_name, frames, options=None):
        """Streams posed keyframes into map_name; yields plenoxd.v1.MappingProgress messages,
        the last with done=True once the frames are all sent and the optimisation budget is
        spent. frames: dataset.Frame objects (with .pose), Frame messages (with pose), or
        dicts. options: IntegrateOptions or a dict of its fields."""
        def requests():
            first = pb.IntegrateRequest(map=map_name)
            if options is not None:
                first.options.CopyFrom(_integrate_options(options))
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

    def integrate_all(self, map_name, frames, options=None):
        """integrate() run to the end; returns the final MappingProgress (done=True)."""
        last = None
        for last in self.integrate(map_name, frames, options):
            pass
        return last

    def watch_job(self, job_id):
        """Yields plenoxd.v1.JobStatus until the job ends."""
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

    def track(self, map_name, frames, initial_pose=None, lockstep=True, options=None,
              priors=False, fps=None):
        """Tracks frames against map_name; returns a TrackStream yielding one
        plenoxd.v1.PoseEstimate per frame served (see convert.pose_from_proto).

        initial_pose: the first frame's pose ((t, q), 4x4 or Pose); its estimate is that pose.
        lockstep=True sends a frame only after the previous one's estimate came back (no drops).
        lockstep=False streams from a sender thread (at fps frames per second when given, else
        as fast as frames come); the server then keeps only the newest waiting frame and each
        estimate's `dropped` (and TrackStream.dropped) counts the skipped ones.
        priors=True also sends dataset frames' poses, which the tracker uses as initial guesses
        (e.g. VIO poses); leave it False when the poses are ground truth.
        options: TrackOptions or a dict (mode "gauss_newton"/"adam", rays, iterations)."""
        return TrackStream(self, map_name, frames, initial_pose, lockstep, options, priors, fps)

    # --- views ---

    def render(self, map_name, pose, intrinsics, with_info=False, timeout=None):
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

    def export(self, map_name, min_density=0.0):
        """The map's surface points as binary little-endian PLY bytes."""
        parts, offset = [], 0
        call = None
        try:
            call = self._stub.Export(pb.ExportRequest(map=map_name, min_density=min_density),
                                     metadata=self.metadata_for(map_name))
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


def estimate_pose(estimate):
    """(t, q) of a PoseEstimate; convert.pose_to_matrix(*estimate_pose(e)) for a 4x4."""
    return convert.pose_from_proto(estimate.pose)


def state_name(estimate):
    """"OK", "DEGRADED", "LOST" (or "UNSPECIFIED") of a PoseEstimate."""
    return pb.TrackingState.Name(estimate.state).replace("TRACKING_STATE_", "")


def as_dict(message):
    """A protobuf message as a plain dict (field names as in the .proto, defaults included)."""
    from google.protobuf.json_format import MessageToDict  # noqa: PLC0415
    return MessageToDict(message, preserving_proto_field_name=True,
                         including_default_value_fields=True)

