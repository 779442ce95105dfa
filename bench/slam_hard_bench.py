#!/usr/bin/python3
"""Hard-case SLAM benchmark (issue 21, "SLAM that is never lost"): `plenox slam` in its default
mode on sequences made to lose a tracker, with the per-frame states and times it reports.

Cases (bench/README.md, "Hard-case SLAM benchmark"):

  teddy ×K        tum_fr3_teddy (and infinitam_teddy) with every K-th frame, K = 1..4
                  (bench/hard_cases.py --every K: K times the motion per frame at 30 Hz)
  synthetic       `plenox synth` paths: circle (the reference), head-turns, walk-out
  derived         from the synthetic circle by bench/hard_cases.py: colour shifted 4,2 px,
                  Kinect-like noise and holes, lens covered for 1 s, a kidnap

For every case it runs

    plenox slam --dataset DIR --out TMP/traj.txt --frames-out TMP/frames.csv --json
    plenox eval-traj --est TMP/traj.txt --gt DIR/groundtruth.txt --align se3 --json  # with GT

and prints one markdown table (a row per case) and the issue's goals, each marked MET or NOT
MET as measured.

    /usr/bin/python3 bench/slam_hard_bench.py --out docs/bench_slam_hard.md
    /usr/bin/python3 bench/slam_hard_bench.py --quick --cases teddy,kidnap
"""

import argparse
import csv
import datetime
import json
import os
import shutil
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_common import (REPO, CommandError, cell, check_keys, git_commit,  # noqa: E402
                          log, machine_line, make_synthetic, read_rows, render_table,
                          run_json, set_log_prefix, write_report)

# The keys of `plenox slam --json` this benchmark reads.
SLAM_KEYS = ("processed", "keyframes", "lost", "degraded", "relocalised",
             "ms_per_frame_median", "ms_per_frame_max", "fps")
# Map segments started after a loss and joined again (docs/SLAM.md, "Map segments").
SEGMENT_KEYS = ("segments", "segments_joined")
RELOCALISED_STATES = ("OK", "RELOCALISED")

# Goals of issue 21 (2 CPU cores, 640x480, default mode).
TEDDY_ATE_GOAL_M = 0.015      # ATE (SE(3)) on tum_fr3_teddy at every 1st-3rd frame
TEDDY_ATE_EVERY = (1, 2, 3)
KIDNAP_FRAMES_GOAL = 10       # relocalised within this many frames of the jump
RELOCALISED_TOLERANCE_M = 0.10  # a "relocalised" pose further than this from GT is not
WORST_RATIO_GOAL = 2.0        # worst frame <= 2x the median
FPS_GOAL = 10.0

NOT_APPLICABLE = "–"

# Case keys (--cases) in table order.
CASE_KEYS = ("teddy", "infinitam", "circle", "head-turns", "walk-out", "shift", "noise",
             "cover", "kidnap", "cover-walk")


def settings(quick):
    """Sizes of the generated cases: the goal's 640x480, or --quick's 320x240 and fewer
    frames."""
    if quick:
        return {"width": 320, "height": 240, "circle": 180, "head-turns": 150,
                "walk-out": 210, "shift": (2, 1), "cover": (60, 1.0), "kidnap": (119, 20),
                "cover-walk": (50, 1.5),
                "infinitam_frames": 150, "infinitam_every": (1,)}
    return {"width": 640, "height": 480, "circle": 360, "head-turns": 300, "walk-out": 300,
            "shift": (4, 2), "cover": (90, 1.0), "kidnap": (239, 60), "cover-walk": (50, 1.5),
            "infinitam_frames": None, "infinitam_every": (1, 2, 3, 4)}


def case_list(s, wanted, everies):
    """(key, row name, recipe) in table order. A recipe is ("synth", path, frames) or
    ("derive", base, hard_cases.derive keyword arguments); base is ("data", folder) or
    ("synth", "circle")."""
    cases = []
    if "teddy" in wanted:
        for k in everies:
            cases.append(("teddy", "tum_fr3_teddy ×%d" % k,
                          ("derive", ("data", "tum_fr3_teddy"), {"every": k})))
    if "infinitam" in wanted:
        for k in s["infinitam_every"]:
            if k in everies:
                cases.append(("infinitam", "infinitam_teddy ×%d" % k,
                              ("derive", ("data", "infinitam_teddy"),
                               {"every": k, "frames": s["infinitam_frames"]})))
    circle = ("synth", "circle")
    if "circle" in wanted:
        cases.append(("circle", "synthetic circle", ("synth", "circle", s["circle"])))
    if "head-turns" in wanted:
        cases.append(("head-turns", "synthetic head turns",
                      ("synth", "head-turns", s["head-turns"])))
    if "walk-out" in wanted:
        cases.append(("walk-out", "synthetic walk-out", ("synth", "walk-out", s["walk-out"])))
    if "shift" in wanted:
        cases.append(("shift", "synthetic colour shifted %d,%d px" % s["shift"],
                      ("derive", circle, {"shift": s["shift"]})))
    if "noise" in wanted:
        cases.append(("noise", "synthetic Kinect noise + holes",
                      ("derive", circle, {"noise": True})))
    if "cover" in wanted:
        cases.append(("cover", "synthetic lens covered %g s" % s["cover"][1],
                      ("derive", circle, {"cover": s["cover"]})))
    if "kidnap" in wanted:
        cases.append(("kidnap", "synthetic kidnap %d→%d" % s["kidnap"],
                      ("derive", circle, {"kidnap": s["kidnap"]})))
    if "cover-walk" in wanted:
        # The lens covered while the walk-out path leaves the mapped half: uncovered, the camera
        # sees only space the map never saw (docs/SLAM.md, "Map segments").
        cases.append(("cover-walk", "synthetic walk-out, lens covered %g s on the way" %
                      s["cover-walk"][1],
                      ("derive", ("synth", "walk-out"), {"cover": s["cover-walk"]})))
    return cases


# ----------------------------------------------------------------------------------------
# Datasets
# ----------------------------------------------------------------------------------------

class Datasets:
    """Makes each case's dataset once, under root; remembers failures."""

    def __init__(self, args, s, root):
        self.args, self.s, self.root = args, s, root
        self.made = {}  # key -> path or CommandError
        os.makedirs(root, exist_ok=True)

    def synth(self, path, frames):
        key = ("synth", path, frames)
        if key not in self.made:
            out = os.path.join(self.root, "synthetic_%s_%d" % (path, frames))
            try:
                if os.path.exists(out):
                    shutil.rmtree(out)
                make_synthetic(self.args.plenox, out, self.args.timeout, frames,
                               ["--width", str(self.s["width"]), "--height",
                                str(self.s["height"]), "--path", path])
                self.made[key] = out
            except CommandError as exc:
                self.made[key] = exc
        return self.made[key]

    def base(self, base):
        if base[0] == "data":
            path = os.path.join(self.args.data, base[1])
            if not os.path.exists(os.path.join(path, "intrinsics.txt")):
                return CommandError("%s: not a TUM-layout sequence (no intrinsics.txt)" % path)
            return path
        return self.synth(base[1], self.s[base[1]])

    def derive(self, name, base, ops):
        src = self.base(base)
        if isinstance(src, CommandError):
            return CommandError("%s: its source could not be made: %s" % (name, src))
        key = ("derive", src, json.dumps(ops, sort_keys=True))
        if key not in self.made:
            out = os.path.join(self.root, "case_%d" % len(self.made))
            log("%s: bench/hard_cases.py %s from %s" % (name, ops, src))
            try:
                import hard_cases  # numpy and cv2: only the derived cases need them
                if os.path.exists(out):
                    shutil.rmtree(out)
                hard_cases.derive(src, out, log=log, **ops)
                self.made[key] = out
            except ImportError as exc:
                self.made[key] = CommandError("%s: bench/hard_cases.py needs numpy and cv2 "
                                              "(scripts/install_deps.sh --bench): %s"
                                              % (name, exc))
            except (ValueError, OSError) as exc:
                self.made[key] = CommandError("%s: bench/hard_cases.py failed: %s"
                                              % (name, exc))
        return self.made[key]

    def make(self, name, recipe):
        if recipe[0] == "synth":
            return self.synth(recipe[1], recipe[2])
        return self.derive(name, recipe[1], recipe[2])


def read_meta(dataset):
    path = os.path.join(dataset, "hard_case.json")
    if not os.path.exists(path):
        return {}
    with open(path) as f:
        return json.load(f)


# ----------------------------------------------------------------------------------------
# One case
# ----------------------------------------------------------------------------------------

def source_frames(dataset):
    """{timestamp rounded to 0.1 ms: index} of the sequence's frames (associations.txt), or
    None when it has no such list. A realtime run (`--slam-arg=--realtime`) drops frames, so
    its processed frame numbers are not the sequence's: the covered span and the kidnap's jump
    are in the sequence's numbers."""
    path = os.path.join(dataset, "associations.txt")
    if not os.path.exists(path):
        return None
    return {round(float(r[0]), 4): i for i, r in enumerate(read_rows(path))}


def read_states(csv_path, sources=None):
    """[(frame, state, ms)] of `plenox slam --frames-out`; `frame` is the sequence's frame
    number when `sources` (source_frames) knows the frame's timestamp."""
    with open(csv_path) as f:
        rows = list(csv.DictReader(f))
    def frame_of(r):
        if sources is None:
            return int(r["frame"])
        return sources.get(round(float(r["timestamp"]), 4), int(r["frame"]))
    return [(frame_of(r), r["state"], float(r["ms"])) for r in rows]


def first_back(states, start, errors=None, tolerance=None):
    """Frames from `start` to the first frame tracked again (OK or RELOCALISED) and, when
    `errors` (position error per frame, m) is given, within `tolerance` of ground truth; or
    None."""
    for frame, state, _ in states:
        if frame < start or state not in RELOCALISED_STATES:
            continue
        if errors is not None and not (errors.get(frame) is not None and
                                       errors[frame] <= tolerance):
            continue
        return frame - start
    return None


def position_errors(traj_path, dataset, sources=None):
    """{frame: |estimated - ground-truth position|} (m, no alignment: the run starts at frame
    0's ground truth; None where ground truth has no pose), frames numbered as read_states
    numbers them, or None when the sequence has no ground truth or numpy is missing."""
    gt_path = os.path.join(dataset, "groundtruth.txt")
    if not os.path.exists(gt_path):
        return None
    try:
        import numpy as np
        from bench_common import GroundTruth
    except ImportError:
        return None
    gt = GroundTruth(gt_path)
    errors = {}
    for i, r in enumerate(read_rows(traj_path)):
        pose = gt.pose(float(r[0]), max_dt=1e-3)
        frame = i if sources is None else sources.get(round(float(r[0]), 4), i)
        errors[frame] = (None if pose is None else
                         float(np.linalg.norm(np.array([float(x) for x in r[1:4]]) - pose[:3, 3])))
    return errors


def frame_ranges(frames):
    """[3, 4, 5, 9] -> '3-5, 9'."""
    out, start, prev = [], None, None
    for f in sorted(frames):
        if start is None:
            start = prev = f
        elif f == prev + 1:
            prev = f
        else:
            out.append("%d" % start if start == prev else "%d-%d" % (start, prev))
            start = prev = f
    if start is not None:
        out.append("%d" % start if start == prev else "%d-%d" % (start, prev))
    return ", ".join(out)


def run_case(args, key, name, dataset, work):
    """Runs and scores one case. Returns (row, problems)."""
    row, problems = {}, []
    meta = read_meta(dataset)
    traj = os.path.join(work, "traj.txt")
    frames_csv = os.path.join(work, "frames.csv")
    cmd = args.prefix + [args.plenox, "slam", "--dataset", dataset, "--out", traj,
                         "--frames-out", frames_csv, "--json"] + args.slam_arg
    try:
        j = run_json("%s slam" % name, cmd, args.timeout)
    except CommandError as exc:
        return row, [str(exc)]
    problems += check_keys("%s slam" % name, j, SLAM_KEYS)
    for k in SLAM_KEYS + SEGMENT_KEYS:
        if k in j:
            row[k] = j[k]
    med, worst = j.get("ms_per_frame_median"), j.get("ms_per_frame_max")
    if isinstance(med, (int, float)) and isinstance(worst, (int, float)) and med > 0:
        row["worst_ratio"] = worst / med

    if os.path.exists(os.path.join(dataset, "groundtruth.txt")):
        label = "%s eval-traj --align se3" % name
        try:
            e = run_json(label, [args.plenox, "eval-traj", "--est", traj, "--gt",
                                 os.path.join(dataset, "groundtruth.txt"), "--align", "se3",
                                 "--json"], args.timeout)
            problems += check_keys(label, e, ("ate_rmse_m",))
            if "ate_rmse_m" in e:
                row["ate_se3"] = e["ate_rmse_m"]
        except CommandError as exc:
            problems.append(str(exc))

    try:
        sources = source_frames(dataset)
        states = read_states(frames_csv, sources)
    except (OSError, KeyError, ValueError) as exc:
        problems.append("%s: cannot read `plenox slam --frames-out` %s: %s"
                        % (name, frames_csv, exc))
        return row, problems
    # Where LOST frames are allowed: the covered span, the kidnap's relocalisation frames.
    allowed, back_from = set(), None
    if meta.get("covered"):
        first, last = meta["covered"]
        allowed = set(range(first, last + 1))
        if key == "cover-walk":
            # Uncovered in unseen space: relocalisation has its frames before a segment starts.
            allowed |= set(range(last + 1, last + 1 + KIDNAP_FRAMES_GOAL))
        back_from = last + 1
        row["span"] = "covered frames %d-%d" % (first, last)
    if meta.get("jump_index") is not None:
        back_from = meta["jump_index"]
        allowed = set(range(back_from, back_from + KIDNAP_FRAMES_GOAL))
        row["span"] = "jump at frame %d" % back_from
    lost = [f for f, s, _ in states if s == "LOST"]
    row["lost_frames"] = lost
    row["lost_outside"] = [f for f in lost if f not in allowed]
    # The sequence's last frame the run reached (frames are the sequence's numbers).
    last_frame = states[-1][0] if states else -1
    if back_from is not None and back_from > last_frame:
        row["reloc"] = None  # the run ended first (--max-frames): n/a
        row["span"] += " (not reached)"
    elif back_from is not None:
        # A frame reported OK far from the truth (the tracker did not notice the jump) is not
        # relocalised: with ground truth, only a tracked frame near it counts.
        try:
            errors = position_errors(traj, dataset, sources)
        except (OSError, ValueError, IndexError) as exc:
            problems.append("%s: cannot compare the trajectory with ground truth: %s"
                            % (name, exc))
            errors = None
        back = first_back(states, back_from, errors, RELOCALISED_TOLERANCE_M)
        row["reloc"] = back if back is not None else float("inf")
        if errors is not None:
            end = back_from + back if back is not None else last_frame + 1
            row["wrong_ok"] = [f for f, st, _ in states if back_from <= f < end and
                               st in RELOCALISED_STATES]
            if back is not None:
                row["reloc_error_m"] = errors.get(back_from + back)
    return row, problems


# ----------------------------------------------------------------------------------------
# Table and goals
# ----------------------------------------------------------------------------------------

COLUMNS = (  # (header, row key, format, scale)
    ("frames", "processed", "%d", 1.0),
    ("LOST", "lost", "%d", 1.0),
    ("DEGRADED", "degraded", "%d", 1.0),
    ("RELOCALISED", "relocalised", "%d", 1.0),
    ("keyframes", "keyframes", "%d", 1.0),
    ("ATE se3 (cm)", "ate_se3", "%.2f", 100.0),
    ("ms/frame median", "ms_per_frame_median", "%.1f", 1.0),
    ("worst ms", "ms_per_frame_max", "%.1f", 1.0),
    ("worst/median", "worst_ratio", "%.2f", 1.0),
    ("frames/s", "fps", "%.2f", 1.0),
    ("frames to relocalise", "reloc", "%d", 1.0),
    ("segments", "segments", "%d", 1.0),
    ("joined", "segments_joined", "%d", 1.0),
)


def table(rows, header, notes):
    cols = ["case"] + [c[0] for c in COLUMNS]
    body = []
    for name, row, has_gt in rows:
        cells = []
        for _, k, spec, scale in COLUMNS:
            if (k == "ate_se3" and not has_gt) or (k == "reloc" and "span" not in row and
                                                   row):
                cells.append(NOT_APPLICABLE)
            elif k == "reloc" and row.get("reloc") == float("inf"):
                cells.append("never")
            else:
                cells.append(cell(row, k, spec, scale))
        body.append([name] + cells)
    return render_table(cols, body, header, notes)


def goal_lines(rows, quick):
    out = []

    def verdict(ok):
        return "MET" if ok else "NOT MET"

    measured = [(n, r) for n, r, _ in rows if r]
    failed = [n for n, r, _ in rows if not r]
    missing = " (no result for %s)" % ", ".join(failed) if failed else ""

    # No LOST frame outside the covered lens and the kidnap's relocalisation.
    bad = [(n, r["lost_outside"]) for n, r in measured
           if "lost_outside" in r and r["lost_outside"]]
    unknown = [n for n, r in measured if "lost_outside" not in r]
    out.append("goal: no LOST frame on any case except the covered-lens stretch (and the "
               "kidnap's first %d frames after the jump): %s%s%s" % (
                   KIDNAP_FRAMES_GOAL,
                   verdict(not bad and not unknown and not failed),
                   "; LOST at " + "; ".join("%s: %d (frames %s)" % (n, len(f), frame_ranges(f))
                                           for n, f in bad) if bad else "",
                   missing + (" (per-frame states not read for %s)" % ", ".join(unknown)
                              if unknown else "")))

    for n, r in measured:
        if "reloc" not in r or not r.get("span", "").startswith("jump"):
            continue
        back, err = r["reloc"], r.get("reloc_error_m")
        if back is None:
            out.append("goal %s: relocalised within %d frames: not measured (the run ended "
                       "before the jump)" % (n, KIDNAP_FRAMES_GOAL))
            continue
        out.append("goal %s: relocalised within %d frames: %s (%s)" % (
            n, KIDNAP_FRAMES_GOAL, verdict(back <= KIDNAP_FRAMES_GOAL),
            "never tracked again" if back == float("inf") else
            "%d frames after the jump%s" % (back, "" if err is None else
                                            ", %.1f cm from ground truth" % (100 * err))))
    for n, r in measured:
        if r.get("span", "").startswith("covered") and r.get("reloc") is not None:
            back = r["reloc"]
            out.append("%s: tracked again %s after the lens is uncovered" % (
                n, "never" if back == float("inf") else "%d frames" % back))
    for n, r in measured:
        if r.get("wrong_ok"):
            out.append("%s: frames %s were reported tracked (OK/RELOCALISED) but lie more than "
                       "%.0f cm from ground truth (%s): not counted as relocalised" % (
                           n, frame_ranges(r["wrong_ok"]), 100 * RELOCALISED_TOLERANCE_M,
                           r["span"]))

    teddy = [(n, r) for n, r in measured if n.startswith("tum_fr3_teddy ×") and
             int(n.split("×")[1]) in TEDDY_ATE_EVERY]
    if teddy:
        vals = ["%s %s" % (n.split(" ")[1], "%.2f cm" % (100 * r["ate_se3"]) if "ate_se3" in r
                           else "failed") for n, r in teddy]
        ok = all(r.get("ate_se3", 1e9) <= TEDDY_ATE_GOAL_M for _, r in teddy) and \
            len(teddy) == len(TEDDY_ATE_EVERY)
        out.append("goal: tum_fr3_teddy ATE (SE(3)) <= %.1f cm at every 1st-3rd frame: %s (%s)"
                   % (100 * TEDDY_ATE_GOAL_M, verdict(ok), ", ".join(vals)))

    def per_case(title, key, ok_fn, fmt):
        vals = [(n, r.get(key)) for n, r in measured]
        bad = [(n, v) for n, v in vals if not isinstance(v, (int, float)) or not ok_fn(v)]
        out.append("goal: %s: %s%s%s" % (
            title, verdict(not bad and not failed),
            "; not met by " + ", ".join("%s (%s)" % (n, fmt % v if isinstance(v, (int, float))
                                                     else "not reported") for n, v in bad)
            if bad else "", missing))

    per_case("every frame within its budget, worst frame <= %gx the median (LOST frames "
             "included)" % WORST_RATIO_GOAL, "worst_ratio", lambda v: v <= WORST_RATIO_GOAL,
             "%.2fx")
    per_case(">= %g frames/s wall-clock with mapping running" % FPS_GOAL, "fps",
             lambda v: v >= FPS_GOAL, "%.2f")
    if quick:
        out.append("quick mode: the synthetic cases ran at 320x240 with fewer frames, not at "
                   "the goals' 640x480, so these verdicts are indicative only")
    return out


# ----------------------------------------------------------------------------------------
# Main
# ----------------------------------------------------------------------------------------

def parse_list(text):
    return [s.strip() for s in text.split(",") if s.strip()]


def main():
    set_log_prefix("slam_hard_bench")
    ap = argparse.ArgumentParser(
        description="Hard-case SLAM benchmark (issue 21; bench/README.md).")
    ap.add_argument("--plenox", default=os.path.join(REPO, "build", "clients", "plenox",
                                                     "plenox"),
                    help="plenox binary (default build/clients/plenox/plenox in the repo)")
    ap.add_argument("--data", default=os.path.join(os.path.dirname(REPO), "shared", "data"),
                    help="folder with tum_fr3_teddy and infinitam_teddy (default "
                         "../shared/data)")
    ap.add_argument("--cases", default=",".join(CASE_KEYS),
                    help="comma-separated subset of %s (default: all)" % ",".join(CASE_KEYS))
    ap.add_argument("--every", default="1,2,3,4",
                    help="the K of the teddy ×K rows (default 1,2,3,4)")
    ap.add_argument("--quick", action="store_true",
                    help="synthetic cases at 320x240 with fewer frames, infinitam_teddy ×1 "
                         "only and its first 150 frames")
    ap.add_argument("--cpus", metavar="LIST",
                    help="run plenox slam under `taskset -c LIST` (e.g. 0,1 for the goals' "
                         "2 cores)")
    ap.add_argument("--slam-arg", action="append", default=[], metavar="ARG",
                    help="extra argument for every `plenox slam` run, e.g. "
                         "--slam-arg=--backend=cuda (repeatable; --opt=value form)")
    ap.add_argument("--timeout", type=float, default=3600.0,
                    help="limit per command in seconds (default 3600)")
    ap.add_argument("--keep", metavar="DIR",
                    help="keep the generated sequences and the runs in DIR (default: a "
                         "temporary folder, deleted at the end)")
    ap.add_argument("--out", help="also write the report to this file")
    args = ap.parse_args()
    wanted = parse_list(args.cases)
    bad = [c for c in wanted if c not in CASE_KEYS]
    if bad:
        ap.error("unknown case(s) %s; choose from %s" % (", ".join(bad), ",".join(CASE_KEYS)))
    try:
        everies = [int(k) for k in parse_list(args.every)]
        if any(k < 1 for k in everies):
            raise ValueError
    except ValueError:
        ap.error("--every: comma-separated integers >= 1")
    args.plenox = os.path.abspath(args.plenox)
    args.data = os.path.abspath(args.data)
    args.prefix = []
    if args.cpus:
        if not shutil.which("taskset"):
            ap.error("--cpus needs taskset (util-linux)")
        args.prefix = ["taskset", "-c", args.cpus]
    s = settings(args.quick)
    cases = case_list(s, wanted, everies)

    notes, rows = [], []
    any_failed = False
    started = datetime.datetime.now(datetime.timezone.utc)
    machine = machine_line()
    if args.keep:
        root = os.path.abspath(args.keep)
        os.makedirs(root, exist_ok=True)
        cleanup = None
    else:
        cleanup = tempfile.TemporaryDirectory(prefix="slam_hard_bench_")
        root = cleanup.name
    try:
        datasets = Datasets(args, s, os.path.join(root, "sequences"))
        for i, (key, name, recipe) in enumerate(cases):
            log("=== %s" % name)
            dataset = datasets.make(name, recipe)
            if isinstance(dataset, CommandError):
                any_failed = True
                notes.append("%s: no dataset: %s" % (name, dataset))
                rows.append((name, {}, True))  # every cell says failed
                continue
            work = os.path.join(root, "runs", "%02d_%s" % (i, key))
            os.makedirs(work, exist_ok=True)
            row, problems = run_case(args, key, name, dataset, work)
            for p in problems:
                any_failed = True
                notes.append(p)
                log("FAILED " + p.splitlines()[0])
            if row.get("lost_frames"):
                notes.append("%s: LOST frames %s%s" % (
                    name, frame_ranges(row["lost_frames"]),
                    " (%s)" % row["span"] if "span" in row else ""))
            rows.append((name, row, os.path.exists(os.path.join(dataset, "groundtruth.txt"))))
    finally:
        if cleanup is not None:
            cleanup.cleanup()

    commit = git_commit()
    header = [
        "## Hard-case SLAM benchmark",
        "",
        "- date: %s" % started.strftime("%Y-%m-%d %H:%M UTC"),
        "- machine: %s%s" % (machine, "; plenox slam pinned with taskset -c %s" % args.cpus
                             if args.cpus else ""),
        "- plenox: %s (repository at commit %s); `plenox slam` default mode%s" % (
            args.plenox, commit or "unknown",
            "; extra flags: %s" % " ".join(args.slam_arg) if args.slam_arg else ""),
        "- %s: synthetic cases at %dx%d; derived cases from the synthetic circle (%d frames) "
        "by bench/hard_cases.py; teddy ×K keeps every K-th frame re-timed at 30 Hz" % (
            "quick mode" if args.quick else "full mode", s["width"], s["height"], s["circle"]),
        "- every run starts at frame 0's ground-truth pose when the sequence has one "
        "(infinitam_teddy has none: ATE `%s`); ATE is `plenox eval-traj --align se3`. "
        "Timings are wall-clock on a possibly shared machine" % NOT_APPLICABLE,
    ]
    text = table(rows, header, goal_lines(rows, args.quick) + notes)
    write_report(text, args.out)
    return 1 if any_failed else 0


if __name__ == "__main__":
    sys.exit(main())
