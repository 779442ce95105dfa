#!/usr/bin/python3
"""Loop closure inside SLAM (issue 22; docs/BENCHMARKS.md, "Loop closure"): `plenox slam` on
every sequence twice, with loop closure and with --no-loop-closure, same flags otherwise.

    /usr/bin/python3 bench/loop_closure_slam_bench.py [--cases teddy,infinitam,laps,...]
        [--quick] [--deterministic | --realtime] [--keep DIR] [--out FILE]

Cases: the real sequences (tum_fr3_teddy, infinitam_teddy) and synthetic ones made here: two
laps of the room's circle (`laps`), the same with Kinect-like depth noise and holes
(`laps-noise`), at three times the motion per frame (`laps-fast`), the head-turning circle
(`head-turns`), a figure eight through the room's centre, one turn and a quarter (`eight`),
and a figure eight through two rooms joined by a doorway, 1.2 turns (`two-rooms`). Per run it
reads the JSON (frames, LOST, keyframes, loops accepted and rejected,
corrections, ATE of the online trajectory and of the trajectory in the map's final frame),
--frames-out (the tracking times: median, p99, p99/median) and --loops-out: each loop edge is
compared with the ground truth's relative pose between its two keyframes, and one more than
5 cm or 2 degrees from it is a false loop ("–" without ground truth).
"""

import argparse
import csv
import datetime
import json
import os
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_common import (REPO, CommandError, git_commit, log, machine_line,  # noqa: E402
                          percentile, quat_to_rot, read_rows, run_json, set_log_prefix)
from slam_hard_bench import Datasets, settings  # noqa: E402

CASE_KEYS = ["teddy", "infinitam", "laps", "laps-noise", "laps-fast", "head-turns", "eight",
             "two-rooms"]
FALSE_LOOP_M = 0.05
FALSE_LOOP_DEG = 2.0


def case_list(s, wanted):
    """(key, row name, recipe) as slam_hard_bench.Datasets makes them."""
    laps = 2 * 360  # the circle takes 12 s, 360 frames at 30 Hz
    cases = []
    if "teddy" in wanted:
        cases.append(("teddy", "tum_fr3_teddy", ("data", "tum_fr3_teddy")))
    if "infinitam" in wanted:
        cases.append(("infinitam", "infinitam_teddy", ("data", "infinitam_teddy")))
    if "laps" in wanted:
        cases.append(("laps", "synthetic circle, two laps", ("synth", "circle", laps)))
    if "laps-noise" in wanted:
        cases.append(("laps-noise", "synthetic two laps, Kinect noise + holes",
                      ("derive", ("synth", "circle"), {"noise": True})))
    if "laps-fast" in wanted:
        cases.append(("laps-fast", "synthetic two laps ×3",
                      ("derive", ("synth", "circle"), {"every": 3})))
    if "head-turns" in wanted:
        cases.append(("head-turns", "synthetic head turns",
                      ("synth", "head-turns", s["head-turns"])))
    if "eight" in wanted:
        # One turn and a quarter (20 s each): the second pass over the first lobe closes it.
        cases.append(("eight", "synthetic figure eight, 1.25 turns",
                      ("synth", "figure-eight", 750)))
    if "two-rooms" in wanted:
        # 1.2 turns of 30 s: the second visit to each room closes a loop there.
        cases.append(("two-rooms", "synthetic figure eight through two rooms, 1.2 turns",
                      ("synth", "two-room-eight", 1080)))
    return cases


def pose_matrix(values):
    """4x4 of tx ty tz qx qy qz qw."""
    import numpy as np
    m = np.eye(4)
    m[:3, :3] = quat_to_rot([float(v) for v in values[3:7]])
    m[:3, 3] = [float(v) for v in values[:3]]
    return m


def false_loops(loops_path, dataset):
    """(false, checked, worst cm, worst deg): loop edges of --loops-out against the ground
    truth; None without it."""
    gt_path = os.path.join(dataset, "groundtruth.txt")
    if not os.path.exists(gt_path):
        return None
    import numpy as np
    from bench_common import GroundTruth
    gt = GroundTruth(gt_path)
    wrong = checked = 0
    worst_m = worst_deg = 0.0
    for r in read_rows(loops_path):
        a, b = gt.pose(float(r[0]), max_dt=0.02), gt.pose(float(r[1]), max_dt=0.02)
        if a is None or b is None:
            continue
        truth = np.linalg.inv(a) @ b
        measured = pose_matrix(r[2:9])
        error = np.linalg.inv(truth) @ measured
        angle = np.degrees(np.arccos(np.clip((np.trace(error[:3, :3]) - 1) / 2, -1, 1)))
        checked += 1
        wrong += np.linalg.norm(error[:3, 3]) > FALSE_LOOP_M or angle > FALSE_LOOP_DEG
        worst_m = max(worst_m, np.linalg.norm(error[:3, 3]))
        worst_deg = max(worst_deg, angle)
    return wrong, checked, worst_m, worst_deg


def frame_times(csv_path):
    """[(ms, a rebuild ran)] per frame of --frames-out."""
    with open(csv_path) as f:
        return [(float(r["ms"]), r.get("rebuilding") == "1") for r in csv.DictReader(f)]


def run(args, name, dataset, work, loop_closure):
    os.makedirs(work, exist_ok=True)
    files = {k: os.path.join(work, k) for k in ("traj.txt", "corrected.txt", "loops.txt",
                                                 "frames.csv")}
    cmd = args.prefix + [args.plenox, "slam", "--dataset", dataset, "--out", files["traj.txt"],
                         "--corrected-out", files["corrected.txt"], "--loops-out",
                         files["loops.txt"], "--frames-out", files["frames.csv"], "--json"]
    if not loop_closure:
        cmd.append("--no-loop-closure")
    if args.deterministic:
        cmd.append("--deterministic")
    if args.realtime:
        cmd.append("--realtime")
    j = run_json("%s%s" % (name, "" if loop_closure else " (no loop closure)"), cmd,
                 args.timeout)
    with open(os.path.join(work, "result.json"), "w") as f:
        json.dump(j, f, indent=1)
    if loop_closure:
        log("%s: %s sequential edges measured from the images, %s of them used by the last "
            "solve" % (name, j.get("links_measured", "?"), j.get("last_measured_edges", "?")))
    times = frame_times(files["frames.csv"])
    ms = [t for t, _ in times]
    during = [t for t, rebuilding in times if rebuilding]
    row = dict(j)
    row["p50"] = percentile(ms, 50)
    row["p99"] = percentile(ms, 99)
    # The goal's measure: tracking p99 while a correction's rebuild runs, against the p50.
    row["rebuild_frames"] = len(during)
    row["p99_rebuilding"] = percentile(during, 99) if during else None
    row["false"] = false_loops(files["loops.txt"], dataset)
    return row


def fmt(value, spec, scale=1.0):
    return "–" if value is None else spec % (value * scale)


def table_row(name, lc, r):
    false = r["false"]
    spec = ("| %s | %s | %s | %d | %d | %d | %d | %s | %s | %s | %s | %s | %.0f | %.0f | "
            "%.2f | %s | %.1f | %.0f |")
    return spec % (
        name, "on" if lc else "off",
        "%d" % r["processed"] if not r.get("dropped") else "%d (%d dropped)" % (
            r["processed"], r["dropped"]),
        r["lost"], r["keyframes"],
        r.get("loops_accepted", 0), r.get("loops_rejected", 0),
        "–" if false is None else "%d/%d" % false[:2],
        "–" if not false or not false[1] else "%.1f / %.2f" % (100 * false[2], false[3]),
        "%d (%d)" % (r.get("corrections", 0), r.get("corrections_in_place", 0)),
        fmt(r.get("ate_se3_m"), "%.2f", 100), fmt(r.get("corrected_ate_se3_m"), "%.2f", 100),
        r["p50"], r["p99"], r["p99"] / max(r["p50"], 1e-9),
        "–" if r["p99_rebuilding"] is None else "%.2f (%d frames)" % (
            r["p99_rebuilding"] / max(r["p50"], 1e-9), r["rebuild_frames"]),
        r["fps"], r["wall_s"])


def main():
    set_log_prefix("loop_closure_slam_bench")
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plenox", default=os.path.join(REPO, "build", "clients", "plenox",
                                                     "plenox"))
    ap.add_argument("--data", default=os.path.join(os.path.dirname(REPO), "shared", "data"))
    ap.add_argument("--cases", default=",".join(CASE_KEYS),
                    help="comma-separated subset of %s" % ",".join(CASE_KEYS))
    ap.add_argument("--quick", action="store_true", help="synthetic cases at 320x240")
    ap.add_argument("--deterministic", action="store_true",
                    help="map in lock-step (plenox slam --deterministic): the difference loop "
                         "closure makes without the CPU it takes from concurrent mapping")
    ap.add_argument("--realtime", action="store_true",
                    help="replay at the frames' timestamps, dropping what tracking cannot keep "
                         "up with, as a live camera (plenox slam --realtime); default: every "
                         "frame as fast as it is tracked")
    ap.add_argument("--loop-closure", choices=("both", "on", "off"), default="both",
                    help="run each case with and without loop closure (both), or one side "
                         "only (a change to loop closure alone leaves the 'off' rows as they "
                         "were: rerun only 'on')")
    ap.add_argument("--keep", help="make the sequences under this folder and keep them (a "
                                   "second run reuses nothing; it only keeps them to look at)")
    ap.add_argument("--timeout", type=float, default=3600.0)
    ap.add_argument("--out", help="also write the report here")
    args = ap.parse_args()
    wanted = [c for c in args.cases.split(",") if c]
    bad = [c for c in wanted if c not in CASE_KEYS]
    if bad:
        ap.error("unknown case(s) %s" % ", ".join(bad))
    if args.deterministic and args.realtime:
        ap.error("--deterministic maps in lock-step; a realtime replay cannot wait for it")
    args.plenox = os.path.abspath(args.plenox)
    args.data = os.path.abspath(args.data)
    args.prefix = []
    s = settings(args.quick)
    s["circle"] = 2 * 360  # the derived cases start from the two-lap circle
    mode = ("lock-step" if args.deterministic else
            "realtime replay" if args.realtime else "concurrent, every frame")
    lines = ["Machine: %s; commit %s; %s UTC; %s." % (
                 machine_line(), git_commit(),
                 datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M"),
                 mode),
             "",
             "| sequence | loop closure | frames | LOST | keyframes | loops | rejected | "
             "false/checked | worst loop error cm / deg | corrections (in place) | "
             "ATE online (cm) | ATE final frame (cm) | median ms | p99 ms | p99/median | "
             "p99 rebuilding/median | frames/s | wall s |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | "
             "--- | --- | --- | --- | --- |"]
    failed = False
    with tempfile.TemporaryDirectory(prefix="loop_closure_slam_bench_") as tmp:
        root = os.path.abspath(args.keep) if args.keep else tmp
        datasets = Datasets(args, s, os.path.join(root, "sequences"))
        for key, name, recipe in case_list(s, wanted):
            dataset = (datasets.base(recipe) if recipe[0] == "data" else
                       datasets.make(name, recipe))
            if isinstance(dataset, CommandError):
                log(str(dataset))
                failed = True
                continue
            for lc in {"both": (True, False), "on": (True,), "off": (False,)}[args.loop_closure]:
                try:
                    r = run(args, name, dataset, os.path.join(root, key, str(lc)), lc)
                except CommandError as exc:
                    log(str(exc))
                    failed = True
                    continue
                lines.append(table_row(name, lc, r))
                print(lines[-1], flush=True)
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        with open(args.out, "w") as f:
            f.write(text)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
