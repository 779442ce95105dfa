#!/usr/bin/python3
"""Derives a hard RGB-D sequence from a TUM-layout one (issue 21's hard cases).

    /usr/bin/python3 bench/hard_cases.py --src DIR --out NEW_DIR [operations]

Operations, applied in this order:

  --every K            keep every K-th frame (0, K, 2K, ...): K times the motion per frame.
  --kidnap AT,TO       after frame AT, jump to frame TO and go on from there to the end (frame
                       indices after --every). Ground truth follows the frames, so the camera
                       teleports: output frame AT+1 is the jump.
  --frames N           keep only the first N output frames.
  --shift-colour DX,DY colour moved DX pixels right and DY down against depth (an unregistered
                       sensor); the uncovered border repeats the edge pixels.
  --noise              Kinect-like depth: axial noise sigma(z) = 0.0012 + 0.0019 (z - 0.4)^2 m
                       (Nguyen et al. 2012), quantised in disparity steps of 1/8 px (the
                       Kinect's 580 px focal length and 7.5 cm baseline: 0.7 cm steps at 1.5 m,
                       2.6 cm at 3 m), range 0.4-4.5 m, holes along depth edges (70 % of a
                       3 px band) and in random blobs (3 % of the image). Seeded (--noise-seed)
                       per output frame.
  --cover START,SECONDS
                       a covered lens: black colour and zero depth from output frame START for
                       SECONDS (frames whose timestamp is within SECONDS of frame START's).

Timing. Output frame j keeps the timestamp of source frame j (past the source's end the
median frame interval goes on), whichever source frame it shows. So a thinned or kidnapped
sequence is replayed at the sensor's own frame rate: with --every K the camera really moves
K times faster per second as well as per frame, so frames per second, realtime replay and any
time-based keyframe or motion model see a fast user with a 30 Hz sensor, not a slow sensor
(keeping the source stamps would be the latter). Depth stamps keep their offset from the
colour stamp of the frame they came from.

The new folder has intrinsics.txt (copied), rgb/ and depth/ (images untouched by an operation
are hard links to, or copies of, the source's; changed ones are PNG), rgb.txt, depth.txt,
associations.txt, groundtruth.txt (each output frame's pose, interpolated at its source frame's
colour stamp as plenox does, written at its new stamp; only when the source has ground truth)
and hard_case.json (what was done, per-frame source indices, the jump and the covered frames),
which bench/slam_hard_bench.py reads.

Needs numpy and cv2 (Debian's python3-numpy, python3-opencv: scripts/install_deps.sh --bench).
"""

import argparse
import json
import os
import shutil
import statistics
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_common import GroundTruth, read_frames, read_intrinsics, write_tum  # noqa: E402

# Kinect v1 (structured light) constants of --noise. The sensor measures disparity on its own
# IR camera (580 px focal length at 640x480), whatever resolution the frames are stored at.
KINECT_FOCAL_PX = 580.0
KINECT_BASELINE_M = 0.075
KINECT_DISPARITY_STEP_PX = 1.0 / 8.0
KINECT_MIN_RANGE_M = 0.4
KINECT_MAX_RANGE_M = 4.5
EDGE_JUMP = 0.04        # relative depth jump between neighbours that makes an edge
EDGE_DROP = 0.7         # chance an edge-band pixel is lost
BLOB_FRACTION = 0.03    # share of the image in random blobs
BLOB_RADIUS_PX = (2.0, 7.0)  # at 640 px width, scaled with the image


def kinect_sigma(z):
    """Axial noise (m) of a Kinect v1 at depth z (m)."""
    return 0.0012 + 0.0019 * (z - 0.4) ** 2


def parse_pair(text, kind, name):
    parts = text.split(",")
    if len(parts) != 2:
        raise argparse.ArgumentTypeError("%s: expected two comma-separated values, got %r"
                                         % (name, text))
    try:
        return kind(parts[0]), kind(parts[1])
    except ValueError:
        raise argparse.ArgumentTypeError("%s: cannot read %r" % (name, text))


# ----------------------------------------------------------------------------------------
# Frame selection and timing
# ----------------------------------------------------------------------------------------

def select_frames(count, every=1, kidnap=None, frames=None):
    """Source indices of the output frames, and the output index of the jump (or None)."""
    thinned = list(range(0, count, every))
    jump = None
    if kidnap is not None:
        at, to = kidnap
        if not (0 <= at < len(thinned) - 1 and 0 <= to < len(thinned)):
            raise ValueError("--kidnap %d,%d: both must be frames of the %d-frame sequence "
                             "(after --every), AT before the last" % (at, to, len(thinned)))
        if abs(to - (at + 1)) < 2:
            raise ValueError("--kidnap %d,%d is no jump" % (at, to))
        thinned = thinned[:at + 1] + thinned[to:]
        jump = at + 1
    if frames is not None:
        thinned = thinned[:frames]
        if jump is not None and jump >= len(thinned):
            jump = None
    if not thinned:
        raise ValueError("no frames left")
    return thinned, jump


def output_stamps(source_stamps, n):
    """Output frame j at source frame j's stamp; past the end, the median interval goes on."""
    if len(source_stamps) > 1:
        step = statistics.median(b - a for a, b in zip(source_stamps, source_stamps[1:]))
    else:
        step = 1.0 / 30.0
    out = list(source_stamps[:n])
    while len(out) < n:
        out.append(out[-1] + step)
    return out, step


# ----------------------------------------------------------------------------------------
# Image operations (numpy arrays; colour as read by cv2, depth as uint16 sensor units)
# ----------------------------------------------------------------------------------------

def shift_colour(image, dx, dy):
    """Content moved dx right and dy down; the border repeats the edge."""
    h, w = image.shape[:2]
    rows = np.clip(np.arange(h) - dy, 0, h - 1)
    cols = np.clip(np.arange(w) - dx, 0, w - 1)
    return image[rows][:, cols]


def edge_mask(z):
    """Pixels next to a relative depth jump > EDGE_JUMP, on either side, widened by 1 px."""
    valid = z > 0
    mask = np.zeros(z.shape, bool)
    for axis in (0, 1):
        a = np.take(z, range(0, z.shape[axis] - 1), axis=axis)
        b = np.take(z, range(1, z.shape[axis]), axis=axis)
        va = np.take(valid, range(0, z.shape[axis] - 1), axis=axis)
        vb = np.take(valid, range(1, z.shape[axis]), axis=axis)
        jump = va & vb & (np.abs(a - b) > EDGE_JUMP * np.minimum(a, b))
        if axis == 0:
            mask[:-1] |= jump
            mask[1:] |= jump
        else:
            mask[:, :-1] |= jump
            mask[:, 1:] |= jump
    widened = mask.copy()
    widened[1:] |= mask[:-1]
    widened[:-1] |= mask[1:]
    widened[:, 1:] |= mask[:, :-1]
    widened[:, :-1] |= mask[:, 1:]
    return widened


def blob_mask(shape, rng):
    """Random filled ellipses covering about BLOB_FRACTION of the image."""
    import cv2
    h, w = shape
    mask = np.zeros(shape, np.uint8)
    scale = w / 640.0
    target = BLOB_FRACTION * h * w
    while mask.sum() < target:
        ru, rv = rng.uniform(*BLOB_RADIUS_PX, size=2) * scale
        centre = (int(rng.integers(0, w)), int(rng.integers(0, h)))
        axes = (max(1, int(round(ru))), max(1, int(round(rv))))
        cv2.ellipse(mask, centre, axes, float(rng.uniform(0, 180)), 0, 360, 1, thickness=-1)
    return mask.astype(bool)


def kinect_depth(depth, depth_scale, rng):
    """Kinect-like version of a uint16 depth image (see --noise)."""
    z = depth.astype(np.float64) / depth_scale
    valid = z > 0
    noisy = z + rng.standard_normal(z.shape) * kinect_sigma(z)
    # Quantise in disparity, the quantity the sensor measures.
    fb = KINECT_FOCAL_PX * KINECT_BASELINE_M
    with np.errstate(divide="ignore", invalid="ignore"):
        disparity = np.where(noisy > 0, fb / noisy, 0.0)
        steps = np.round(disparity / KINECT_DISPARITY_STEP_PX) * KINECT_DISPARITY_STEP_PX
        quantised = np.where(steps > 0, fb / steps, 0.0)
    keep = valid & (quantised >= KINECT_MIN_RANGE_M) & (quantised <= KINECT_MAX_RANGE_M)
    edges = edge_mask(z) & (rng.random(z.shape) < EDGE_DROP)
    keep &= ~edges & ~blob_mask(z.shape, rng)
    out = np.where(keep, np.round(quantised * depth_scale), 0)
    return np.clip(out, 0, 65535).astype(np.uint16)


# ----------------------------------------------------------------------------------------
# Writing
# ----------------------------------------------------------------------------------------

def link_or_copy(src, dst):
    try:
        os.link(src, dst)
    except OSError:
        shutil.copyfile(src, dst)


def write_list(path, header, rows):
    with open(path, "w") as f:
        f.write(header)
        for row in rows:
            f.write(" ".join(row) + "\n")


def derive(src, out, every=1, kidnap=None, frames=None, shift=None, noise=False,
           noise_seed=7, cover=None, log=None):
    """Writes the derived sequence to `out` (must not exist yet); returns hard_case.json's
    content."""
    import cv2
    if every < 1:
        raise ValueError("--every must be >= 1")
    intr = read_intrinsics(src)
    source = sorted(read_frames(src), key=lambda f: f[0])
    if not source:
        raise ValueError("%s lists no frames" % src)
    indices, jump = select_frames(len(source), every, kidnap, frames)
    stamps, step = output_stamps([f[0] for f in source], len(indices))
    covered = []
    if cover is not None:
        start, seconds = cover
        if not 0 <= start < len(indices):
            raise ValueError("--cover %d,%g: START must be an output frame (0-%d)"
                             % (start, seconds, len(indices) - 1))
        if seconds <= 0:
            raise ValueError("--cover: SECONDS must be positive")
        covered = [j for j in range(start, len(indices))
                   if stamps[j] - stamps[start] < seconds - 1e-9]
    gt_path = os.path.join(src, "groundtruth.txt")
    gt = GroundTruth(gt_path) if os.path.exists(gt_path) else None

    os.makedirs(out)
    os.makedirs(os.path.join(out, "rgb"))
    os.makedirs(os.path.join(out, "depth"))
    shutil.copyfile(os.path.join(src, "intrinsics.txt"), os.path.join(out, "intrinsics.txt"))
    rgb_rows, depth_rows, assoc_rows, gt_stamps, gt_poses = [], [], [], [], []
    covered_set = set(covered)
    for j, s in enumerate(indices):
        t_rgb, rgb_path, t_depth, depth_path = source[s]
        t = stamps[j]
        td = t + (t_depth - t_rgb)
        name, dname = "%.6f" % t, "%.6f" % td
        colour_changed = shift is not None or j in covered_set
        depth_changed = noise or j in covered_set
        rgb_rel = "rgb/%s%s" % (name, ".png" if colour_changed
                                else os.path.splitext(rgb_path)[1])
        depth_rel = "depth/%s%s" % (dname, ".png" if depth_changed
                                    else os.path.splitext(depth_path)[1])
        if colour_changed:
            image = cv2.imread(rgb_path, cv2.IMREAD_UNCHANGED)
            if image is None:
                raise IOError("cannot read %s" % rgb_path)
            if j in covered_set:
                image = np.zeros_like(image)
            else:
                image = shift_colour(image, *shift)
            if not cv2.imwrite(os.path.join(out, rgb_rel), image):
                raise IOError("cannot write %s" % rgb_rel)
        else:
            link_or_copy(rgb_path, os.path.join(out, rgb_rel))
        if depth_changed:
            depth = cv2.imread(depth_path, cv2.IMREAD_UNCHANGED)
            if depth is None or depth.dtype != np.uint16 or depth.ndim != 2:
                raise IOError("%s: expected a 16-bit single-channel depth image" % depth_path)
            if j in covered_set:
                depth = np.zeros_like(depth)
            else:
                rng = np.random.default_rng([noise_seed, j])
                depth = kinect_depth(depth, intr["depth_scale"], rng)
            if not cv2.imwrite(os.path.join(out, depth_rel), depth):
                raise IOError("cannot write %s" % depth_rel)
        else:
            link_or_copy(depth_path, os.path.join(out, depth_rel))
        rgb_rows.append((name, rgb_rel))
        depth_rows.append((dname, depth_rel))
        assoc_rows.append((name, rgb_rel, dname, depth_rel))
        if gt is not None:
            pose = gt.pose(t_rgb)
            if pose is not None:
                gt_stamps.append(float(name))
                gt_poses.append(pose)
        if log and (j + 1) % 100 == 0:
            log("%s: %d/%d frames" % (out, j + 1, len(indices)))

    write_list(os.path.join(out, "rgb.txt"), "# color images\n# timestamp filename\n", rgb_rows)
    write_list(os.path.join(out, "depth.txt"), "# depth maps\n# timestamp filename\n",
               depth_rows)
    write_list(os.path.join(out, "associations.txt"), "", assoc_rows)
    if gt is not None:
        write_tum(os.path.join(out, "groundtruth.txt"), gt_stamps, gt_poses)
    meta = {
        "source": os.path.abspath(src),
        "every": every,
        "kidnap": list(kidnap) if kidnap is not None else None,
        "shift_colour": list(shift) if shift is not None else None,
        "noise": {"seed": noise_seed, "sigma": "0.0012 + 0.0019 (z - 0.4)^2",
                  "range_m": [KINECT_MIN_RANGE_M, KINECT_MAX_RANGE_M]} if noise else None,
        "cover": list(cover) if cover is not None else None,
        "frames": len(indices),
        "frame_interval_s": step,
        "source_index": indices,
        "jump_index": jump,
        "covered": [covered[0], covered[-1]] if covered else None,
        "ground_truth": gt is not None,
    }
    with open(os.path.join(out, "hard_case.json"), "w") as f:
        json.dump(meta, f, indent=1)
        f.write("\n")
    return meta


def main(argv=None):
    ap = argparse.ArgumentParser(
        description="Derives a hard RGB-D sequence (TUM layout) from another; see the module "
                    "docstring (bench/README.md, 'Hard cases').")
    ap.add_argument("--src", required=True, help="source sequence (TUM layout)")
    ap.add_argument("--out", required=True, help="new folder to write (must not exist)")
    ap.add_argument("--every", type=int, default=1, metavar="K",
                    help="keep every K-th frame, re-timed at the source's frame rate")
    ap.add_argument("--kidnap", metavar="AT,TO",
                    type=lambda s: parse_pair(s, int, "--kidnap"),
                    help="after frame AT jump to frame TO and go on from there")
    ap.add_argument("--frames", type=int, metavar="N", help="keep only the first N frames")
    ap.add_argument("--shift-colour", metavar="DX,DY",
                    type=lambda s: parse_pair(s, int, "--shift-colour"),
                    help="move colour DX px right and DY px down against depth")
    ap.add_argument("--noise", action="store_true",
                    help="Kinect-like depth noise, quantisation and holes")
    ap.add_argument("--noise-seed", type=int, default=7, help="seed of --noise (default 7)")
    ap.add_argument("--cover", metavar="START,SECONDS",
                    type=lambda s: parse_pair(s, float, "--cover"),
                    help="black colour and no depth from output frame START for SECONDS")
    args = ap.parse_args(argv)
    if args.frames is not None and args.frames < 1:
        ap.error("--frames must be >= 1")
    if args.cover is not None and args.cover[0] != int(args.cover[0]):
        ap.error("--cover START must be a frame index")
    if os.path.exists(args.out):
        ap.error("--out %s exists already" % args.out)
    cover = (int(args.cover[0]), args.cover[1]) if args.cover else None
    try:
        meta = derive(args.src, args.out, args.every, args.kidnap, args.frames,
                      args.shift_colour, args.noise, args.noise_seed, cover,
                      log=lambda m: print(m, file=sys.stderr, flush=True))
    except (ValueError, IOError, OSError) as exc:
        print("hard_cases.py: %s" % exc, file=sys.stderr)
        return 1
    print("wrote %d frames to %s%s%s" % (
        meta["frames"], args.out,
        "; jump at frame %d" % meta["jump_index"] if meta["jump_index"] is not None else "",
        "; covered frames %d-%d" % tuple(meta["covered"]) if meta["covered"] else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
