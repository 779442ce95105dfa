#!/usr/bin/python3
"""Open3D frame-to-frame RGB-D odometry peer for the localisation benchmark (bench/README.md).

Tracks every frame of a TUM-layout RGB-D sequence with Open3D 0.16's legacy
o3d.pipelines.odometry.compute_rgbd_odometry (hybrid photometric + geometric Jacobian),
frame i against frame i-1, and chains the relative motions into a trajectory that starts at
frame 0's ground-truth pose. No map is used. It writes the trajectory as a TUM file
('t tx ty tz qx qy qz qw', camera-to-world) stamped with each frame's RGB timestamp.

Run it with Debian's interpreter (/usr/bin/python3: python3-open3d, numpy, python3-opencv):

    OMP_WAIT_POLICY=passive /usr/bin/python3 bench/peers/open3d_odometry.py \
        --dataset ../shared/data/tum_fr3_teddy --out /tmp/odometry.txt --json

The last stdout line is one JSON object when --json is given. Progress goes to stderr.
(The tensor odometry, o3d.t.pipelines.odometry, does not work in Debian's build, which
lacks IPP: research/toolchain.md section 6.)
"""

import argparse
import faulthandler
import json
import os
import sys
import time

# Open3D links libgomp and TBB; on few cores their busy-waiting fights and everything gets
# ~10x slower. The policy is read when libgomp starts, so set it before importing open3d.
os.environ.setdefault("OMP_WAIT_POLICY", "passive")

import numpy as np  # noqa: E402

try:
    import cv2  # noqa: E402,F401  (bench_common.load_rgbd decodes with it)
    import open3d as o3d  # noqa: E402
except ImportError as exc:  # pragma: no cover - depends on the interpreter
    sys.exit("open3d_odometry.py: %s. Run it with /usr/bin/python3 (Debian's python3-open3d, "
             "python3-opencv)." % exc)

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from bench_common import (ASSOC_MAX_DT, GroundTruth, load_rgbd, peak_rss_mb,  # noqa: E402
                          percentile, read_frames, read_intrinsics, write_tum)

SYSTEM = "open3d_odometry"


def log(msg):
    print("[%s] %s" % (SYSTEM, msg), file=sys.stderr, flush=True)


def int_list(text):
    try:
        v = [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError("expected comma-separated integers, got %r" % text)
    if not v or min(v) < 1:
        raise argparse.ArgumentTypeError("expected positive integers, got %r" % text)
    return v


def pinhole(intr):
    return o3d.camera.PinholeCameraIntrinsic(intr["width"], intr["height"], intr["fx"],
                                             intr["fy"], intr["cx"], intr["cy"])


def odometry_option(iterations, depth_diff_max, depth_min, depth_max):
    return o3d.pipelines.odometry.OdometryOption(
        iteration_number_per_pyramid_level=o3d.utility.IntVector(iterations),
        depth_diff_max=depth_diff_max, depth_min=depth_min, depth_max=depth_max)


def jacobian(name):
    if name == "hybrid":
        return o3d.pipelines.odometry.RGBDOdometryJacobianFromHybridTerm()
    return o3d.pipelines.odometry.RGBDOdometryJacobianFromColorTerm()


def legacy_rgbd(depth, rgb, depth_scale, depth_max):
    """Open3D legacy RGBDImage: depth in metres (float), colour as float intensity in [0, 1]
    (what compute_rgbd_odometry expects). Depth beyond depth_max becomes 0 (no measurement)."""
    return o3d.geometry.RGBDImage.create_from_color_and_depth(
        o3d.geometry.Image(rgb), o3d.geometry.Image(depth), depth_scale=depth_scale,
        depth_trunc=depth_max, convert_rgb_to_intensity=True)


def add_common_args(ap):
    """Flags shared with open3d_f2m.py's --method odometry."""
    ap.add_argument("--depth-max", type=float, default=4.0,
                    help="tracking depth limit in metres: the frame's depth beyond it is "
                         "ignored (odometry: in both images) (default 4, OdometryOption's "
                         "default)")
    ap.add_argument("--depth-min", type=float, default=0.0,
                    help="odometry depth lower limit in metres (default 0, Open3D's default)")
    ap.add_argument("--depth-diff-max", type=float, default=0.03,
                    help="odometry correspondence depth gate in metres (default 0.03, "
                         "Open3D's default)")
    ap.add_argument("--iterations", type=int_list, default=[20, 10, 5],
                    help="iterations per pyramid level, fine to coarse (default 20,10,5, "
                         "Open3D's default)")
    ap.add_argument("--jacobian", choices=["hybrid", "color"], default="hybrid",
                    help="Open3D odometry Jacobian (default hybrid: "
                         "RGBDOdometryJacobianFromHybridTerm)")


def main():
    faulthandler.enable()  # a crash inside Open3D then leaves a Python stack on stderr
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dataset", required=True, help="TUM-layout sequence folder")
    ap.add_argument("--out", required=True, help="TUM trajectory file to write")
    add_common_args(ap)
    ap.add_argument("--on-failure", choices=["previous", "identity"], default="previous",
                    help="relative motion used when odometry reports failure: the previous "
                         "frame's (constant velocity, default) or the identity")
    ap.add_argument("--init", choices=["identity", "previous"], default="identity",
                    help="odometry initial guess: identity (default, Open3D's default "
                         "odo_init) or the previous relative motion")
    ap.add_argument("--max-frames", type=int, default=0,
                    help="track only the first N frames (0 = all; for quick checks)")
    ap.add_argument("--json", action="store_true", help="print one JSON object last")
    args = ap.parse_args()

    dataset = os.path.abspath(args.dataset)
    name = os.path.basename(dataset.rstrip("/"))
    intr = read_intrinsics(dataset)
    frames = read_frames(dataset)
    if args.max_frames > 0:
        frames = frames[:args.max_frames]
    if len(frames) < 1:
        sys.exit("open3d_odometry.py: no frames in %s" % dataset)
    gt = GroundTruth(os.path.join(dataset, "groundtruth.txt"))
    pose0 = gt.pose(frames[0][0])
    if pose0 is None:
        sys.exit("open3d_odometry.py: frame 0 has no ground-truth pose within %.0f ms"
                 % (ASSOC_MAX_DT * 1e3))
    ds = intr["depth_scale"]
    log("%s: %d frames, %dx%d, depth_max %g m, iterations %s, %s Jacobian, on failure: %s"
        % (name, len(frames), intr["width"], intr["height"], args.depth_max,
           args.iterations, args.jacobian, args.on_failure))

    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    cam = pinhole(intr)
    option = odometry_option(args.iterations, args.depth_diff_max, args.depth_min,
                             args.depth_max)
    jac = jacobian(args.jacobian)

    poses = [pose0]
    stamps = [frames[0][0]]
    ms, lost_frames = [], []
    rel = np.eye(4)  # last relative motion, frame i-1 <- frame i (camera coordinates)
    wall0 = time.perf_counter()  # wall clock: the whole loop, PNG decoding included
    depth, rgb = load_rgbd(frames[0], intr)
    prev = legacy_rgbd(depth, rgb, ds, args.depth_max)
    for i in range(1, len(frames)):
        depth, rgb = load_rgbd(frames[i], intr)  # PNG decoding: not timed
        t0 = time.perf_counter()
        cur = legacy_rgbd(depth, rgb, ds, args.depth_max)
        init = rel if args.init == "previous" else np.eye(4)
        # source = frame i, target = frame i-1: T maps frame-i camera coordinates into
        # frame-(i-1) camera coordinates, so pose_i = pose_{i-1} T.
        ok, T, _ = o3d.pipelines.odometry.compute_rgbd_odometry(cur, prev, cam, init, jac,
                                                                option)
        t1 = time.perf_counter()
        ms.append(1e3 * (t1 - t0))
        if ok:
            rel = np.asarray(T)
        else:
            lost_frames.append(i)
            if args.on_failure == "identity":
                rel = np.eye(4)
        poses.append(poses[-1] @ rel)
        stamps.append(frames[i][0])
        prev = cur
        if i % 10 == 0 or not ok:
            log("frame %d/%d: %.0f ms%s" % (i, len(frames) - 1, ms[-1],
                                           "" if ok else " (odometry failed)"))

    wall_s = time.perf_counter() - wall0
    write_tum(args.out, stamps, poses)
    result = {
        "system": SYSTEM,
        "sequence": name,
        "frames": len(poses),
        "tracked_frames": len(ms),
        "ms_per_frame_median": percentile(ms, 50),
        "ms_per_frame_p95": percentile(ms, 95),
        "ms_per_frame_mean": float(np.mean(ms)) if ms else None,
        "fps": len(frames) / wall_s if wall_s > 0 else None,
        "wall_s": wall_s,
        "peak_rss_mb": peak_rss_mb(),
        "map_mb": None,  # no map: frame-to-frame
        "keyframes": None,
        "lost": len(lost_frames),
        "lost_frames": lost_frames,
        "on_failure": args.on_failure,
        "init": args.init,
        "depth_max": args.depth_max,
        "depth_min": args.depth_min,
        "depth_diff_max": args.depth_diff_max,
        "iterations": args.iterations,
        "jacobian": args.jacobian,
        "trajectory": os.path.abspath(args.out),
        "open3d": o3d.__version__,
    }
    print("%s %s: %d frames, %s ms/frame median, %s ms p95, %d lost -> %s"
          % (SYSTEM, name, len(poses), "n/a" if not ms else "%.0f" % result[
              "ms_per_frame_median"], "n/a" if not ms else "%.0f" % result[
              "ms_per_frame_p95"], len(lost_frames), args.out), flush=True)
    if args.json:
        print(json.dumps(result), flush=True)


if __name__ == "__main__":
    main()
