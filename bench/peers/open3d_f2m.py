#!/usr/bin/python3
"""Open3D frame-to-model tracking peer for the localisation benchmark (bench/README.md).

The map is an Open3D 0.16 TSDF (o3d.t.geometry.VoxelBlockGrid on CPU:0, 1 cm voxels) fused
from every K-th frame (0, K, 2K, ...) at its ground-truth pose, with open3d_tsdf.py's
integration. Then every frame from frame 1 on is tracked against that fixed map, starting
from frame 0's ground-truth pose:

1. ray-cast the TSDF at the previous frame's estimated pose (depth, colour, vertex and normal
   maps), then
2. --method icp (default): point-to-plane ICP (legacy o3d.pipelines.registration.
   registration_icp) of the frame's depth, back-projected and voxel-downsampled, against the
   ray-cast vertices and normals; or
   --method odometry: o3d.pipelines.odometry.compute_rgbd_odometry (hybrid Jacobian) of the
   frame against the ray-cast RGB-D image.

It writes the trajectory as a TUM file ('t tx ty tz qx qy qz qw', camera-to-world) stamped
with each frame's RGB timestamp. Run it with Debian's interpreter:

    OMP_WAIT_POLICY=passive /usr/bin/python3 bench/peers/open3d_f2m.py \
        --dataset ../shared/data/tum_fr3_teddy --out /tmp/f2m.txt [--method odometry] --json

The last stdout line is one JSON object when --json is given. Progress goes to stderr.
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
    sys.exit("open3d_f2m.py: %s. Run it with /usr/bin/python3 (Debian's python3-open3d, "
             "python3-opencv)." % exc)

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from bench_common import (ASSOC_MAX_DT, GroundTruth, load_rgbd, percentile,  # noqa: E402
                          read_frames, read_intrinsics, write_tum)
import open3d_odometry as odo  # noqa: E402
import open3d_tsdf as tsdf  # noqa: E402

RAY_CAST_DEPTH_MIN = 0.1  # m, as in open3d_tsdf.py


def log(msg):
    print("[open3d_f2m] " + msg, file=sys.stderr, flush=True)


def frame_cloud(depth, intr, depth_max, voxel):
    """The frame's depth back-projected to a camera-frame point cloud (z <= depth_max),
    voxel-downsampled (voxel > 0)."""
    cam = odo.pinhole(intr)
    pcd = o3d.geometry.PointCloud.create_from_depth_image(
        o3d.geometry.Image(depth), cam, np.eye(4), depth_scale=intr["depth_scale"],
        depth_trunc=depth_max, stride=1, project_valid_depth_only=True)
    return pcd.voxel_down_sample(voxel) if voxel > 0 else pcd


def model_cloud(render, pose, voxel):
    """The ray-cast vertex and normal maps (camera frame of the render) as a world-frame
    point cloud with normals, voxel-downsampled (voxel > 0)."""
    z = render["depth"].numpy()[:, :, 0]
    vert = render["vertex"].numpy().reshape(-1, 3)
    nrm = render["normal"].numpy().reshape(-1, 3)
    ok = (z.reshape(-1) > 0) & np.isfinite(vert).all(axis=1) & np.isfinite(nrm).all(axis=1)
    ok &= np.linalg.norm(nrm, axis=1) > 0.5
    R, t = pose[:3, :3], pose[:3, 3]
    pcd = o3d.geometry.PointCloud()
    pcd.points = o3d.utility.Vector3dVector((vert[ok].astype(np.float64) @ R.T) + t)
    pcd.normals = o3d.utility.Vector3dVector(nrm[ok].astype(np.float64) @ R.T)
    if voxel > 0:
        pcd = pcd.voxel_down_sample(voxel)  # averages points and normals per voxel
        pcd.normalize_normals()
    return pcd


def render_rgbd(render, depth_scale, depth_max):
    """The ray-cast depth and colour as a legacy RGBDImage for compute_rgbd_odometry."""
    z = render["depth"].numpy()[:, :, 0] / depth_scale  # ray_cast returns z * depth_scale
    z = np.ascontiguousarray(np.where(np.isfinite(z), z, 0.0).astype(np.float32))
    rgb = np.nan_to_num(render["color"].numpy(), nan=0.0, posinf=0.0, neginf=0.0)
    rgb8 = np.ascontiguousarray(np.clip(rgb * 255.0 + 0.5, 0, 255).astype(np.uint8))
    return o3d.geometry.RGBDImage.create_from_color_and_depth(
        o3d.geometry.Image(rgb8), o3d.geometry.Image(z), depth_scale=1.0,
        depth_trunc=depth_max, convert_rgb_to_intensity=True)


def main():
    faulthandler.enable()  # a crash inside Open3D then leaves a Python stack on stderr
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dataset", required=True, help="TUM-layout sequence folder")
    ap.add_argument("--out", required=True, help="TUM trajectory file to write")
    ap.add_argument("--method", choices=["icp", "odometry"], default="icp",
                    help="frame-to-model alignment: point-to-plane ICP against the ray-cast "
                         "vertices (default) or RGB-D odometry against the ray-cast image")
    ap.add_argument("--every", type=int, default=10,
                    help="map keyframe stride K: frames 0, K, 2K, ... (default 10)")
    ap.add_argument("--voxel-size", type=float, default=0.01,
                    help="TSDF voxel edge in metres (default 0.01)")
    ap.add_argument("--map-depth-max", type=float, default=10.0,
                    help="TSDF integration depth limit in metres (default 10, as in the "
                         "mapping benchmark's open3d_tsdf.py)")
    ap.add_argument("--trunc-voxel-multiplier", type=float, default=8.0,
                    help="SDF truncation in voxels (default 8, Open3D's default)")
    ap.add_argument("--weight-threshold", type=float, default=1.0,
                    help="ray_cast min voxel weight (default 1, as in open3d_tsdf.py)")
    ap.add_argument("--icp-voxel", type=float, default=0.02,
                    help="ICP: voxel-downsampling of the frame's cloud and of the ray-cast "
                         "model cloud, metres (default 0.02; 0 = none)")
    ap.add_argument("--icp-max-distance", type=float, default=0.05,
                    help="ICP: max correspondence distance in metres (default 0.05)")
    ap.add_argument("--icp-iterations", type=int, default=30,
                    help="ICP: max iterations (default 30, Open3D's default)")
    ap.add_argument("--icp-min-fitness", type=float, default=0.3,
                    help="ICP: the frame counts as lost when fewer than this fraction of its "
                         "points have a model point within --icp-max-distance after ICP "
                         "(default 0.3)")
    odo.add_common_args(ap)  # --depth-max (frame depth used for tracking) and odometry's
    ap.add_argument("--on-failure", choices=["previous", "identity"], default="previous",
                    help="motion used when a frame is lost: the previous frame's relative "
                         "motion (constant velocity, default) or none (identity)")
    ap.add_argument("--max-frames", type=int, default=0,
                    help="track only the first N frames (0 = all; for quick checks)")
    ap.add_argument("--json", action="store_true", help="print one JSON object last")
    args = ap.parse_args()
    if args.every < 1:
        ap.error("--every must be >= 1")

    system = "open3d_f2m_" + args.method
    dataset = os.path.abspath(args.dataset)
    name = os.path.basename(dataset.rstrip("/"))
    intr = read_intrinsics(dataset)
    frames = read_frames(dataset)
    if args.max_frames > 0:
        frames = frames[:args.max_frames]
    if not frames:
        sys.exit("open3d_f2m.py: no frames in %s" % dataset)
    gt = GroundTruth(os.path.join(dataset, "groundtruth.txt"))
    pose0 = gt.pose(frames[0][0])
    if pose0 is None:
        sys.exit("open3d_f2m.py: frame 0 has no ground-truth pose within %.0f ms"
                 % (ASSOC_MAX_DT * 1e3))

    # --- map: keyframes at ground-truth poses (not timed as tracking) ---------------------
    key_ids, key_poses, missing = [], {}, []
    for i in range(0, len(frames), args.every):
        T = gt.pose(frames[i][0])
        if T is None:
            missing.append(i)
        else:
            key_ids.append(i)
            key_poses[i] = T
    if missing:
        log("no ground-truth pose within %.0f ms for keyframes %s; they are not mapped"
            % (ASSOC_MAX_DT * 1e3, missing))
    log("%s: %d frames, mapping %d keyframes (every %d), voxel %.4g m, map depth_max %g m"
        % (name, len(frames), len(key_ids), args.every, args.voxel_size, args.map_depth_max))
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    vbg, built = tsdf.build_tsdf(frames, key_ids, key_poses, intr, args.voxel_size,
                                 args.map_depth_max, args.trunc_voxel_multiplier, 0, log=log)
    block_coords = tsdf.active_block_coords(vbg)
    K_t = tsdf.intrinsic_tensor(intr)
    ds = intr["depth_scale"]
    attrs = (["depth", "vertex", "normal"] if args.method == "icp" else ["depth", "color"])
    if args.method == "icp":
        log("tracking: ray-cast + point-to-plane ICP, frame voxel %g m, max distance %g m, "
            "%d iterations, depth_max %g m" % (args.icp_voxel, args.icp_max_distance,
                                              args.icp_iterations, args.depth_max))
        criteria = o3d.pipelines.registration.ICPConvergenceCriteria(
            max_iteration=args.icp_iterations)
        estimation = o3d.pipelines.registration.TransformationEstimationPointToPlane()
    else:
        log("tracking: ray-cast + RGB-D odometry (%s Jacobian, iterations %s), depth_max %g m"
            % (args.jacobian, args.iterations, args.depth_max))
        cam = odo.pinhole(intr)
        option = odo.odometry_option(args.iterations, args.depth_diff_max, args.depth_min,
                                     args.depth_max)
        jac = odo.jacobian(args.jacobian)

    # --- tracking --------------------------------------------------------------------------
    poses = [pose0]
    stamps = [frames[0][0]]
    ms, ray_cast_ms, lost_frames, fitness = [], [], [], []
    rel = np.eye(4)  # last relative motion, frame i-1 <- frame i
    for i in range(1, len(frames)):
        depth, rgb = load_rgbd(frames[i], intr)  # PNG decoding: not timed
        prev = poses[-1]
        t0 = time.perf_counter()
        render = vbg.ray_cast(block_coords, K_t,
                              o3d.core.Tensor(np.linalg.inv(prev), o3d.core.Dtype.Float64),
                              intr["width"], intr["height"], attrs, ds, RAY_CAST_DEPTH_MIN,
                              args.map_depth_max, args.weight_threshold,
                              args.trunc_voxel_multiplier, 8)
        t1 = time.perf_counter()
        if args.method == "icp":
            target = model_cloud(render, prev, args.icp_voxel)
            source = frame_cloud(depth, intr, args.depth_max, args.icp_voxel)
            if len(target.points) >= 3 and len(source.points) >= 3:
                reg = o3d.pipelines.registration.registration_icp(
                    source, target, args.icp_max_distance, prev, estimation, criteria)
                ok = reg.fitness >= args.icp_min_fitness
                fitness.append(reg.fitness)
                new = np.asarray(reg.transformation)
            else:
                ok, new = False, None
                fitness.append(0.0)
        else:
            target = render_rgbd(render, ds, args.depth_max)
            source = odo.legacy_rgbd(depth, rgb, ds, args.depth_max)
            # source = frame i, target = the render at `prev`: T maps frame-i camera
            # coordinates into the render's, so pose_i = prev T.
            ok, T, _ = o3d.pipelines.odometry.compute_rgbd_odometry(
                source, target, cam, np.eye(4), jac, option)
            new = prev @ np.asarray(T) if ok else None
        t2 = time.perf_counter()
        ms.append(1e3 * (t2 - t0))
        ray_cast_ms.append(1e3 * (t1 - t0))
        if ok:
            rel = np.linalg.inv(prev) @ new
        else:
            lost_frames.append(i)
            if args.on_failure == "identity":
                rel = np.eye(4)
            new = prev @ rel
        poses.append(new)
        stamps.append(frames[i][0])
        if i % 10 == 0 or not ok:
            log("frame %d/%d: %.0f ms (ray cast %.0f ms)%s%s"
                % (i, len(frames) - 1, ms[-1], ray_cast_ms[-1],
                   ", fitness %.2f" % fitness[-1] if fitness else "",
                   "" if ok else " (lost)"))

    write_tum(args.out, stamps, poses)
    result = {
        "system": system,
        "sequence": name,
        "frames": len(poses),
        "tracked_frames": len(ms),
        "ms_per_frame_median": percentile(ms, 50),
        "ms_per_frame_p95": percentile(ms, 95),
        "ms_per_frame_mean": float(np.mean(ms)) if ms else None,
        "ray_cast_ms_median": percentile(ray_cast_ms, 50),
        "lost": len(lost_frames),
        "lost_frames": lost_frames,
        "on_failure": args.on_failure,
        "method": args.method,
        "keyframes": len(key_ids),
        "every": args.every,
        "voxel_size": args.voxel_size,
        "map_depth_max": args.map_depth_max,
        "weight_threshold": args.weight_threshold,
        "map_integrate_seconds": built["integrate_seconds"],
        "depth_max": args.depth_max,
        "trajectory": os.path.abspath(args.out),
        "open3d": o3d.__version__,
    }
    if args.method == "icp":
        result.update({
            "icp_voxel": args.icp_voxel, "icp_max_distance": args.icp_max_distance,
            "icp_iterations": args.icp_iterations, "icp_min_fitness": args.icp_min_fitness,
            "icp_fitness_median": percentile(fitness, 50),
            "icp_fitness_min": min(fitness) if fitness else None})
    else:
        result.update({
            "depth_min": args.depth_min, "depth_diff_max": args.depth_diff_max,
            "iterations": args.iterations, "jacobian": args.jacobian})
    print("%s %s: %d frames against %d keyframes, %s ms/frame median, %s ms p95, %d lost -> %s"
          % (system, name, len(poses), len(key_ids),
             "n/a" if not ms else "%.0f" % result["ms_per_frame_median"],
             "n/a" if not ms else "%.0f" % result["ms_per_frame_p95"], len(lost_frames),
             args.out), flush=True)
    if args.json:
        print(json.dumps(result), flush=True)


if __name__ == "__main__":
    main()
