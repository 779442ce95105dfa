#!/usr/bin/python3
"""Self-check of bench/hard_cases.py (the derived hard SLAM sequences) and of what the hard
benchmark needs from plenox (`synth --path`, `slam --frames-out`, `ms_per_frame_max`).

    /usr/bin/python3 tests/bench/hard_cases_test.py --plenox build/clients/plenox/plenox

Writes a tiny `plenox synth` sequence, derives every hard case from it and checks frame counts,
timestamps, ground truth, shifted colour, the covered span, the kidnap's jump and the depth
noise; then runs `plenox slam` on derived sequences, directly and through
bench/slam_hard_bench.py's scoring. Exits 0 when everything passed, 1 with
the failures listed, 77 (skip) when this interpreter lacks numpy or cv2.
"""

import argparse
import csv
import json
import os
import subprocess
import sys
import tempfile

try:
    import cv2
    import numpy as np
except ImportError as missing:
    print("SKIP: %s cannot import numpy/cv2 (%s); install Debian's python3-numpy and "
          "python3-opencv (scripts/install_deps.sh --bench)" % (sys.executable, missing))
    sys.exit(77)

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, os.path.join(REPO, "bench"))
import hard_cases  # noqa: E402
from bench_common import GroundTruth, read_frames, read_intrinsics  # noqa: E402

FRAMES, WIDTH, HEIGHT = 24, 64, 48


class Failures:
    def __init__(self):
        self.items = []

    def check(self, condition, what):
        print("  [%s] %s" % ("ok  " if condition else "FAIL", what), flush=True)
        if not condition:
            self.items.append(what)
        return condition


def run(cmd):
    return subprocess.run(cmd, stdin=subprocess.DEVNULL, capture_output=True, text=True,
                          timeout=300)


def frames_of(dataset):
    return sorted(read_frames(dataset), key=lambda f: f[0])


def colour(frame):
    return cv2.imread(frame[1], cv2.IMREAD_UNCHANGED)


def depth(frame):
    return cv2.imread(frame[3], cv2.IMREAD_UNCHANGED)


def poses(dataset):
    gt = GroundTruth(os.path.join(dataset, "groundtruth.txt"))
    return [gt.pose(f[0], max_dt=1e-6) for f in frames_of(dataset)]


def derived(work, name, src, f, **ops):
    out = os.path.join(work, name)
    meta = hard_cases.derive(src, out, **ops)
    with open(os.path.join(out, "hard_case.json")) as fh:
        f.check(json.load(fh) == json.loads(json.dumps(meta)), "%s: hard_case.json written" % name)
    return out, meta


def check_every(work, src, f):
    out, meta = derived(work, "every3", src, f, every=3)
    s, o = frames_of(src), frames_of(out)
    f.check(len(o) == FRAMES // 3 and meta["frames"] == len(o), "every 3: %d frames" % len(o))
    f.check(meta["source_index"] == list(range(0, FRAMES, 3)), "every 3: source frames 0, 3, ...")
    # Re-timed at the sensor's rate: output frame j at source frame j's stamp.
    f.check(all(abs(o[j][0] - s[j][0]) < 1e-6 for j in range(len(o))),
            "every 3: frame j keeps source frame j's timestamp")
    f.check(all(np.array_equal(colour(o[j]), colour(s[3 * j])) and
                np.array_equal(depth(o[j]), depth(s[3 * j])) for j in range(len(o))),
            "every 3: frame j shows source frame 3j")
    ps, po = poses(src), poses(out)
    f.check(all(po[j] is not None and np.allclose(po[j], ps[3 * j], atol=1e-6)
                for j in range(len(o))), "every 3: ground truth of frame j is source frame 3j's")
    moved = [np.linalg.norm(po[j + 1][:3, 3] - po[j][:3, 3]) for j in range(len(o) - 1)]
    moved_src = [np.linalg.norm(ps[j + 1][:3, 3] - ps[j][:3, 3]) for j in range(len(o) - 1)]
    f.check(np.median(moved) > 2.5 * np.median(moved_src),
            "every 3: ~3x the motion per frame (%.1f mm vs %.1f mm)"
            % (1e3 * np.median(moved), 1e3 * np.median(moved_src)))


def check_shift(work, src, f):
    out, _ = derived(work, "shift", src, f, shift=(4, 2))
    s, o = frames_of(src), frames_of(out)
    f.check(len(o) == FRAMES, "shift: every frame kept")
    a, b = colour(s[7]), colour(o[7])
    f.check(np.array_equal(b[2:, 4:], a[:-2, :-4]), "shift 4,2: colour(u, v) = source(u-4, v-2)")
    f.check(np.array_equal(b[2:, :4], np.repeat(a[:-2, :1], 4, axis=1)) and
            np.array_equal(b[:2, 4:], np.repeat(a[:1, :-4], 2, axis=0)),
            "shift 4,2: the uncovered border repeats the edge")
    f.check(not np.array_equal(a, b), "shift 4,2: the colour did change")
    f.check(all(np.array_equal(depth(o[j]), depth(s[j])) for j in range(FRAMES)),
            "shift: depth untouched")


def check_cover(work, src, f):
    out, meta = derived(work, "cover", src, f, cover=(5, 0.2))
    o, s = frames_of(out), frames_of(src)
    # 0.2 s at 30 Hz from frame 5: frames 5-10.
    f.check(meta["covered"] == [5, 10], "cover 5,0.2: frames %s covered" % meta["covered"])
    black = [j for j in range(FRAMES) if not colour(o[j]).any() and not depth(o[j]).any()]
    f.check(black == list(range(5, 11)), "cover: black colour and zero depth exactly in 5-10")
    f.check(all(np.array_equal(depth(o[j]), depth(s[j])) for j in (4, 11)),
            "cover: frames around the span untouched")
    f.check(np.allclose(poses(out)[7], poses(src)[7], atol=1e-6),
            "cover: ground truth goes on through the span")


def check_kidnap(work, src, f):
    out, meta = derived(work, "kidnap", src, f, kidnap=(15, 3))
    o, s = frames_of(out), frames_of(src)
    n = 16 + (FRAMES - 3)
    f.check(len(o) == n and meta["jump_index"] == 16, "kidnap 15,3: %d frames, jump at 16"
            % len(o))
    f.check(meta["source_index"][14:18] == [14, 15, 3, 4], "kidnap: frames ...14, 15, 3, 4...")
    step = 1.0 / 30.0
    gaps = [o[j + 1][0] - o[j][0] for j in range(n - 1)]
    f.check(all(abs(g - step) < 2e-6 for g in gaps),
            "kidnap: timestamps go on at the frame rate past the source's end")
    po, ps = poses(out), poses(src)
    f.check(np.allclose(po[16], ps[3], atol=1e-6) and np.allclose(po[15], ps[15], atol=1e-6),
            "kidnap: ground truth jumps from source frame 15 to 3")
    jump = np.linalg.norm(po[16][:3, 3] - po[15][:3, 3])
    step_m = np.linalg.norm(po[15][:3, 3] - po[14][:3, 3])
    f.check(jump > 5 * step_m, "kidnap: the jump (%.0f mm) dwarfs a step (%.0f mm)"
            % (1e3 * jump, 1e3 * step_m))
    f.check(np.array_equal(colour(o[16]), colour(s[3])), "kidnap: frame 16 shows source frame 3")
    return out


def check_noise(work, src, f):
    out, _ = derived(work, "noise", src, f, noise=True)
    again, _ = derived(work, "noise_again", src, f, noise=True)
    other, _ = derived(work, "noise_other", src, f, noise=True, noise_seed=8)
    scale = read_intrinsics(src)["depth_scale"]
    o, s = frames_of(out), frames_of(src)
    f.check(all(np.array_equal(depth(a), depth(b)) for a, b in zip(o, frames_of(again))),
            "noise: the same seed gives the same depth")
    f.check(not np.array_equal(depth(o[0]), depth(frames_of(other)[0])),
            "noise: another seed gives other depth")
    errors, sigmas, holes, total = [], [], 0, 0
    for a, b in zip(s, o):
        z0 = depth(a).astype(np.float64) / scale
        z1 = depth(b).astype(np.float64) / scale
        kept = (z0 > 0) & (z1 > 0)
        holes += int(((z0 > 0) & (z1 == 0) & (z0 <= hard_cases.KINECT_MAX_RANGE_M)).sum())
        total += int((z0 > 0).sum())
        errors.append((z1 - z0)[kept] / hard_cases.kinect_sigma(z0[kept]))
        sigmas.append(z0[kept])
    e = np.concatenate(errors)
    # Axial noise plus disparity quantisation (steps of z^2 / (8 f b), about half of sigma(z)
    # in 1-4 m): the normalised error's spread is that of N(0, 1), a little widened.
    f.check(abs(np.mean(e)) < 0.1, "noise: unbiased (mean %.3f sigma)" % np.mean(e))
    f.check(1.0 < np.std(e) < 1.4, "noise: spread %.2f sigma (noise + quantisation)" % np.std(e))
    f.check(0.03 < holes / total < 0.3, "noise: %.1f%% of the valid depth became holes"
            % (100.0 * holes / total))
    z = depth(o[0]).astype(np.float64) / scale
    far = z > 3.0
    if far.any():
        fb = hard_cases.KINECT_FOCAL_PX * hard_cases.KINECT_BASELINE_M
        steps = fb / z[far] / hard_cases.KINECT_DISPARITY_STEP_PX
        # Depth is stored in 1/scale m units, so the disparity is a whole step only to
        # within that rounding (~0.01 step at 3 m).
        f.check(np.abs(steps - np.round(steps)).max() < 0.05,
                "noise: far depth lies on disparity steps of 1/8 px")
    f.check(z.max() <= hard_cases.KINECT_MAX_RANGE_M + 1e-3, "noise: nothing beyond 4.5 m")


def check_plenox(plenox, work, kidnapped, f):
    r = run([plenox, "synth", "--out", os.path.join(work, "bad"), "--path", "spiral"])
    f.check(r.returncode != 0 and "head-turns" in r.stderr and "--path" in r.stderr,
            "plenox synth --path spiral: refused, naming the paths (%d: %s)"
            % (r.returncode, r.stderr.strip()[:120]))
    f.check(not os.path.exists(os.path.join(work, "bad")), "plenox synth --path spiral: no output")
    walk = os.path.join(work, "walk")
    r = run([plenox, "synth", "--out", walk, "--frames", "180", "--width", "16", "--height",
             "16", "--path", "walk-out"])
    if f.check(r.returncode == 0, "plenox synth --path walk-out (%s)" % r.stderr.strip()[:200]):
        p = poses(walk)
        # Stands at x = -0.7 looking along -x, ends 1.2 m further +x looking along +x.
        f.check(len(p) == 180 and p[0][0, 3] < -0.6 and p[-1][0, 3] > 0.4 and
                p[0][0, 2] < -0.9 and p[-1][0, 2] > 0.9, "walk-out: walks and turns towards +x")
    traj, csv_path = os.path.join(work, "slam.txt"), os.path.join(work, "frames.csv")
    r = run([plenox, "slam", "--dataset", kidnapped, "--out", traj, "--frames-out", csv_path,
             "--max-frames", "4", "--voxel-size", "0.08", "--iterations-per-keyframe", "2",
             "--threads", "1", "--json", "--quiet"])
    if not f.check(r.returncode == 0, "plenox slam on a derived sequence (%s)"
                   % r.stderr.strip()[-300:]):
        return
    j = json.loads(r.stdout.strip().splitlines()[-1])
    with open(csv_path) as fh:
        rows = list(csv.DictReader(fh))
    f.check(len(rows) == 4 and [int(x["frame"]) for x in rows] == [0, 1, 2, 3],
            "--frames-out: one line per processed frame")
    f.check(all(x["state"] in ("OK", "DEGRADED", "LOST", "RELOCALISED", "WAITING")
                for x in rows), "--frames-out: states %s" % [x["state"] for x in rows])
    ms = [float(x["ms"]) for x in rows]
    f.check(abs(j.get("ms_per_frame_max", -1) - max(ms)) < 1e-2 and
            j["ms_per_frame_max"] >= j["ms_per_frame_median"],
            "ms_per_frame_max (%s) is the slowest frame of the CSV (%.3f)"
            % (j.get("ms_per_frame_max"), max(ms)))
    f.check(abs(float(rows[1]["timestamp"]) - frames_of(kidnapped)[1][0]) < 1e-6,
            "--frames-out: frame timestamps")
    f.check(int(rows[0]["keyframe"]) == 1, "--frames-out: frame 0 is a keyframe")


def check_bench(plenox, work, covered, kidnapped, f):
    """bench/slam_hard_bench.py's scoring of one run: the spans where LOST is allowed, the
    frames to relocalise, the goal lines."""
    import slam_hard_bench as bench
    f.check(bench.frame_ranges([9, 3, 4, 5, 12, 13]) == "3-5, 9, 12-13", "frame_ranges")
    states = [(0, "OK", 1.0), (1, "LOST", 1.0), (2, "LOST", 1.0), (3, "RELOCALISED", 1.0),
              (4, "OK", 1.0)]
    f.check(bench.first_back(states, 1) == 2 and bench.first_back(states, 0) == 0 and
            bench.first_back(states, 5) is None, "first_back")
    # A realtime run drops frames: its states are numbered as the sequence's frames.
    dropped = os.path.join(work, "dropped_frames.csv")
    with open(dropped, "w") as fh:
        fh.write("frame,timestamp,state,ms\n0,0.000000,OK,1\n1,0.100000,LOST,2\n"
                 "2,0.166667,OK,3\n")
    sources = {0.0: 0, 0.0333: 1, 0.0667: 2, 0.1: 3, 0.1333: 4, 0.1667: 5}
    f.check(bench.read_states(dropped, sources) == [(0, "OK", 1.0), (3, "LOST", 2.0),
                                                    (5, "OK", 3.0)] and
            [x[0] for x in bench.read_states(dropped)] == [0, 1, 2],
            "read_states: sequence frame numbers of a realtime run")
    args = argparse.Namespace(plenox=plenox, prefix=[], timeout=300, slam_arg=[
        "--voxel-size=0.08", "--iterations-per-keyframe=2", "--threads=1", "--quiet",
        "--max-frames=24"], data=work)
    # The benchmark's own datasets: a synthetic path at its size, and a case derived from one.
    sizes = dict(bench.settings(quick=True), width=32, height=24, circle=12)
    made = bench.Datasets(args, sizes, os.path.join(work, "bench_sequences"))
    head = made.make("head", ("synth", "head-turns", 9))
    f.check(not isinstance(head, Exception) and len(frames_of(head)) == 9 and
            read_intrinsics(head)["width"] == 32, "bench: plenox synth --path head-turns, 32x24")
    shifted = made.make("shift", ("derive", ("synth", "circle"), {"shift": (2, 1)}))
    f.check(not isinstance(shifted, Exception) and len(frames_of(shifted)) == 12 and
            hard_cases.read_intrinsics(shifted)["height"] == 24 and
            bench.read_meta(shifted)["shift_colour"] == [2, 1],
            "bench: a case derived from the synthetic circle")
    missing = made.make("nothing", ("derive", ("data", "no_such_sequence"), {"every": 2}))
    f.check(isinstance(missing, Exception), "bench: a missing source is reported: %s" % missing)
    rows = []
    for name, dataset in (("tiny cover", covered), ("tiny kidnap", kidnapped)):
        work_dir = os.path.join(work, "bench_" + name.split()[1])
        os.makedirs(work_dir)
        row, problems = bench.run_case(args, name, name, dataset, work_dir)
        if not f.check(not problems, "%s: run and scored (%s)" % (name, problems)):
            return
        with open(os.path.join(work_dir, "frames.csv")) as fh:
            lost = [int(r["frame"]) for r in csv.DictReader(fh) if r["state"] == "LOST"]
        f.check(row["processed"] == 24 and row["lost"] == len(lost) == len(row["lost_frames"]),
                "%s: counts match the per-frame states" % name)
        f.check(row["ms_per_frame_max"] >= row["ms_per_frame_median"] and
                abs(row["worst_ratio"] - row["ms_per_frame_max"] / row["ms_per_frame_median"])
                < 1e-9, "%s: worst/median" % name)
        f.check(isinstance(row.get("ate_se3"), float), "%s: ATE from eval-traj" % name)
        rows.append((name, row, True))
    cover, kidnap = rows[0][1], rows[1][1]
    f.check(cover["span"] == "covered frames 5-10" and
            cover["lost_outside"] == [x for x in cover["lost_frames"] if not 5 <= x <= 10],
            "cover: LOST allowed only in the covered frames (LOST %s)" % cover["lost_frames"])
    # No depth at all for 6 frames: tracking cannot go on through them.
    f.check(set(range(5, 11)) <= set(cover["lost_frames"]), "cover: the covered frames are LOST")
    f.check(isinstance(cover.get("reloc"), int) or cover.get("reloc") == float("inf"),
            "cover: frames to relocalise after frame 10: %s" % cover.get("reloc"))
    f.check(kidnap["span"] == "jump at frame 16" and
            kidnap["lost_outside"] == [x for x in kidnap["lost_frames"] if not 16 <= x < 26],
            "kidnap: LOST allowed in the 10 frames from the jump (LOST %s)"
            % kidnap["lost_frames"])
    # Relocalised = the first tracked frame from the jump on that is near the truth; tracked
    # frames before it are listed as wrong.
    back = kidnap.get("reloc")
    with open(os.path.join(work, "bench_kidnap", "frames.csv")) as fh:
        tracked = [int(r["frame"]) for r in csv.DictReader(fh)
                   if r["state"] in ("OK", "RELOCALISED") and int(r["frame"]) >= 16]
    if isinstance(back, int):
        f.check(kidnap["reloc_error_m"] <= 0.10 and 16 + back in tracked and
                kidnap["wrong_ok"] == [x for x in tracked if x < 16 + back],
                "kidnap: relocalised after %d frames, %.1f cm from ground truth; wrongly "
                "tracked before: %s" % (back, 100 * kidnap["reloc_error_m"], kidnap["wrong_ok"]))
    else:
        f.check(back == float("inf") and kidnap["wrong_ok"] == tracked,
                "kidnap: never relocalised; wrongly tracked: %s" % kidnap["wrong_ok"])
    goals = bench.goal_lines(rows, quick=True)
    lost_goal = [g for g in goals if g.startswith("goal: no LOST frame")]
    met = not cover["lost_outside"] and not kidnap["lost_outside"]
    f.check(len(lost_goal) == 1 and (": MET" in lost_goal[0]) == met,
            "goal line for LOST frames agrees with the rows: %s" % lost_goal[:1])
    f.check(any(g.startswith("goal tiny kidnap: relocalised within 10 frames") for g in goals),
            "goal line for the kidnap")
    table = bench.table(rows, ["## test"], goals)
    f.check("| tiny cover | 24 | %d |" % cover["lost"] in table, "table row")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--plenox", default=os.path.join(REPO, "build", "clients", "plenox",
                                                     "plenox"))
    args = ap.parse_args()
    f = Failures()
    with tempfile.TemporaryDirectory(prefix="hard_cases_test_") as work:
        src = os.path.join(work, "src")
        r = run([args.plenox, "synth", "--out", src, "--frames", str(FRAMES), "--width",
                 str(WIDTH), "--height", str(HEIGHT)])
        if r.returncode != 0:
            print("FAIL: plenox synth: %s %s" % (r.stdout, r.stderr))
            return 1
        for name, fn in (("every", check_every), ("shift", check_shift),
                         ("cover", check_cover), ("noise", check_noise)):
            print(name, flush=True)
            fn(work, src, f)
        print("kidnap", flush=True)
        kidnapped = check_kidnap(work, src, f)
        print("bad input", flush=True)
        for i, ops in enumerate(({"kidnap": (30, 2)}, {"kidnap": (5, 6)},
                                 {"cover": (99, 1.0)}, {"every": 0})):
            try:
                hard_cases.derive(src, os.path.join(work, "bad_%d" % i), **ops)
                f.check(False, "%s refused" % ops)
            except ValueError as exc:
                f.check(True, "%s refused: %s" % (ops, exc))
        print("plenox", flush=True)
        check_plenox(args.plenox, work, kidnapped, f)
        print("bench scoring", flush=True)
        check_bench(args.plenox, work, os.path.join(work, "cover"), kidnapped, f)
    if f.items:
        print("%d check(s) failed:\n  %s" % (len(f.items), "\n  ".join(f.items)))
        return 1
    print("all checks passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
