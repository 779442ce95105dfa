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
import bisect
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
    import cv2  # noqa: E402
    import open3d as o3d  # noqa: E402
except ImportError as exc:  # pragma: no cover - depends on the interpreter
    sys.exit("open3d_tsdf.py: %s. Run it with /usr/bin/python3 (Debian's python3-open3d, "
             "python3-opencv)." % exc)

ASSOC_MAX_DT = 0.02   # s, rgb<->depth association and GT look-up tolerance
VALID_DEPTH_MAX = 10.0  # m, protocol: pixels with 0 < z <= 10 m are scored


def log(msg):
    print("[open3d_tsdf] " + msg, file=sys.stderr, flush=True)


# ----------------------------------------------------------------------------------------
# TUM-layout dataset reading
# ----------------------------------------------------------------------------------------

def read_rows(path):
    """Whitespace-split, non-empty, non-comment lines of a TUM text file."""
    rows = []
    with open(path) as f:
        for line in f:
            line = line.strip()
            if line and not line.startswith("#"):
                rows.append(line.split())
    return rows


def read_intrinsics(dataset):
    rows = read_rows(os.path.join(dataset, "intrinsics.txt"))
    if not rows or len(rows[0]) < 7:
        raise ValueError("intrinsics.txt: expected 'fx fy cx cy width height depth_scale ...'")
    v = rows[0]
    return {
        "fx": float(v[0]), "fy": float(v[1]), "cx": float(v[2]), "cy": float(v[3]),
        "width": int(float(v[4])), "height": int(float(v[5])), "depth_scale": float(v[6]),
    }


def associate(rgb_rows, depth_rows, max_dt):
    """Pair rgb and depth stamps one-to-one, closest pairs first (TUM associate.py logic)."""
    rgb = sorted((float(r[0]), r[1]) for r in rgb_rows)
    depth = sorted((float(r[0]), r[1]) for r in depth_rows)
    dstamps = [d[0] for d in depth]
    cands = []
    for i, (t, _) in enumerate(rgb):
        lo = bisect.bisect_left(dstamps, t - max_dt)
        hi = bisect.bisect_right(dstamps, t + max_dt)
        for j in range(lo, hi):
            cands.append((abs(dstamps[j] - t), i, j))
    cands.sort()
    used_r, used_d, pairs = set(), set(), []
    for _, i, j in cands:
        if i in used_r or j in used_d:
            continue
        used_r.add(i)
        used_d.add(j)
        pairs.append((rgb[i][0], rgb[i][1], depth[j][0], depth[j][1]))
    pairs.sort()
    return pairs


def read_frames(dataset):
    """Frame list in associations.txt order: (t_rgb, rgb_path, t_depth, depth_path)."""
    assoc = os.path.join(dataset, "associations.txt")
    if os.path.exists(assoc):
        frames = [(float(r[0]), r[1], float(r[2]), r[3]) for r in read_rows(assoc)]
    else:
        frames = associate(read_rows(os.path.join(dataset, "rgb.txt")),
                           read_rows(os.path.join(dataset, "depth.txt")), ASSOC_MAX_DT)
    return [(tr, os.path.join(dataset, pr), td, os.path.join(dataset, pd))
            for tr, pr, td, pd in frames]


def quat_slerp(q0, q1, a):
    q0 = q0 / np.linalg.norm(q0)
    q1 = q1 / np.linalg.norm(q1)
    d = float(np.dot(q0, q1))
    if d < 0.0:  # take the short way round
        q1, d = -q1, -d
    if d > 0.9995:
        q = q0 + a * (q1 - q0)
    else:
        th = math.acos(min(1.0, d))
        q = (math.sin((1.0 - a) * th) * q0 + math.sin(a * th) * q1) / math.sin(th)
    return q / np.linalg.norm(q)


def quat_to_rot(q):
    x, y, z, w = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


class GroundTruth:
    """groundtruth.txt ('t tx ty tz qx qy qz qw', camera-to-world) with interpolation."""

    def __init__(self, path):
        rows = sorted((float(r[0]), [float(x) for x in r[1:8]]) for r in read_rows(path))
        if not rows:
            raise ValueError("%s has no poses" % path)
        self.t = [r[0] for r in rows]
        self.p = [np.array(r[1]) for r in rows]

    def pose(self, t, max_dt=ASSOC_MAX_DT):
        """4x4 camera-to-world at time t, or None when t is off the ends by more than max_dt."""
        i = bisect.bisect_left(self.t, t)
        if i < len(self.t) and self.t[i] == t:
            tr, q = self.p[i][:3], self.p[i][3:]
        elif i == 0 or i == len(self.t):
            j = 0 if i == 0 else len(self.t) - 1
            if abs(self.t[j] - t) > max_dt:
                return None
            tr, q = self.p[j][:3], self.p[j][3:]
        else:
            t0, t1 = self.t[i - 1], self.t[i]
            a = (t - t0) / (t1 - t0)
            p0, p1 = self.p[i - 1], self.p[i]
            tr = (1.0 - a) * p0[:3] + a * p1[:3]
            q = quat_slerp(p0[3:], p1[3:], a)
        T = np.eye(4)
        T[:3, :3] = quat_to_rot(np.asarray(q) / np.linalg.norm(q))
        T[:3, 3] = tr
        return T


def load_rgbd(frame, intr):
    _, rgb_path, _, depth_path = frame
    depth = cv2.imread(depth_path, cv2.IMREAD_UNCHANGED)
    bgr = cv2.imread(rgb_path, cv2.IMREAD_COLOR)
    if depth is None or bgr is None:
        raise IOError("cannot read %s or %s" % (depth_path, rgb_path))
    if depth.dtype != np.uint16 or depth.ndim != 2:
        raise ValueError("%s: expected 16-bit single-channel depth, got %s %s"
                         % (depth_path, depth.dtype, depth.shape))
    want = (intr["height"], intr["width"])
    if depth.shape != want or bgr.shape[:2] != want:
        raise ValueError("%s: image size %s / %s does not match intrinsics.txt %s"
                         % (rgb_path, bgr.shape[:2], depth.shape, want))
    rgb = np.ascontiguousarray(bgr[:, :, ::-1])
    return depth, rgb


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
    device = o3c.Device("CPU:0")
    K_t = o3c.Tensor(np.array([[intr["fx"], 0.0, intr["cx"]],
                               [0.0, intr["fy"], intr["cy"]],
                               [0.0, 0.0, 1.0]]), o3c.Dtype.Float64)
    ds = intr["depth_scale"]
    attr_dtypes = [o3c.float32, o3c.float32, o3c.float32]
    attr_channels = [1, 1, 3]
    bytes_per_voxel = 4 * sum(attr_channels)
    block_res = 16

    def make_grid(block_count):
        return o3d.t.geometry.VoxelBlockGrid(
            attr_names=["tsdf", "weight", "color"], attr_dtypes=attr_dtypes,
            attr_channels=[[c] for c in attr_channels], voxel_size=args.voxel_size,
            block_resolution=block_res, block_count=block_count, device=device)

    # --- capacity ------------------------------------------------------------------------
    # Open3D allocates and zero-fills block_count blocks up front (and doubles the capacity
    # with a rehash when it runs out). The pre-pass finds the exact set of blocks the keyframes
    # will touch, so the grid neither rehashes nor holds gigabytes it never uses. It is not
    # timed: it only sizes a buffer.
    block_count = args.block_count
    if block_count <= 0:
        scratch = make_grid(1024)  # compute_unique_block_coordinates does not insert
        seen, max_frame = set(), 0
        for i in key_ids:
            depth, _ = load_rgbd(frames[i], intr)
            coords = scratch.compute_unique_block_coordinates(
                o3d.t.geometry.Image(o3c.Tensor(depth)), K_t,
                o3c.Tensor(np.linalg.inv(poses[i]), o3c.Dtype.Float64), ds, args.depth_max,
                args.trunc_voxel_multiplier).numpy()
            seen.update(map(tuple, coords.tolist()))
            max_frame = max(max_frame, len(coords))
        del scratch
        # Open3D's insert rehashes (doubling, and slowly) when size + the number of keys
        # passed in would exceed the capacity, even if most keys are already there.
        block_count = max(1024, int(1.1 * (len(seen) + max_frame)) + 64)
        log("pre-pass: keyframes touch %d blocks (at most %d per frame); capacity %d blocks "
            "(%.0f MB)" % (len(seen), max_frame, block_count,
                           block_count * block_res ** 3 * bytes_per_voxel / 1e6))
    vbg = make_grid(block_count)

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
            d_img, K_t, extrinsic, ds, args.depth_max, args.trunc_voxel_multiplier)
        vbg.integrate(blocks, d_img, c_img, K_t, extrinsic, ds, args.depth_max,
                      args.trunc_voxel_multiplier)
        t2 = time.perf_counter()
        load_s += t1 - t0
        integrate_s += t2 - t1
        log("integrated keyframe %d (%d/%d) in %.3f s, %d blocks"
            % (i, n + 1, len(key_ids), t2 - t1, vbg.hashmap().size()))

    hashmap = vbg.hashmap()
    active_blocks = int(hashmap.size())
    block_coords = hashmap.key_tensor()[hashmap.active_buf_indices().to(o3c.int64)]
    # 1e6 bytes, like `plenox map` (peak RSS is ru_maxrss KiB / 1024, also like plenox).
    map_mb = active_blocks * block_res ** 3 * bytes_per_voxel / 1e6

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
