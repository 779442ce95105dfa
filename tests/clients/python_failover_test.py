#!/usr/bin/env python3
"""The installed plenoxd_client riding through a failover, against real plenoxd processes
(issue 24, part 5): a daemon killed with SIGKILL and a new one started on the same port and
data directory.

    <venv>/bin/python tests/clients/python_failover_test.py --plenoxd <plenoxd> \\
      --plenox <plenox> [--installed-in <venv>]

1. Unary calls: CreateMap is not repeated while the daemon is down (UNAVAILABLE at once);
   list_maps() and health() made while it is down return once the new daemon serves the port.
2. A Slam stream (lock-step, deterministic) cut by a SIGKILL mid-walk reconnects, relocalises
   in the map reloaded from its snapshot, and finishes with the done message: reconnects == 1,
   at most the frame in flight lost, and the poses after the reconnect within the bound the
   C++ CLI test (remote_failover_test.cc) holds them to.
Exits 0 when everything passed, 1 with a list of failures otherwise, 77 (skip) when this
interpreter has no grpc/numpy.
"""

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
import traceback

try:
    import grpc
    import numpy as np
except ImportError as missing:
    print(f"SKIP: {sys.executable} cannot import grpc/numpy ({missing}); "
          "install Debian's python3-grpcio and python3-numpy")
    sys.exit(77)

import plenoxd_client
from plenoxd_client import Client, PlenoxdError, TumDataset, slam_pose

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from python_client_test import Daemon  # noqa: E402  (the same daemon helper)

FRAMES, WIDTH, HEIGHT = 60, 96, 72
VOXEL_SIZE = 0.04
KILL_AT_FRAME = 30  # the walk is killed after this many updates, with a snapshot on disk


def check(failures, condition, what):
    print(f"  [{'ok  ' if condition else 'FAIL'}] {what}", flush=True)
    if not condition:
        failures.append(what)
    return condition


# The daemons of python_client_test (the same start, port discovery and log), here on one data
# directory and, for a restart in place, one address: snapshots every 0.5 s, the CPU backend.
DAEMON_ARGS = ["--snapshot-seconds", "0.5", "--backend", "cpu", "--threads", "2"]


def start_daemon(binary, work, name, data_dir, listen="127.0.0.1:0"):
    return Daemon(binary, work, name, DAEMON_ARGS, data_dir=data_dir, listen=listen)


def position_rmse(pairs, groundtruth):
    """Position RMSE over (timestamp, t) pairs with a ground-truth pose; (rmse, matched)."""
    errors = [np.linalg.norm(np.asarray(t) - groundtruth[ts][0]) for ts, t in pairs
              if ts in groundtruth]
    if not errors:
        return float("inf"), 0
    return float(np.sqrt(np.mean(np.square(errors)))), len(errors)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--plenoxd", required=True)
    parser.add_argument("--plenox", required=True)
    parser.add_argument("--installed-in", help="the venv the package must be imported from")
    parser.add_argument("--keep", action="store_true", help="keep the work folder")
    args = parser.parse_args()
    if args.installed_in:
        where = os.path.realpath(plenoxd_client.__file__)
        if not where.startswith(os.path.realpath(args.installed_in) + os.sep):
            print(f"plenoxd_client imported from {where}, not from {args.installed_in}")
            return 1

    failures = []
    work = tempfile.mkdtemp(prefix="plenoxd_py_failover_")
    data = os.path.join(work, "data")
    os.makedirs(data)
    daemons = []
    try:
        sequence = os.path.join(work, "sequence")
        synth = subprocess.run(
            [args.plenox, "synth", "--out", sequence, "--frames", str(FRAMES), "--width",
             str(WIDTH), "--height", str(HEIGHT)], capture_output=True, text=True, timeout=120)
        if not check(failures, synth.returncode == 0, "plenox synth writes the sequence"):
            print(synth.stdout, synth.stderr)
            return 1
        seq = TumDataset(sequence)
        frames = seq[:]
        groundtruth = seq.groundtruth()

        first = start_daemon(args.plenoxd, work, "first", data)
        daemons.append(first)
        listen = first.target
        client = Client(first.target, retry_seconds=30.0)

        print("unary calls across a restart")
        client.create_map("kept", voxel_size=VOXEL_SIZE)
        client.save_map("kept")
        first.kill()
        began = time.monotonic()
        try:
            client.create_map("other", voxel_size=VOXEL_SIZE)
            check(failures, False, "create_map while the daemon is down raises")
        except PlenoxdError as e:
            check(failures, e.code == grpc.StatusCode.UNAVAILABLE
                  and time.monotonic() - began < 2.0,
                  f"create_map is not repeated: UNAVAILABLE at once (got {e.code_name} after "
                  f"{time.monotonic() - began:.1f} s)")
        restarted = []

        def restart(after):
            time.sleep(after)
            restarted.append(start_daemon(args.plenoxd, work, f"second{len(restarted)}", data,
                                    listen))

        thread = threading.Thread(target=restart, args=(1.5,))
        began = time.monotonic()
        thread.start()
        names = [m.name for m in client.list_maps()]
        waited = time.monotonic() - began
        thread.join()
        daemons.extend(restarted)
        check(failures, names == ["kept"] and 1.5 <= waited < 30.0,
              f"list_maps while the daemon restarts: waits {waited:.1f} s for it, then answers "
              f"({names})")
        check(failures, client.health(), "health() after the restart: SERVING")

        print("a Slam stream across a kill -9")
        second = restarted[0]
        stream = client.slam("room", frames, initial_pose=frames[0].pose,
                             options={"voxel_size": VOXEL_SIZE, "deterministic": True})
        updates = []
        killed_at = None
        kill_index = 0
        third = []
        for update in stream:
            updates.append(update)
            if killed_at is None and len(updates) >= KILL_AT_FRAME and os.path.exists(
                    os.path.join(data, "room.plx")):
                second.kill()
                killed_at = time.monotonic()
                kill_index = len(updates)
                # The replacement comes up while the stream waits for it.
                threading.Thread(target=lambda: third.append(
                    start_daemon(args.plenoxd, work, "third", data, listen))).start()
        while killed_at is not None and not third and time.monotonic() - killed_at < 30:
            time.sleep(0.1)
        daemons.extend(third)
        check(failures, killed_at is not None, "the daemon was killed mid-walk")
        lost = stream.frames_lost
        check(failures, stream.reconnects == 1 and 0 <= lost <= 1,
              f"one reconnect, at most the frame in flight lost (reconnects "
              f"{stream.reconnects}, frames_lost {lost})")
        check(failures, len(updates) + lost == FRAMES and stream.received == len(updates)
              and stream.sent == FRAMES,
              f"every frame answered or lost ({len(updates)} updates, {lost} lost, "
              f"{stream.sent} sent)")
        check(failures, stream.done is not None and stream.done.mapping.finished,
              "the new stream ends with the done message")
        check(failures, stream.resume_seconds is not None and stream.resume_seconds < 30,
              f"tracking again {stream.resume_seconds} s after the break")
        after = updates[kill_index:]
        rmse, matched = position_rmse([(u.timestamp, slam_pose(u)[0]) for u in after],
                                      groundtruth)
        check(failures, matched == len(after) and rmse < 0.02,
              f"after the reconnect: position RMSE {100 * rmse:.2f} cm < 2 cm over {matched} "
              "frames")
        info = client.get_map("room")
        check(failures, info.keyframes >= stream.done.mapping.keyframes if stream.done else False,
              f"the map has the new stream's keyframes ({info.keyframes})")
        for d in daemons:
            if d.proc.poll() is None:
                code = d.stop()
                check(failures, code == 0, f"{d.name}: SIGTERM -> exit 0 (got {code})")
    except Exception:  # noqa: BLE001
        check(failures, False, f"raised\n{traceback.format_exc()}")
    finally:
        for d in daemons:
            if d.proc.poll() is None:
                d.kill()
        if failures:
            for d in daemons:
                print(f"--- {d.name} log (tail) ---\n{d.log_tail()}")
        if args.keep or failures:
            print(f"work folder kept: {work}")
        else:
            shutil.rmtree(work, ignore_errors=True)
    if failures:
        print(f"{len(failures)} check(s) FAILED")
        return 1
    print("all checks passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
