#!/usr/bin/env python3
"""Map and track a TUM-layout RGB-D sequence with a running plenoxd.

    <venv>/bin/python clients/python/examples/track_sequence.py \\
        --server 127.0.0.1:50051 --dataset ../shared/data/tum_fr3_teddy --map teddy

Starts nothing: it talks to the daemon at --server. It creates the map if needed, integrates
every --every'th frame with its ground-truth pose (when the map has no keyframes yet), tracks
every frame in lock-step starting from the first frame's ground-truth pose, writes the estimates
as a TUM trajectory ("timestamp tx ty tz qx qy qz qw") and prints the absolute trajectory error
against the ground truth (RMSE of the position differences, no alignment).
"""

import argparse
import os
import sys
import time

from example_common import add_common_arguments, make_client, print_ate
from plenoxd_client import PlenoxdError, TumDataset, convert, state_name
from plenoxd_client.trajectory import write_tum_trajectory


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_common_arguments(p)
    p.add_argument("--every", type=int, default=10, help="integrate every N'th frame (10)")
    p.add_argument("--iterations", type=int, default=0,
                   help="optimisation iterations per keyframe (0 = the server default)")
    p.add_argument("--rays", type=int, default=0, help="tracking rays per frame (0 = default)")
    p.add_argument("--reintegrate", action="store_true",
                   help="integrate keyframes even when the map already has some")
    p.add_argument("--out", help="trajectory file to write (default: <map>_trajectory.txt)")
    return p.parse_args(argv)


def main(argv=None):
    args = parse_args(sys.argv[1:] if argv is None else argv)
    sequence = TumDataset(args.dataset)
    frames = sequence[:args.max_frames] if args.max_frames > 0 else sequence[:]
    if not sequence.has_groundtruth or frames[0].pose is None:
        print(f"{args.dataset}: mapping needs ground-truth poses (groundtruth.txt)",
              file=sys.stderr)
        return 2
    k = sequence.intrinsics
    print(f"{sequence.name}: {len(frames)} frames {k.width}x{k.height}, "
          f"keyframes every {args.every}")

    with make_client(args) as client:
        try:
            client.wait_ready(timeout=10.0)
            try:
                info = client.get_map(args.map)
                print(f"map {args.map}: exists ({info.keyframes} keyframes, {info.bricks} bricks)")
            except PlenoxdError as e:
                if e.code_name != "NOT_FOUND":
                    raise
                info = client.create_map(args.map, voxel_size=args.voxel_size)
                print(f"map {args.map}: created (voxel {info.voxel_size:g} m)")

            if info.keyframes == 0 or args.reintegrate:
                keyframes = [f for f in frames[::args.every] if f.pose is not None]
                options = {"iterations_per_keyframe": args.iterations}
                start = time.monotonic()
                last = None
                for last in client.integrate(args.map, keyframes, options):
                    # The final (done) message carries no training batch, hence no PSNR.
                    psnr = f", psnr {last.train_psnr:.1f} dB" if last.train_psnr > 0 else ""
                    print(f"  mapping: {last.keyframes_integrated}/{len(keyframes)} keyframes, "
                          f"{last.iterations} iterations{psnr}" + (" (done)" if last.done else ""),
                          flush=True)
                if last is None or not last.done:
                    print("mapping ended without done=true", file=sys.stderr)
                    return 1
                print(f"mapped {last.keyframes_integrated} keyframes in "
                      f"{time.monotonic() - start:.1f} s (map version {last.map_version})")

            options = {"rays": args.rays} if args.rays else None
            estimates, states = {}, {}
            start = time.monotonic()
            stream = client.track(args.map, frames, initial_pose=frames[0].pose, lockstep=True,
                                  options=options)
            for e in stream:
                estimates[e.timestamp] = convert.pose_from_proto(e.pose)
                states[state_name(e)] = states.get(state_name(e), 0) + 1
            seconds = time.monotonic() - start
        except PlenoxdError as e:
            print(f"error: {e}", file=sys.stderr)
            return 1

    out = args.out or f"{args.map}_trajectory.txt"
    write_tum_trajectory(out, estimates)
    print(f"tracked {len(estimates)} frames in {seconds:.1f} s "
          f"({1000.0 * seconds / max(1, len(estimates)):.0f} ms/frame), states "
          + ", ".join(f"{k}={v}" for k, v in sorted(states.items())))
    print(f"trajectory: {os.path.abspath(out)}")
    print_ate(estimates, sequence.groundtruth())
    return 0


if __name__ == "__main__":
    sys.exit(main())
