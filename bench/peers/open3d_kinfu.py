#!/usr/bin/python3
"""Open3D KinectFusion-style dense SLAM peer for the SLAM benchmark (bench/README.md).

Tracks and maps a TUM-layout RGB-D sequence at once, in the KinectFusion manner, with Open3D
0.16's tensor API on the CPU:

- Map: a TSDF, o3d.t.geometry.VoxelBlockGrid (tsdf, weight, colour; 1 cm voxels by default).
  Frame 0 is fused at its ground-truth pose; from then on every frame is fused at its
  estimated pose right after it is tracked. No pose other than frame 0's comes from ground
  truth.
- Tracking: the model is ray-cast at the previous frame's estimate (VoxelBlockGrid.ray_cast,
  vertex and normal maps in that camera's frame) over the blocks the previous frame touched,
  as Open3D's own t.pipelines.slam.Model does. The new frame is aligned to that rendering by
  point-to-plane ICP with projective data association, coarse to fine over a 3-level pyramid.

Why the projective point-to-plane step (o3d.t.pipelines.odometry.
compute_odometry_result_point_to_plane) rather than o3d.t.pipelines.registration.icp:

- It is KinectFusion's own alignment. A source pixel is matched to the model pixel it
  projects to, with no nearest-neighbour search, and the matches are gated by depth
  difference. registration.icp matches by nearest neighbour in 3-D (a KD-tree or hybrid
  search per iteration). That is a different, slower algorithm for dense image-aligned data.
- It is the step that o3d.t.pipelines.odometry.rgbd_odometry_multi_scale(Method.
  PointToPlane) iterates. That wrapper cannot run in Debian's build: its pre-processing
  (Image.filter_bilateral, and pyrdown through filter_gaussian) is "not implemented" without
  IPP (shared/research/toolchain.md section 6). This peer runs the same loop itself:
  - levels are made by keeping every 2nd or 4th pixel of the depth and of the ray-cast maps,
    with the intrinsics scaled to match, instead of Gaussian pyramids;
  - the depth is not bilateral-filtered;
  - Open3D's per-level criteria apply: at most N iterations per level (default 10, 5, 3,
    coarse to fine, rgbd_odometry_multi_scale's default), stopping early when the fitness
    and the inlier RMSE change by less than 1e-6 (relative);
  - Open3D's default OdometryLossParams apply: depth_outlier_trunc 0.07 m and
    depth_huber_delta 0.05 m.
  Each call returns an increment, which is applied on the left of the running
  source-to-target estimate, as rgbd_odometry_multi_scale does.

Two corrections to Open3D 0.16's TSDF (both off with --as-shipped). Without them, the
ray-cast model does not sit where the fused depth was. Frame-to-model tracking then chases
that offset, frame after frame:

- Integration reads the depth pixel at the truncated projection of a voxel,
  (int)(fx x/z + cx). That is the pixel to the upper left of the nearest one, so the fused
  surface slides half a pixel. The peer fuses with cx + 0.5 and cy + 0.5, which turns the
  truncation into rounding.
- ray_cast marches with nearest-lower-voxel look-ups (floor of the position) and no
  trilinear interpolation. Voxel i's value belongs to the point i * voxel_size, so the
  surface it finds lies about half a voxel along +x, +y and +z (world) beyond the fused
  one. The peer subtracts (0.5, 0.5, 0.5) * voxel_size (world) from the ray-cast vertices.

On random planes seen from random poses (1 cm voxels, noise-free depth), the mean signed
distance of the ray-cast surface from the true plane is -9 to +9 mm as shipped and under
1 mm with both corrections. The per-pixel scatter, about 4 mm, comes from the
nearest-voxel look-ups and stays. On `plenox synth`'s 60 frames the peer's ATE goes from
8.9 cm to 1.7 cm (depth_max 10 m). On tum_fr3_teddy (depth_max 3 m) it goes from 11.2 cm
(2.3 cm after SE(3) alignment) to 4.9 cm (1.5 cm).

A frame is lost when the final fitness (the share of the frame's pixels with an inlier
match) is below --min-fitness. It is then given the previous frame's relative motion and
is not fused.

It writes the trajectory as a TUM file ('t tx ty tz qx qy qz qw', camera-to-world), stamped
with each frame's RGB timestamp. Run it with Debian's interpreter:

    OMP_WAIT_POLICY=passive /usr/bin/python3 bench/peers/open3d_kinfu.py \
        --dataset ../shared/data/tum_fr3_teddy --out /tmp/kinfu.txt --json

The last stdout line is one JSON object when --json is given. Progress goes to stderr.
"""

import argparse
import faulthandler
import json
import os
import sys
import time

# Open3D links libgomp and TBB. On few cores their busy-waiting fights and everything gets
# ~10x slower (research/toolchain.md section 6). The policy is read when libgomp starts,
# so it must be set before open3d is imported.
os.environ.setdefault("OMP_WAIT_POLICY", "passive")

import numpy as np  # noqa: E402

try:
    import cv2  # noqa: E402,F401  (bench_common.load_rgbd decodes with it)
    import open3d as o3d  # noqa: E402
except ImportError as exc:  # pragma: no cover - depends on the interpreter
    sys.exit("open3d_kinfu.py: %s. Run it with /usr/bin/python3 (Debian's python3-open3d, "
             "python3-opencv)." % exc)

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from bench_common import (ASSOC_MAX_DT, GroundTruth, load_rgbd, peak_rss_mb,  # noqa: E402
                          percentile, read_frames, read_intrinsics, write_tum)
import open3d_tsdf as tsdf  # noqa: E402

SYSTEM = "open3d_kinfu"
RAY_CAST_DEPTH_MIN = 0.1  # m, as in open3d_tsdf.py and open3d_f2m.py
NAN = float("nan")


def log(msg):
    print("[%s] %s" % (SYSTEM, msg), file=sys.stderr, flush=True)


def int_list(text):
    try:
        v = [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError("expected comma-separated integers, got %r" % text)
    if not v or min(v) < 0 or max(v) < 1:
        raise argparse.ArgumentTypeError("expected non-negative integers, got %r" % text)
    return v


def scaled_intrinsics(intr, stride):
    """Intrinsics of the image that keeps every stride-th pixel (pixel k is pixel stride*k of
    the full image; Open3D's pixel centres are at integer coordinates, so fx and cx scale
    exactly)."""
    return o3d.core.Tensor(np.array([[intr["fx"] / stride, 0.0, intr["cx"] / stride],
                                     [0.0, intr["fy"] / stride, intr["cy"] / stride],
                                     [0.0, 0.0, 1.0]]), o3d.core.Dtype.Float64)


def frame_vertex_maps(z, Ks, strides):
    """Camera-frame vertex maps of the frame's depth z (metres, 0 = none) at each stride; NaN
    where there is no depth (the odometry kernel skips NaN vertices)."""
    maps = []
    for K, s in zip(Ks, strides):
        zs = np.ascontiguousarray(z[::s, ::s])
        img = o3d.t.geometry.Image(o3d.core.Tensor(zs))
        maps.append(img.create_vertex_map(K, NAN).as_tensor())
    return maps


def model_maps(render, strides, offset):
    """The ray-cast vertex and normal maps (camera frame of the render) at each stride, NaN
    where the ray hit nothing. offset (camera frame) is subtracted from every vertex."""
    z = render["depth"].numpy()[:, :, 0]
    vert = render["vertex"].numpy() - offset.astype(np.float32)
    nrm = render["normal"].numpy()
    bad = ~((z > 0) & np.isfinite(vert).all(axis=2) & np.isfinite(nrm).all(axis=2)
            & (np.linalg.norm(nrm, axis=2) > 0.5))
    vert = np.where(bad[:, :, None], np.float32(NAN), vert).astype(np.float32)
    nrm = np.where(bad[:, :, None], np.float32(NAN), nrm).astype(np.float32)
    out = []
    for s in strides:
        out.append((o3d.core.Tensor(np.ascontiguousarray(vert[::s, ::s])),
                    o3d.core.Tensor(np.ascontiguousarray(nrm[::s, ::s]))))
    return out, int((~bad).sum())


def align(src_maps, model, Ks, iterations, init, outlier_trunc, huber_delta):
    """Coarse-to-fine projective point-to-plane ICP, as rgbd_odometry_multi_scale runs it.
    Level l uses stride 2**l; iterations[0] is for the coarsest level. Returns
    (source-to-target 4x4, fitness and inlier RMSE of the last step, iterations run)."""
    T = init.copy()
    fitness, rmse, n_it = 1.0, 0.0, 0  # Open3D starts from fitness 1, RMSE 0
    for k, level in enumerate(reversed(range(len(Ks)))):  # coarsest first
        for _ in range(iterations[k]):
            r = o3d.t.pipelines.odometry.compute_odometry_result_point_to_plane(
                src_maps[level], model[level][0], model[level][1], Ks[level],
                o3d.core.Tensor(T, o3d.core.Dtype.Float64), outlier_trunc, huber_delta)
            T = r.transformation.numpy() @ T  # the result is an increment, applied on the left
            n_it += 1
            fit, err = float(r.fitness), float(r.inlier_rmse)
            # Open3D's OdometryConvergenceCriteria defaults: relative changes below 1e-6.
            converged = (fitness > 0 and rmse > 0 and abs(fitness - fit) / fitness < 1e-6
                         and abs(rmse - err) / rmse < 1e-6)
            fitness, rmse = fit, err
            if converged:
                break
    return T, fitness, rmse, n_it


def main():
    faulthandler.enable()  # a crash inside Open3D then leaves a Python stack on stderr
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dataset", required=True, help="TUM-layout sequence folder")
    ap.add_argument("--out", required=True, help="TUM trajectory file to write")
    ap.add_argument("--voxel-size", type=float, default=0.01,
                    help="TSDF voxel edge in metres (default 0.01)")
    ap.add_argument("--depth-max", type=float, default=3.0,
                    help="depth limit in metres for tracking, fusion and ray casting: the "
                         "frame's depth beyond it is ignored (default 3, the depth_max of "
                         "Open3D's dense SLAM example; rendered sequences whose walls are "
                         "farther need more)")
    ap.add_argument("--trunc-voxel-multiplier", type=float, default=8.0,
                    help="SDF truncation in voxels (default 8, Open3D's default)")
    ap.add_argument("--iterations", type=int_list, default=[10, 5, 3],
                    help="ICP iterations per pyramid level, coarse to fine; the list's "
                         "length is the number of levels (strides ..., 4, 2, 1) (default "
                         "10,5,3, rgbd_odometry_multi_scale's default criteria)")
    ap.add_argument("--depth-outlier-trunc", type=float, default=0.07,
                    help="ICP: matches whose point-to-plane residual exceeds this (metres) "
                         "are dropped (default 0.07, Open3D's OdometryLossParams)")
    ap.add_argument("--depth-huber-delta", type=float, default=0.05,
                    help="ICP: Huber loss delta in metres (default 0.05, Open3D's "
                         "OdometryLossParams)")
    ap.add_argument("--min-fitness", type=float, default=0.1,
                    help="a frame is lost when fewer than this share of its pixels have an "
                         "inlier model match after ICP (default 0.1)")
    ap.add_argument("--init", choices=["previous-pose", "constant-velocity"],
                    default="previous-pose",
                    help="ICP initial guess: the previous frame's pose (default, as "
                         "KinectFusion) or that pose moved by the previous relative motion")
    ap.add_argument("--ray-cast-blocks", choices=["frustum", "all"], default="frustum",
                    help="blocks ray-cast for tracking: those the previous fused frame "
                         "touched (default, as Open3D's t.pipelines.slam.Model) or every "
                         "allocated block (slower as the map grows)")
    ap.add_argument("--block-count", type=int, default=0,
                    help="initial hash-map capacity in 16^3 blocks; 0 (default) = 8 times the "
                         "blocks frame 0 touches, at least 1024. Open3D zero-fills the whole "
                         "capacity up front (it counts in peak RSS, not in map MB) and doubles "
                         "it with a rehash when it runs out; the JSON reports rehashes.")
    ap.add_argument("--as-shipped", action="store_true",
                    help="fuse and ray-cast exactly as Open3D does, without the half-pixel "
                         "and half-voxel corrections (see the module docstring)")
    ap.add_argument("--max-frames", type=int, default=0,
                    help="process only the first N frames (0 = all; for quick checks)")
    ap.add_argument("--json", action="store_true", help="print one JSON object last")
    args = ap.parse_args()
    if len(args.iterations) > 4:
        ap.error("--iterations: at most 4 pyramid levels")
    if args.voxel_size <= 0 or args.depth_max <= RAY_CAST_DEPTH_MIN:
        ap.error("--voxel-size must be > 0 and --depth-max > %g" % RAY_CAST_DEPTH_MIN)

    dataset = os.path.abspath(args.dataset)
    name = os.path.basename(dataset.rstrip("/"))
    intr = read_intrinsics(dataset)
    frames = read_frames(dataset)
    if args.max_frames > 0:
        frames = frames[:args.max_frames]
    if not frames:
        sys.exit("open3d_kinfu.py: no frames in %s" % dataset)
    gt = GroundTruth(os.path.join(dataset, "groundtruth.txt"))
    pose0 = gt.pose(frames[0][0])
    if pose0 is None:
        sys.exit("open3d_kinfu.py: frame 0 has no ground-truth pose within %.0f ms"
                 % (ASSOC_MAX_DT * 1e3))
    W, H, ds = intr["width"], intr["height"], intr["depth_scale"]
    strides = [2 ** l for l in range(len(args.iterations))]  # index 0: full resolution
    log("%s: %d frames, %dx%d, voxel %.4g m, depth_max %g m, ICP iterations %s (strides %s), "
        "ray cast over %s blocks%s"
        % (name, len(frames), W, H, args.voxel_size, args.depth_max, args.iterations,
           strides[::-1], args.ray_cast_blocks,
           ", Open3D as shipped" if args.as_shipped else ""))

    # Open3D prints its warnings (e.g. range-map reallocation in ray_cast) on stdout.
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    o3c = o3d.core
    K_t = tsdf.intrinsic_tensor(intr)
    # Integration: with cx, cy moved by +0.5, Open3D's truncation of the projected voxel
    # centre picks the nearest pixel instead of the one to its upper left (module docstring).
    shift = 0.0 if args.as_shipped else 0.5
    K_fuse = tsdf.intrinsic_tensor(dict(intr, cx=intr["cx"] + shift, cy=intr["cy"] + shift))
    # Ray cast: its surface lies half a voxel along +x, +y, +z of the fused one.
    grid_bias = np.zeros(3) if args.as_shipped else np.full(3, 0.5 * args.voxel_size)
    Ks = [scaled_intrinsics(intr, s) for s in strides]
    wall0 = time.perf_counter()  # wall clock: the whole loop, PNG decoding included
    depth, rgb = load_rgbd(frames[0], intr)
    block_count = args.block_count
    if block_count <= 0:
        scratch = tsdf.make_grid(args.voxel_size, 1024, o3c.Device("CPU:0"))  # no insertion
        first = scratch.compute_unique_block_coordinates(
            o3d.t.geometry.Image(o3c.Tensor(depth)), K_t,
            o3c.Tensor(np.linalg.inv(pose0), o3c.Dtype.Float64), ds, args.depth_max,
            args.trunc_voxel_multiplier)
        block_count = max(1024, 8 * int(first.shape[0]))
        del scratch
    vbg = tsdf.make_grid(args.voxel_size, block_count, o3c.Device("CPU:0"))
    capacity = [vbg.hashmap().capacity()]
    log("hash map capacity %d blocks (%.0f MB)"
        % (capacity[0], capacity[0] * tsdf.BLOCK_RES ** 3 * tsdf.BYTES_PER_VOXEL / 1e6))

    def fuse(depth, rgb, pose):
        """Fuses a frame at pose (camera-to-world); returns the blocks it touched."""
        extrinsic = o3c.Tensor(np.linalg.inv(pose), o3c.Dtype.Float64)
        d_img = o3d.t.geometry.Image(o3c.Tensor(depth))
        c_img = o3d.t.geometry.Image(o3c.Tensor(rgb))
        blocks = vbg.compute_unique_block_coordinates(
            d_img, K_t, extrinsic, ds, args.depth_max, args.trunc_voxel_multiplier)
        vbg.integrate(blocks, d_img, c_img, K_fuse, extrinsic, ds, args.depth_max,
                      args.trunc_voxel_multiplier)
        cap = vbg.hashmap().capacity()
        if cap != capacity[-1]:
            log("the hash map rehashed: capacity %d -> %d blocks" % (capacity[-1], cap))
            capacity.append(cap)
        return blocks

    t0 = time.perf_counter()
    frustum = fuse(depth, rgb, pose0)
    fuse0_ms = 1e3 * (time.perf_counter() - t0)
    fused = 1

    poses = [pose0]
    stamps = [frames[0][0]]
    ms, ray_ms, icp_ms, fuse_ms = [], [], [], []
    lost_frames, fitness, icp_iters = [], [], []
    rel = np.eye(4)  # last relative motion, frame i-1 <- frame i
    for i in range(1, len(frames)):
        depth, rgb = load_rgbd(frames[i], intr)  # PNG decoding: not in ms/frame
        prev = poses[-1]
        t0 = time.perf_counter()
        blocks = frustum if args.ray_cast_blocks == "frustum" else tsdf.active_block_coords(vbg)
        # Open3D's Model ray-casts with weight_threshold min(frames fused, 3).
        render = vbg.ray_cast(blocks, K_t, o3c.Tensor(np.linalg.inv(prev), o3c.Dtype.Float64),
                              W, H, ["depth", "vertex", "normal"], ds, RAY_CAST_DEPTH_MIN,
                              args.depth_max, float(min(fused, 3)),
                              args.trunc_voxel_multiplier, 8)
        model, model_px = model_maps(render, strides, prev[:3, :3].T @ grid_bias)
        t1 = time.perf_counter()
        z = depth.astype(np.float32) / np.float32(ds)
        z[z > args.depth_max] = 0.0
        src = frame_vertex_maps(z, Ks, strides)
        init = rel if args.init == "constant-velocity" else np.eye(4)
        # source = frame i, target = the render at `prev`: T maps frame-i camera
        # coordinates into the render's, so pose_i = prev T.
        T, fit, rmse, n_it = align(src, model, Ks, args.iterations, init,
                                   args.depth_outlier_trunc, args.depth_huber_delta)
        ok = fit >= args.min_fitness and np.isfinite(T).all()
        t2 = time.perf_counter()
        if ok:
            rel = T
            new = prev @ T
            frustum = fuse(depth, rgb, new)
            fused += 1
        else:
            lost_frames.append(i)
            new = prev @ rel
        t3 = time.perf_counter()
        ms.append(1e3 * (t3 - t0))
        ray_ms.append(1e3 * (t1 - t0))
        icp_ms.append(1e3 * (t2 - t1))
        if ok:
            fuse_ms.append(1e3 * (t3 - t2))
        fitness.append(fit)
        icp_iters.append(n_it)
        poses.append(new)
        stamps.append(frames[i][0])
        if i % 10 == 0 or not ok:
            log("frame %d/%d: %.0f ms (ray cast %.0f, ICP %.0f, %d iterations), fitness %.2f, "
                "model pixels %d, %d blocks%s"
                % (i, len(frames) - 1, ms[-1], ray_ms[-1], icp_ms[-1], n_it, fit, model_px,
                   vbg.hashmap().size(), "" if ok else " (lost: not fused)"))
    wall_s = time.perf_counter() - wall0

    write_tum(args.out, stamps, poses)
    active_blocks = int(vbg.hashmap().size())
    capacity_blocks = int(vbg.hashmap().capacity())
    block_mb = tsdf.BLOCK_RES ** 3 * tsdf.BYTES_PER_VOXEL / 1e6
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
        "lost": len(lost_frames),
        "lost_frames": lost_frames,
        "keyframes": None,  # KinectFusion keeps no keyframes: every tracked frame is fused
        "fused_frames": fused,
        # 1e6 bytes, like `plenox map` and open3d_tsdf.py: the voxel payload of the allocated
        # blocks, not the hash map's unused capacity (which is in peak RSS).
        "map_mb": active_blocks * block_mb,
        "map_capacity_mb": capacity_blocks * block_mb,
        "active_blocks": active_blocks,
        "block_count": capacity_blocks,
        "rehashes": len(capacity) - 1,
        "peak_rss_mb": peak_rss_mb(),
        "ray_cast_ms_median": percentile(ray_ms, 50),
        "icp_ms_median": percentile(icp_ms, 50),
        "fuse_ms_median": percentile(fuse_ms, 50),
        "fuse_frame0_ms": fuse0_ms,
        "icp_iterations_mean": float(np.mean(icp_iters)) if icp_iters else None,
        "fitness_median": percentile(fitness, 50),
        "fitness_min": min(fitness) if fitness else None,
        "voxel_size": args.voxel_size,
        "depth_max": args.depth_max,
        "trunc_voxel_multiplier": args.trunc_voxel_multiplier,
        "iterations": args.iterations,
        "depth_outlier_trunc": args.depth_outlier_trunc,
        "depth_huber_delta": args.depth_huber_delta,
        "min_fitness": args.min_fitness,
        "init": args.init,
        "ray_cast_blocks": args.ray_cast_blocks,
        "as_shipped": args.as_shipped,
        "trajectory": os.path.abspath(args.out),
        "open3d": o3d.__version__,
    }
    print("%s %s: %d frames, %s ms/frame median, %s ms p95, %.2f frames/s, %d lost, map "
          "%.1f MB, peak RSS %.0f MB -> %s"
          % (SYSTEM, name, len(poses),
             "n/a" if not ms else "%.0f" % result["ms_per_frame_median"],
             "n/a" if not ms else "%.0f" % result["ms_per_frame_p95"], result["fps"] or 0.0,
             len(lost_frames), result["map_mb"], result["peak_rss_mb"], args.out), flush=True)
    if args.json:
        print(json.dumps(result), flush=True)


if __name__ == "__main__":
    main()
