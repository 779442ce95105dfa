#!/usr/bin/env python3
"""Online SLAM of a TUM-layout RGB-D sequence with a running plenoxd.

    <venv>/bin/python clients/python/examples/slam_sequence.py \\
        --server 127.0.0.1:50051 --dataset ../shared/data/tum_fr3_teddy --map teddy_slam

Starts nothing: it talks to the daemon at --server. It streams every frame without its pose
into map --map (the daemon creates it when it does not exist) in lock-step, starting from the
first frame's ground-truth pose when the sequence has one, so that the trajectory is in the
ground truth's frame. It waits for the daemon's done message (for the last stream on the map,
after the mapping job finished), optionally saves the map in the daemon's data directory,
writes the poses as a TUM trajectory ("timestamp tx ty tz qx qy qz qw") and prints the
absolute trajectory error against the ground truth (RMSE of the position differences, no
alignment). No other ground truth is used.
"""

import argparse
import os
import sys
import time

from example_common import add_common_arguments, make_client, print_ate
from plenoxd_client import PlenoxdError, TumDataset, slam_pose, slam_state_name
from plenoxd_client.trajectory import write_tum_trajectory


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_common_arguments(p)
    p.add_argument("--iterations-per-keyframe", type=int, default=0,
                   help="mapping iterations each keyframe adds (0 = the server default)")
    p.add_argument("--rays", type=int, default=0, help="tracking rays per frame (0 = default)")
    p.add_argument("--deterministic", action="store_true",
                   help="the daemon maps each keyframe before the next frame (repeatable runs)")
    p.add_argument("--save", action="store_true",
                   help="save the map in the daemon's data directory at the end")
    p.add_argument("--out", help="trajectory file to write (default: <map>_slam.txt)")
    return p.parse_args(argv)


def main(argv=None):
    args = parse_args(sys.argv[1:] if argv is None else argv)
    sequence = TumDataset(args.dataset)
    frames = sequence[:args.max_frames] if args.max_frames > 0 else sequence[:]
    if not frames:
        print(f"{args.dataset}: no frames", file=sys.stderr)
        return 2
    start_pose = frames[0].pose  # None without ground truth: the daemon starts at the identity
    k = sequence.intrinsics
    print(f"{sequence.name}: {len(frames)} frames {k.width}x{k.height}, starting at "
          + ("frame 0's ground-truth pose" if start_pose is not None else "the identity"))
    options = {"voxel_size": args.voxel_size,
               "iterations_per_keyframe": args.iterations_per_keyframe,
               "tracking": {"rays": args.rays},
               "deterministic": args.deterministic}

    estimates, states = {}, {}
    with make_client(args) as client:
        try:
            client.wait_ready(timeout=10.0)
            start = time.monotonic()
            # Lock-step: one frame out, its update back. Ground-truth poses are not sent.
            stream = client.slam(args.map, frames, initial_pose=start_pose, options=options)
            for update in stream:
                estimates[update.timestamp] = slam_pose(update)
                state = slam_state_name(update)
                states[state] = states.get(state, 0) + 1
                if update.keyframe or state != "OK" or stream.received % 50 == 0:
                    note = " keyframe" if update.keyframe else ""
                    reason = f" ({update.reason})" if update.reason else ""
                    print(f"  frame {update.frame}: {state}{note}{reason}, "
                          f"{update.latency_ms:.0f} ms, map {update.mapping.keyframes} keyframes",
                          flush=True)
            seconds = time.monotonic() - start
            done = stream.done
            print(f"done: {done.mapping.keyframes} keyframes, {done.mapping.iterations} mapping "
                  f"iterations, version {done.mapping.map_version}, "
                  f"{done.mapping.map_bytes / 1e6:.1f} MB"
                  + ("" if done.mapping.finished else " (other streams still map it)"))
            if args.save:
                info = client.save_map(args.map)
                print(f"saved {args.map}: version {info.version}, {info.keyframes} keyframes")
        except PlenoxdError as e:
            print(f"error: {e}", file=sys.stderr)
            return 1

    out = args.out or f"{args.map}_slam.txt"
    write_tum_trajectory(out, estimates, f"slam_sequence.py: {sequence.name} into {args.map}")
    print(f"processed {len(estimates)} frames in {seconds:.1f} s "
          f"({1000.0 * seconds / max(1, len(estimates)):.0f} ms/frame), {stream.keyframes} "
          "keyframes, states " + ", ".join(f"{k}={v}" for k, v in sorted(states.items())))
    print(f"trajectory: {os.path.abspath(out)}")
    print_ate(estimates, sequence.groundtruth())
    return 0


if __name__ == "__main__":
    sys.exit(main())
