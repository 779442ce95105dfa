#!/usr/bin/python3
"""Where a map's depth error comes from, by measured depth (docs/BENCHMARKS.md, "Depth at range").

    /usr/bin/python3 bench/depth_by_range.py --map MAP.plx --dataset DIR [--every 10]
        [--stride 2] [--keyframes]

Renders the map (`plenox render`, the median depth) at the ground-truth poses of the held-out
frames of a TUM-layout sequence mapped with `plenox map --every K` (frames K/2, K/2 + K, ...;
--keyframes: the keyframes 0, K, 2K, ... themselves, the views the map was fitted to), and
compares with each frame's measured depth per band of measured depth: the share of pixels,
the mean and median |rendered - measured| and the signed mean (z, metres shown in cm).
Beside the map it scores a map-free reference: the two frames K/2 before and after, their
measured depth warped into the frame at the ground-truth poses (z-buffered, averaged where
both see a pixel). Where the map is much worse than that, the map is at fault; where the two
are alike, the frames disagree with each other (sensor noise, calibration, pose error).

Signed means by measured depth are biased by selection: a band of measured depth holds the
pixels whose noise put them there, so a perfect map reads behind the near end of a band and
in front of the far end. Compare signed numbers between maps, not with zero.
"""

import argparse
import os
import subprocess
import sys
import tempfile

import numpy as np

try:
    import cv2
except ImportError:  # python3-opencv
    sys.exit("depth_by_range.py needs python3-opencv (scripts/install_deps.sh --bench)")

import bench_common

REPO = bench_common.REPO
BANDS = [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 10.0]


class Sequence:
    """A TUM-layout sequence's frames, intrinsics and ground truth (bench_common's readers)."""

    def __init__(self, folder):
        self.frames = bench_common.read_frames(folder)
        self.intr = bench_common.read_intrinsics(folder)
        self.gt = bench_common.GroundTruth(os.path.join(folder, "groundtruth.txt"))

    def intrinsics(self):
        k = self.intr
        return "%g %g %g %g %d %d" % (k["fx"], k["fy"], k["cx"], k["cy"], k["width"],
                                      k["height"])

    def matrix(self, i):
        """world_T_camera at frame i's colour timestamp (as plenox's TUM reader takes it)."""
        m = self.gt.pose(self.frames[i][0])
        if m is None:
            sys.exit("frame %d has no ground-truth pose" % i)
        return m

    def pose_arg(self, i):
        m = self.matrix(i)
        values = list(m[:3, 3]) + list(bench_common.rot_to_quat(m[:3, :3]))
        return " ".join("%.9f" % v for v in values)

    def depth(self, i):
        d, _ = bench_common.load_rgbd(self.frames[i], self.intr)
        return d.astype(np.float64) / self.intr["depth_scale"]

    def warped_depth(self, src, dst):
        """Frame src's measured depth seen from frame dst (nearest point per pixel; 0: none)."""
        k = self.intr
        z = self.depth(src)
        v, u = np.nonzero(z > 0)
        d = z[v, u]
        points = np.stack([(u - k["cx"]) / k["fx"] * d, (v - k["cy"]) / k["fy"] * d, d,
                           np.ones_like(d)])
        q = np.linalg.inv(self.matrix(dst)) @ self.matrix(src) @ points
        q = q[:, q[2] > 1e-6]
        uu = np.round(q[0] / q[2] * k["fx"] + k["cx"]).astype(int)
        vv = np.round(q[1] / q[2] * k["fy"] + k["cy"]).astype(int)
        inside = (uu >= 0) & (uu < k["width"]) & (vv >= 0) & (vv < k["height"])
        out = np.full((k["height"], k["width"]), np.inf)
        np.minimum.at(out, (vv[inside], uu[inside]), q[2][inside])
        out[np.isinf(out)] = 0.0
        return out


def render_depth(args, seq, i, scratch):
    path = os.path.join(scratch, "depth.png")
    pose = seq.pose_arg(i)
    cmd = [args.plenox, "render", "--map", args.map, "--pose", pose, "--intrinsics",
           seq.intrinsics(), "--depth", path]
    done = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    if done.returncode != 0:
        sys.exit("plenox render failed for frame %d: %s" % (i, done.stderr.strip()))
    return cv2.imread(path, cv2.IMREAD_UNCHANGED).astype(np.float64) / 1000.0


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--map", required=True, help="map file made by plenox map --every K")
    ap.add_argument("--dataset", required=True, help="TUM-layout sequence folder")
    ap.add_argument("--plenox", default=os.path.join(REPO, "build/clients/plenox/plenox"))
    ap.add_argument("--every", type=int, default=10, help="the map's keyframe stride K")
    ap.add_argument("--stride", type=int, default=2,
                    help="score every N-th of the frames chosen (each render loads the map)")
    ap.add_argument("--keyframes", action="store_true",
                    help="score the keyframes (the views the map was fitted to)")
    args = ap.parse_args()
    if args.every < 2 or args.stride < 1:
        ap.error("--every must be >= 2 and --stride >= 1")
    seq = Sequence(args.dataset)
    first = 0 if args.keyframes else args.every // 2
    frames = list(range(first, len(seq.frames), args.every))[::args.stride]
    half = args.every // 2
    per_band = [[] for _ in BANDS[1:]]
    with tempfile.TemporaryDirectory(prefix="plx_depth_by_range_") as scratch:
        for n, i in enumerate(frames):
            print("frame %d (%d of %d)" % (i, n + 1, len(frames)), file=sys.stderr)
            measured = seq.depth(i)
            rendered = render_depth(args, seq, i, scratch)
            near = [seq.warped_depth(j, i) for j in (i - half, i + half)
                    if 0 <= j < len(seq.frames) and j != i]
            counted = np.sum([w > 0 for w in near], axis=0)
            reference = np.sum(near, axis=0) / np.maximum(counted, 1)
            ok = (measured > 0) & (rendered > 0)
            for b in range(len(BANDS) - 1):
                sel = ok & (measured >= BANDS[b]) & (measured < BANDS[b + 1])
                ref = sel & (reference > 0)
                per_band[b].append((rendered[sel] - measured[sel],
                                    reference[ref] - measured[ref]))
    total = sum(sum(len(e[0]) for e in band) for band in per_band)
    print("frames %s (%s), every %d" % (" ".join(map(str, frames)),
                                         "keyframes" if args.keyframes else "held out",
                                         args.every))
    print("| measured depth | pixels | map mean abs (cm) | map median abs (cm) | "
          "map signed mean (cm) | neighbours mean abs (cm) |")
    print("| --- | --- | --- | --- | --- | --- |")
    all_map, all_ref = [], []
    for b, band in enumerate(per_band):
        err = np.concatenate([e[0] for e in band])
        ref = np.concatenate([e[1] for e in band])
        if len(err) == 0:
            continue
        all_map.append(err)
        all_ref.append(ref)
        print("| %g-%g m | %.1f %% | %.2f | %.2f | %+.2f | %.2f |" % (
            BANDS[b], BANDS[b + 1], 100.0 * len(err) / total, 100 * np.abs(err).mean(),
            100 * np.median(np.abs(err)), 100 * err.mean(),
            100 * np.abs(ref).mean() if len(ref) else float("nan")))
    err, ref = np.concatenate(all_map), np.concatenate(all_ref)
    print("| all | 100 %% | %.2f | %.2f | %+.2f | %.2f |" % (
        100 * np.abs(err).mean(), 100 * np.median(np.abs(err)), 100 * err.mean(),
        100 * np.abs(ref).mean()))


if __name__ == "__main__":
    main()
