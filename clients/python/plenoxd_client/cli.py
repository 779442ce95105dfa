"""plenoxd-client: the Python client from the shell, for scripts.

    plenoxd-client [--server HOST:PORT] [--token-file F] [--tls-ca PEM] COMMAND ...
      health                 SERVING (exit 0) or NOT_SERVING (exit 1)
      info                   the daemon's version, backend, devices and map count
      maps                   the daemon's maps; maps create|get|save|load|delete NAME
      slam MAP --dataset DIR online SLAM of a TUM-layout sequence into MAP (TUM trajectory)
      export MAP --out F     the map as a PLY point cloud, or a mesh with --mesh

Exit codes: 0 done, 1 the daemon refused or failed the call (its message on stderr), 2 bad
arguments or an unreadable dataset. --json prints what a command returns as JSON instead of
text. A daemon of another API version gets a warning on stderr (--version-check error makes
it an error).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import warnings
from typing import Any, Callable, Dict, List, Optional, Sequence

from .client import Client, slam_pose, slam_state_name
from .dataset import TumDataset
from .errors import PlenoxdError, PlenoxdVersionWarning
from .trajectory import ate, write_tum_trajectory
from .version import API_VERSION, VERSION_CHECKS

__all__ = ["main"]

DEFAULT_SERVER = "127.0.0.1:50051"  # plenoxd's default --listen address, as plenox's


def _print_json(value: Any) -> None:
    print(json.dumps(value, indent=2, sort_keys=True))


def _plain(message: Any) -> Dict[str, Any]:
    """A message (MapInfo, ServerInfo) as a dict of every field, numbers as JSON numbers:
    as_dict() follows protobuf's JSON mapping, which writes 64-bit integers (bricks,
    memory_bytes) as strings. Enums stay numbers."""
    out: Dict[str, Any] = {}
    for field in message.DESCRIPTOR.fields:
        value = getattr(message, field.name)
        if field.message_type is not None:
            if field.label == field.LABEL_REPEATED:
                out[field.name] = [_plain(v) for v in value]
            else:
                out[field.name] = _plain(value)
        elif field.type == field.TYPE_FLOAT:  # float32: its 7 digits, not 0.019999999552965164
            out[field.name] = float(f"{value:.7g}")
        else:
            out[field.name] = value
    return out


def _map_rows(maps: Sequence[Any]) -> List[str]:
    """An aligned table of MapInfo messages, one per row after a header."""
    rows = [["name", "voxel_size", "keyframes", "bricks", "memory_MB", "version", "state"]]
    for m in maps:
        state = ",".join(word for word, on in (("dirty", m.dirty), ("mapping", m.mapping)) if on)
        # dirty: changed since last saved; mapping: a mapping job is writing it.
        rows.append([m.name, f"{m.voxel_size:g}", str(m.keyframes), str(m.bricks),
                     f"{m.memory_bytes / 1e6:.1f}", str(m.version), state or "-"])
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
    return ["  ".join(cell.ljust(w) for cell, w in zip(row, widths)).rstrip() for row in rows]


def _print_maps(maps: Sequence[Any], as_json: bool) -> None:
    if as_json:
        _print_json([_plain(m) for m in maps])
    else:
        print("\n".join(_map_rows(maps)))


# --- commands: each returns the exit code -------------------------------------------------------

def cmd_health(client: Client, args: argparse.Namespace) -> int:
    serving = client.health(args.service, timeout=args.timeout or 5.0)
    if args.json:
        _print_json({"serving": serving})
    else:
        print("SERVING" if serving else "NOT_SERVING")
    return 0 if serving else 1


def cmd_info(client: Client, args: argparse.Namespace) -> int:
    info = client.server_info()
    if args.json:
        _print_json({**_plain(info), "client_api_version": API_VERSION})
        return 0
    print(f"plenoxd {info.version} at {client.target} (this client: API version {API_VERSION})")
    print(f"backend: {info.backend} (CUDA {'built' if info.cuda_built else 'not built'}), "
          f"maps: {info.maps}")
    for d in info.devices:
        print(f"  {d.id}: {d.name}, queue {d.queue_depth}, streams {d.streams}")
    return 0


def cmd_maps(client: Client, args: argparse.Namespace) -> int:
    action = args.action or "list"
    if action == "list":
        _print_maps(client.list_maps(), args.json)
        return 0
    if action == "delete":
        client.delete_map(args.name)
        if args.json:
            _print_json({"deleted": args.name})
        else:
            print(f"deleted {args.name}")
        return 0
    calls: Dict[str, Callable[[], Any]] = {
        "create": lambda: client.create_map(args.name, voxel_size=args.voxel_size),
        "get": lambda: client.get_map(args.name),
        "save": lambda: client.save_map(args.name),
        "load": lambda: client.load_map(args.name),
    }
    _print_maps([calls[action]()], args.json)
    return 0


def cmd_slam(client: Client, args: argparse.Namespace) -> int:
    try:
        sequence = TumDataset(args.dataset)
    except (OSError, ValueError) as e:
        print(f"plenoxd-client: {e}", file=sys.stderr)
        return 2
    frames = sequence[:args.max_frames] if args.max_frames > 0 else sequence[:]
    if not frames:
        print(f"plenoxd-client: {args.dataset}: no frames", file=sys.stderr)
        return 2
    options = {"voxel_size": args.voxel_size, "iterations_per_keyframe": args.iterations,
               "tracking": {"rays": args.rays}, "deterministic": args.deterministic,
               "realtime": args.realtime}
    # The first frame's ground-truth pose puts the trajectory in the ground truth's frame, so
    # the ATE needs no alignment; without ground truth the daemon starts at the identity.
    start = time.monotonic()
    stream = client.slam(args.map, frames, initial_pose=frames[0].pose, options=options,
                         lockstep=not args.streaming, fps=args.fps or None)
    estimates: Dict[float, Any] = {}
    states: Dict[str, int] = {}
    for update in stream:
        estimates[update.timestamp] = slam_pose(update)
        state = slam_state_name(update)
        states[state] = states.get(state, 0) + 1
        if args.progress:
            print(f"frame {update.frame} {update.timestamp:.6f} {state}"
                  + (" keyframe" if update.keyframe else ""), file=sys.stderr, flush=True)
    seconds = time.monotonic() - start
    saved = client.save_map(args.map) if args.save else None
    out = args.out or f"{args.map}_slam.txt"
    write_tum_trajectory(out, estimates, f"plenoxd-client slam: {sequence.name} into {args.map}")
    error = ate(estimates, sequence.groundtruth())
    summary = {
        "map": args.map, "frames_sent": stream.sent, "updates": stream.received,
        "dropped": stream.dropped, "keyframes": stream.keyframes, "states": states,
        "seconds": round(seconds, 3), "trajectory": os.path.abspath(out),
        "ate_rmse_m": None if error is None else error["rmse"],
        "map_keyframes": stream.done.mapping.keyframes if stream.done else None,
        "saved": saved is not None,
    }
    if args.json:
        _print_json(summary)
        return 0
    print(f"{sequence.name} -> {args.map}: {stream.received} of {stream.sent} frames in "
          f"{seconds:.1f} s, {stream.keyframes} keyframes, states "
          + ", ".join(f"{k}={v}" for k, v in sorted(states.items())))
    print(f"trajectory: {summary['trajectory']}")
    if error is not None:
        print(f"ATE (no alignment, {error['matched']} frames): rmse "
              f"{100 * error['rmse']:.2f} cm")
    if saved is not None:
        print(f"saved {args.map}: version {saved.version}, {saved.keyframes} keyframes")
    return 0


def cmd_export(client: Client, args: argparse.Namespace) -> int:
    if args.mesh:
        mesh = client.export_mesh(args.map, args.out)
        result = {"path": args.out, "bytes": mesh.bytes, "vertices": mesh.vertices,
                  "faces": mesh.faces}
    else:
        data = client.export(args.map, min_density=args.min_density)
        temp = f"{args.out}.tmp.{os.getpid()}.ply"  # the file appears only once complete
        with open(temp, "wb") as f:
            f.write(data)
        os.replace(temp, args.out)
        result = {"path": args.out, "bytes": len(data)}
    if args.json:
        _print_json(result)
    else:
        print(f"wrote {result['path']} ({result['bytes']} bytes)")
    return 0


# --- arguments ---------------------------------------------------------------------------------

def _add_command(parent: Any, name: str, text: str) -> argparse.ArgumentParser:
    """A (sub)command parser that also takes --json after its name: `maps --json` as well as
    `--json maps` (SUPPRESS keeps the global flag's value when it is not given here)."""
    parser = parent.add_parser(name, help=text)
    parser.add_argument("--json", action="store_true", default=argparse.SUPPRESS,
                        help="print results as JSON")
    return parser


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="plenoxd-client", description="Talk to a plenoxd daemon (gRPC API version "
        f"{API_VERSION}).")
    p.add_argument("--version", action="version", version=f"plenoxd-client {API_VERSION}")
    p.add_argument("--server", default=DEFAULT_SERVER, metavar="HOST:PORT",
                   help=f"HOST:PORT of plenoxd (default {DEFAULT_SERVER})")
    p.add_argument("--token-file", metavar="F", help="file with the daemon's bearer token")
    p.add_argument("--tls-ca", metavar="PEM",
                   help="PEM of the CA that signed the daemon's TLS certificate")
    p.add_argument("--timeout", type=float, default=60.0, metavar="S",
                   help="seconds for each single-reply call (default 60; 0 = none)")
    p.add_argument("--version-check", choices=VERSION_CHECKS, default="warn",
                   help="when the daemon's API version differs: warn (default), error, off")
    p.add_argument("--json", action="store_true", help="print results as JSON")
    commands = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    health = _add_command(commands, "health", "SERVING (exit 0) or NOT_SERVING (exit 1)")
    health.add_argument("--service", default="", help="service name ('' = the whole daemon)")
    health.set_defaults(run=cmd_health)

    info = _add_command(commands, "info", "the daemon's version, devices and map count")
    info.set_defaults(run=cmd_info)

    maps = _add_command(commands, "maps", "list the daemon's maps, or create|get|save|load|"
                        "delete one")
    maps.set_defaults(run=cmd_maps)
    actions = maps.add_subparsers(dest="action", metavar="ACTION")
    _add_command(actions, "list", "every map (the default)")
    for name, text in (("create", "a new, empty map"), ("get", "one map's info"),
                       ("save", "write it to the daemon's data directory"),
                       ("load", "read <data-dir>/NAME.plx back"),
                       ("delete", "drop it (and its saved file)")):
        action = _add_command(actions, name, text)
        action.add_argument("name", metavar="NAME")
        if name == "create":
            action.add_argument("--voxel-size", type=float, default=0.0,
                                help="metres (0 = the daemon's default)")

    slam = _add_command(commands, "slam", "online SLAM of a TUM-layout sequence into a map")
    slam.add_argument("map", metavar="MAP", help="created by the daemon when missing")
    slam.add_argument("--dataset", required=True, help="sequence folder in the TUM layout")
    slam.add_argument("--voxel-size", type=float, default=0.0,
                      help="metres, for a new map (0 = the daemon's default)")
    slam.add_argument("--iterations", type=int, default=0,
                      help="mapping iterations per keyframe (0 = the daemon's default)")
    slam.add_argument("--rays", type=int, default=0, help="tracking rays per frame (0 = default)")
    slam.add_argument("--deterministic", action="store_true",
                      help="map each keyframe before the next frame (repeatable runs)")
    slam.add_argument("--streaming", action="store_true",
                      help="send frames without waiting for each update (default: lock-step)")
    slam.add_argument("--fps", type=float, default=0.0,
                      help="with --streaming: pace frames like a camera")
    slam.add_argument("--realtime", action="store_true",
                      help="the daemon keeps the newest frame when it falls behind")
    slam.add_argument("--max-frames", type=int, default=0, help="only the first N frames")
    slam.add_argument("--save", action="store_true", help="SaveMap once the stream is done")
    slam.add_argument("--out", help="TUM trajectory to write (default MAP_slam.txt)")
    slam.add_argument("--progress", action="store_true", help="a line per frame on stderr")
    slam.set_defaults(run=cmd_slam)

    export = _add_command(commands, "export", "write a map as PLY points (or a mesh)")
    export.add_argument("map", metavar="MAP")
    export.add_argument("--out", required=True, help="PLY file to write")
    export.add_argument("--mesh", action="store_true", help="a triangle mesh, not points")
    export.add_argument("--min-density", type=float, default=0.0,
                        help="points: leave out voxels below this density")
    export.set_defaults(run=cmd_export)
    return p


def _show_warning(message: Any, category: Any, filename: str, lineno: int,
                  file: Any = None, line: Optional[str] = None) -> None:
    print(f"plenoxd-client: warning: {message}", file=sys.stderr)


def main(argv: Optional[Sequence[str]] = None) -> int:
    args = _parser().parse_args(argv)
    token = None
    if args.token_file:
        try:
            with open(args.token_file, encoding="utf-8") as f:
                token = f.read().strip()
        except OSError as e:
            print(f"plenoxd-client: --token-file: {e}", file=sys.stderr)
            return 2
    with warnings.catch_warnings():
        # A version warning is for the person running the script: one plain line.
        warnings.simplefilter("always", PlenoxdVersionWarning)
        warnings.showwarning = _show_warning
        try:
            with Client(args.server, token=token, root_certificates=args.tls_ca,
                        timeout=args.timeout or None, version_check=args.version_check) as c:
                return args.run(c, args)
        except PlenoxdError as e:
            print(f"plenoxd-client: {e}", file=sys.stderr)
            return 1
        except OSError as e:  # --tls-ca or --out unreadable / unwritable
            print(f"plenoxd-client: {e}", file=sys.stderr)
            return 2


if __name__ == "__main__":
    sys.exit(main())
