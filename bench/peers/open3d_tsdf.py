#!/usr/bin/python3
"""Open3D TSDF peer for the mapping benchmark (see bench/README.md).

Maps every K-th frame of a TUM-layout RGB-D sequence with its ground-truth pose into an
Open3D 0.16 tensor VoxelBlockGrid (CPU:0). It then ray-casts the held-out frames
(i % K == K // 2) and scores them against the measured depth and colour.

Run it with Debian's interpreter (/usr/bin/python3: python3-open3d, numpy, python3-opencv):

    OMP_WAIT_POLICY=passive /usr/bin/python3 bench/peers/open3d_tsdf.py \
        --dataset ../shared/data/tum_fr3_teddy --every 10 --json

The last stdout line is one JSON object when --json is given. Progress goes to stderr.
"""

import argparse
import json
import math
import os
import resource
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
    sys.exit("%s: %s. Run it with /usr/bin/python3 (Debian's python3-open3d, "
             "python3-opencv)." % (os.path.basename(sys.argv[0]), exc))

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from bench_common import (ASSOC_MAX_DT, GroundTruth, load_rgbd, read_frames,  # noqa: E402
                          read_intrinsics)

VALID_DEPTH_MAX = 10.0  # m, protocol: pixels with 0 < z <= 10 m are scored
BLOCK_RES = 16  # voxels per block edge
ATTR_CHANNELS = (1, 1, 3)  # tsdf, weight, colour; all float32
BYTES_PER_VOXEL = 4 * sum(ATTR_CHANNELS)


def log(msg):
    print("[open3d_tsdf] " + msg, file=sys.stderr, flush=True)


# ----------------------------------------------------------------------------------------
# TSDF map (also used by open3d_f2m.py, the frame-to-model tracking peer)
# ----------------------------------------------------------------------------------------

def intrinsic_tensor(intr):
    return o3d.core.Tensor(np.array([[intr["fx"], 0.0, intr["cx"]],
                                     [0.0, intr["fy"], intr["cy"]],
                                     [0.0, 0.0, 1.0]]), o3d.core.Dtype.Float64)


def make_grid(voxel_size, block_count, device):
    o3c = o3d.core
    return o3d.t.geometry.VoxelBlockGrid(
        attr_names=["tsdf", "weight", "color"], attr_dtypes=[o3c.float32] * 3,
        attr_channels=[[c] for c in ATTR_CHANNELS], voxel_size=voxel_size,
        block_resolution=BLOCK_RES, block_count=block_count, device=device)


def build_tsdf(frames, key_ids, poses, intr, voxel_size, depth_max, trunc_voxel_multiplier,
               block_count=0, log=log):
    """Integrates frames[key_ids] at poses (camera-to-world 4x4) into a new VoxelBlockGrid on
    CPU:0. block_count <= 0 sizes the hash map with an untimed pre-pass (see below).
    Returns (grid, {"block_count", "integrate_seconds", "load_seconds"})."""
    o3c = o3d.core
    device = o3c.Device("CPU:0")
    K_t = intrinsic_tensor(intr)
    ds = intr["depth_scale"]

    # --- capacity ------------------------------------------------------------------------
    # Open3D allocates and zero-fills block_count blocks up front (and doubles the capacity
    # with a rehash when it runs out). The pre-pass finds the exact set of blocks the keyframes
    # will touch, so the grid neither rehashes nor holds gigabytes it never uses. It is not
    # timed: it only sizes a buffer.
    if block_count <= 0:
        scratch = make_grid(voxel_size, 1024, device)  # this call does not insert
        seen, max_frame = set(), 0
        for i in key_ids:
            depth, _ = load_rgbd(frames[i], intr)
            coords = scratch.compute_unique_block_coordinates(
                o3d.t.geometry.Image(o3c.Tensor(depth)), K_t,
                o3c.Tensor(np.linalg.inv(poses[i]), o3c.Dtype.Float64), ds, depth_max,
                trunc_voxel_multiplier).numpy()
            seen.update(map(tuple, coords.tolist()))
            max_frame = max(max_frame, len(coords))
        del scratch
        # Open3D's insert rehashes (doubling, and slowly) when size + the number of keys
        # passed in would exceed the capacity, even if most keys are already there.
        block_count = max(1024, int(1.1 * (len(seen) + max_frame)) + 64)
        log("pre-pass: keyframes touch %d blocks (at most %d per frame); capacity %d blocks "
            "(%.0f MB)" % (len(seen), max_frame, block_count,
                           block_count * BLOCK_RES ** 3 * BYTES_PER_VOXEL / 1e6))
    vbg = make_grid(voxel_size, block_count, device)

    # --- mapping -------------------------------------------------------------------------
    # Timed: building the Open3D images from decoded arrays, block allocation, integration.
    # Not timed: PNG decoding (disk I/O), as it is the same work for every system.
    integrate_s, load_s = 0.0, 0.0
    for n, i in enumerate(key_ids):
        t0 = time.perf_counter()
        depth, rgb = load_rgbd(frames[i], intr)
        t1 = time.perf_counter()
        extrinsic = o3c.Tensor(np.linalg.inv(poses[i]), o3c.Dtype.Float64)
        d_img = o3d.t.geometry.Image(o3c.Tensor(depth))
        c_img = o3d.t.geometry.Image(o3c.Tensor(rgb))
        blocks = vbg.compute_unique_block_coordinates(
            d_img, K_t, extrinsic, ds, depth_max, trunc_voxel_multiplier)
        vbg.integrate(blocks, d_img, c_img, K_t, extrinsic, ds, depth_max,
                      trunc_voxel_multiplier)
        t2 = time.perf_counter()
        load_s += t1 - t0
        integrate_s += t2 - t1
        log("integrated keyframe %d (%d/%d) in %.3f s, %d blocks"
            % (i, n + 1, len(key_ids), t2 - t1, vbg.hashmap().size()))
    return vbg, {"block_count": block_count, "integrate_seconds": integrate_s,
                 "load_seconds": load_s}


def active_block_coords(vbg):
    hashmap = vbg.hashmap()
    return hashmap.key_tensor()[hashmap.active_buf_indices().to(o3d.core.int64)]


# ----------------------------------------------------------------------------------------
# Metrics (identical protocol for every system; see bench/README.md)
# ----------------------------------------------------------------------------------------

def range_factor(intr):
    """Per-pixel factor turning z-depth into range along the ray through the pixel centre."""
    u = (np.arange(intr["width"]) + 0.5 - intr["cx"]) / intr["fx"]
    v = (np.arange(intr["height"]) + 0.5 - intr["cy"]) / intr["fy"]
    return np.sqrt(u[None, :] ** 2 + v[:, None] ** 2 + 1.0)


class Scores:
    def __init__(self):
        self.valid = 0
        self.covered = 0
        self.abs_err = []
        self.psnr = []
        self.psnr_covered = []  # diagnostic only: PSNR over covered valid pixels

    def add(self, z_meas, rgb_meas, z_rend, rgb_rend, factor):
        """z_* in metres (0 = none), rgb_* float in [0,1] HxWx3."""
        valid = (z_meas > 0) & (z_meas <= VALID_DEPTH_MAX)
        nvalid = int(valid.sum())
        if nvalid == 0:
            return None
        covered = valid & (z_rend > 0)
        err = np.abs(z_rend[covered] - z_meas[covered]) * factor[covered]
        self.valid += nvalid
        self.covered += int(covered.sum())
        self.abs_err.append(err.astype(np.float64))
        diff = np.clip(rgb_rend[valid], 0.0, 1.0) - rgb_meas[valid]
        mse = float(np.mean(diff.astype(np.float64) ** 2))
        psnr = float("inf") if mse == 0.0 else -10.0 * math.log10(mse)
        self.psnr.append(psnr)
        if covered.any():
            d = np.clip(rgb_rend[covered], 0.0, 1.0) - rgb_meas[covered]
            mse_c = float(np.mean(d.astype(np.float64) ** 2))
            self.psnr_covered.append(float("inf") if mse_c == 0.0 else -10.0 * math.log10(mse_c))
        return {"psnr": psnr, "coverage": covered.sum() / nvalid,
                "depth_l1_m": float(err.mean()) if err.size else None}

    def summary(self):
        err = np.concatenate(self.abs_err) if self.abs_err else np.zeros(0)
        return {
            "psnr": float(np.mean(self.psnr)) if self.psnr else None,
            "depth_l1_m": float(err.mean()) if err.size else None,
            "depth_l1_median_m": float(np.median(err)) if err.size else None,
            "coverage": self.covered / self.valid if self.valid else None,
            "pixels": self.valid,
            "psnr_covered_only": (float(np.mean(self.psnr_covered)) if self.psnr_covered
                                  else None),
        }


# ----------------------------------------------------------------------------------------
# Main
# ----------------------------------------------------------------------------------------

def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dataset", required=True, help="TUM-layout sequence folder")
    ap.add_argument("--every", type=int, default=10, help="keyframe stride K (default 10)")
    ap.add_argument("--voxel-size", type=float, default=0.01, help="metres (default 0.01)")
    ap.add_argument("--depth-max", type=float, default=10.0,
                    help="max depth integrated and ray-cast, metres (default 10)")
    ap.add_argument("--trunc-voxel-multiplier", type=float, default=8.0,
                    help="SDF truncation in voxels (default 8, Open3D's default)")
    ap.add_argument("--weight-threshold", type=float, default=1.0,
                    help="ray_cast min voxel weight (default 1: rendered if integrated at "
                         "least once; Open3D's own default is 3)")
    ap.add_argument("--block-count", type=int, default=0,
                    help="hash-map capacity in 16^3 blocks; 0 (default) sizes it with an "
                         "untimed pre-pass to what the keyframes need (no rehash). Open3D "
                         "zero-fills the whole capacity, so it sets most of the peak RSS.")
    ap.add_argument("--json", action="store_true", help="print one JSON object last")
    args = ap.parse_args()
    if args.every < 2:
        ap.error("--every must be >= 2 (held-out frames are i %% K == K // 2)")

    dataset = os.path.abspath(args.dataset)
    name = os.path.basename(dataset.rstrip("/"))
    intr = read_intrinsics(dataset)
    frames = read_frames(dataset)
    gt = GroundTruth(os.path.join(dataset, "groundtruth.txt"))
    K = args.every
    key_ids = [i for i in range(len(frames)) if i % K == 0]
    held_ids = [i for i in range(len(frames)) if i % K == K // 2]

    poses, missing = {}, []
    for i in key_ids + held_ids:
        T = gt.pose(frames[i][0])
        if T is None:
            missing.append(i)
        else:
            poses[i] = T
    if missing:
        log("no ground-truth pose within %.0f ms for frames %s; they are skipped"
            % (ASSOC_MAX_DT * 1e3, missing))
    key_ids = [i for i in key_ids if i in poses]
    held_ids = [i for i in held_ids if i in poses]
    if not key_ids:
        sys.exit("open3d_tsdf.py: no keyframes with a ground-truth pose in %s" % dataset)
    log("%s: %d frames, %d keyframes, %d held-out, voxel %.4g m, depth_max %g m"
        % (name, len(frames), len(key_ids), len(held_ids), args.voxel_size, args.depth_max))

    # Open3D prints its warnings (e.g. range-map reallocation in ray_cast) on stdout.
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    o3c = o3d.core
    K_t = intrinsic_tensor(intr)
    ds = intr["depth_scale"]
    vbg, built = build_tsdf(frames, key_ids, poses, intr, args.voxel_size, args.depth_max,
                            args.trunc_voxel_multiplier, args.block_count)
    block_count = built["block_count"]
    integrate_s, load_s = built["integrate_seconds"], built["load_seconds"]

    active_blocks = int(vbg.hashmap().size())
    block_coords = active_block_coords(vbg)
    # 1e6 bytes, like `plenox map` (peak RSS is ru_maxrss KiB / 1024, also like plenox).
    map_mb = active_blocks * BLOCK_RES ** 3 * BYTES_PER_VOXEL / 1e6

    # --- held-out evaluation -------------------------------------------------------------
    factor = range_factor(intr)
    scores = Scores()
    render_s = 0.0
    for i in held_ids:
        depth, rgb = load_rgbd(frames[i], intr)
        extrinsic = o3c.Tensor(np.linalg.inv(poses[i]), o3c.Dtype.Float64)
        t0 = time.perf_counter()
        out = vbg.ray_cast(block_coords, K_t, extrinsic, intr["width"], intr["height"],
                           ["depth", "color"], ds, 0.1, args.depth_max,
                           args.weight_threshold, args.trunc_voxel_multiplier, 8)
        z_rend = out["depth"].numpy()[:, :, 0] / ds   # ray_cast returns z * depth_scale
        rgb_rend = out["color"].numpy()              # float in [0,1] (uint8 input / 255)
        render_s += time.perf_counter() - t0
        z_rend = np.where(np.isfinite(z_rend), z_rend, 0.0)
        rgb_rend = np.nan_to_num(rgb_rend, nan=0.0, posinf=0.0, neginf=0.0)
        f = scores.add(depth.astype(np.float64) / ds, rgb.astype(np.float64) / 255.0,
                       z_rend.astype(np.float64), rgb_rend, factor)
        if f is None:
            log("held-out frame %d has no valid depth; skipped" % i)
        else:
            log("held-out frame %d: PSNR %.2f dB, coverage %.3f, depth L1 %s"
                % (i, f["psnr"], f["coverage"],
                   "n/a" if f["depth_l1_m"] is None else "%.2f cm" % (100 * f["depth_l1_m"])))

    s = scores.summary()
    peak_rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # KiB on Linux
    result = {
        "system": "open3d_tsdf",
        "sequence": name,
        "keyframes": len(key_ids),
        "heldout_frames": len(scores.psnr),
        "seconds_per_keyframe": integrate_s / len(key_ids),
        "psnr": s["psnr"],
        "depth_l1_m": s["depth_l1_m"],
        "depth_l1_median_m": s["depth_l1_median_m"],
        "coverage": s["coverage"],
        "map_mb": map_mb,
        "peak_rss_mb": peak_rss_mb,
        "voxel_size": args.voxel_size,
        # extra detail, not part of the required schema
        "depth_max": args.depth_max,
        "weight_threshold": args.weight_threshold,
        "trunc_voxel_multiplier": args.trunc_voxel_multiplier,
        "every": K,
        "active_blocks": active_blocks,
        "block_count": block_count,
        "integrate_seconds": integrate_s,
        "load_seconds": load_s,
        "render_seconds_per_view": render_s / len(held_ids) if held_ids else None,
        "pixels": s["pixels"],
        "psnr_covered_only": s["psnr_covered_only"],
        "open3d": o3d.__version__,
    }

    def fmt(v, scale=1.0, spec="%.3f"):
        return "n/a" if v is None else spec % (v * scale)

    print("open3d_tsdf %s: %d keyframes, %.3f s/keyframe, %d held-out: PSNR %s dB, "
          "depth L1 %s cm (median %s cm), coverage %s, map %.1f MB, peak RSS %.0f MB"
          % (name, len(key_ids), result["seconds_per_keyframe"], result["heldout_frames"],
             fmt(s["psnr"], spec="%.2f"), fmt(s["depth_l1_m"], 100, "%.2f"),
             fmt(s["depth_l1_median_m"], 100, "%.2f"), fmt(s["coverage"]), map_mb,
             peak_rss_mb), flush=True)
    if args.json:
        print(json.dumps(result), flush=True)


if __name__ == "__main__":
    main()
