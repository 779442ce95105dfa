#!/usr/bin/python3
"""Map and track a TUM-layout RGB-D sequence with a running plenoxd.

    PYTHONPATH=<build>/clients/python/gen:<repo>/clients/python \\
      /usr/bin/python3 clients/python/examples/track_sequence.py \\
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

import numpy as np

from plenoxd_client import Client, PlenoxdError, TumDataset, convert, state_name


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--server", required=True, help="HOST:PORT of plenoxd")
    p.add_argument("--dataset", required=True, help="sequence folder in the TUM layout")
    p.add_argument("--map", required=True, help="map name ([A-Za-z0-9_.-], 1-64 characters)")
    p.add_argument("--token-file", help="file with the daemon's bearer token")
    p.add_argument("--root-cert", help="PEM of the CA that signed the daemon's TLS certificate")
    p.add_argument("--every", type=int, default=10, help="integrate every N'th frame (10)")
    p.add_argument("--voxel-size", type=float, default=0.0,
                   help="voxel size in metres for a new map (0 = the server default)")
    p.add_argument("--iterations", type=int, default=0,
                   help="optimisation iterations per keyframe (0 = the server default)")
    p.add_argument("--rays", type=int, default=0, help="tracking rays per frame (0 = default)")
    p.add_argument("--max-frames", type=int, default=0, help="use only the first N frames")
    p.add_argument("--reintegrate", action="store_true",
                   help="integrate keyframes even when the map already has some")
    p.add_argument("--out", help="trajectory file to write (default: <map>_trajectory.txt)")
    return p.parse_args(argv)


def ate(estimates, groundtruth):
    """RMSE, mean and max position error (metres) over the timestamps both have."""
    errors = [np.linalg.norm(t - groundtruth[ts][0]) for ts, (t, _) in estimates.items()
              if ts in groundtruth]
    if not errors:
        return None
    e = np.array(errors)
    return {"rmse": float(np.sqrt(np.mean(e ** 2))), "mean": float(e.mean()),
            "max": float(e.max()), "matched": len(e)}


def write_tum_trajectory(path, estimates):
    with open(path, "w", encoding="utf-8") as f:
        f.write("# timestamp tx ty tz qx qy qz qw\n")
        for ts in sorted(estimates):
            t, q = estimates[ts]
            f.write(f"{ts:.6f} " + " ".join(f"{v:.9f}" for v in (*t, *q)) + "\n")


def main(argv=None):
    args = parse_args(sys.argv[1:] if argv is None else argv)
    token = None
    if args.token_file:
        with open(args.token_file, "r", encoding="utf-8") as f:
            token = f.read().strip()
    sequence = TumDataset(args.dataset)
    frames = sequence[:args.max_frames] if args.max_frames > 0 else sequence[:]
    if not sequence.has_groundtruth or frames[0].pose is None:
        print(f"{args.dataset}: mapping needs ground-truth poses (groundtruth.txt)",
              file=sys.stderr)
        return 2
    k = sequence.intrinsics
    print(f"{sequence.name}: {len(frames)} frames {k.width}x{k.height}, "
          f"keyframes every {args.every}")

    with Client(args.server, token=token, root_certificates=args.root_cert) as client:
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
    error = ate(estimates, sequence.groundtruth())
    if error is None:
        print("ATE: no ground truth to compare with")
    else:
        print(f"ATE (no alignment, {error['matched']} frames): rmse {100 * error['rmse']:.2f} cm, "
              f"mean {100 * error['mean']:.2f} cm, max {100 * error['max']:.2f} cm")
    return 0


if __name__ == "__main__":
    sys.exit(main())
