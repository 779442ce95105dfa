#!/usr/bin/python3
"""SLAM benchmark: `plenox slam` (ours) against two Open3D peers, same protocol.

Every system starts at frame 0's ground-truth pose and uses no other ground truth. For every
sequence this runs

    plenox slam --dataset DIR --out TMP/ours.txt --map-out TMP/slam.plx \\
        --keyframes-out TMP/kf.txt --json                               # row "ours"
    plenox slam ... --realtime --json                                   # row "ours (realtime)"
    /usr/bin/python3 bench/peers/open3d_odometry.py --dataset DIR --out TMP/P.txt --json
    /usr/bin/python3 bench/peers/open3d_kinfu.py --dataset DIR --out TMP/P.txt --json

scores every trajectory with the one scorer,

    plenox eval-traj --est T --gt DIR/groundtruth.txt --align none|se3 --json

and scores the SLAM maps beside a map built from ground-truth poses:

    plenox map --dataset DIR --every K --out TMP/gt.plx --json
    plenox eval-map --map M --dataset DIR --every K --pixels 0 --json   # M: slam.plx, gt.plx

It prints one markdown table (a row per sequence and system) with the machine, the date and
the commit, then whether each goal was met, as measured. bench/README.md ("SLAM benchmark")
explains the protocol and the columns.

    /usr/bin/python3 bench/slam_bench.py --out docs/bench_slam.md
"""

import argparse
import datetime
import os
import shutil
import subprocess
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_common import (PEER_PYTHON, PEERS_DIR, REPO, CommandError, cell,  # noqa: E402
                          check_keys, copy_keys, git_commit, list_sequences, log,
                          machine_line, make_synthetic, peer_env, read_frames, read_rows,
                          render_table, run_json, set_log_prefix, write_report)

# Our two rows: (system label, extra `plenox slam` flags, file suffix).
OURS_MODES = {
    "default": ("ours", [], ""),
    "realtime": ("ours (realtime)", ["--realtime"], "_realtime"),
}
# Peer name (--peers) -> (system label, script).
PEERS = {
    "odometry": ("open3d_odometry", "open3d_odometry.py"),
    "kinfu": ("open3d_kinfu", "open3d_kinfu.py"),
}
PEER_ORDER = ("odometry", "kinfu")
GT_MAP_SYSTEM = "GT-pose map (plenox map)"

# The keys `plenox slam --json` always prints (ATE/RPE only when the dataset has ground truth).
SLAM_KEYS = ("frames", "processed", "dropped", "keyframes", "ok", "degraded", "lost",
             "relocalised", "ms_per_frame_median", "ms_per_frame_p95", "fps", "wall_s",
             "mapping_iterations", "map_mb", "keyframe_mb", "peak_rss_mb",
             "started_from_ground_truth", "trajectory")
PEER_KEYS = ("frames", "ms_per_frame_median", "ms_per_frame_p95", "fps", "lost", "map_mb",
             "peak_rss_mb")
EVAL_TRAJ_KEYS = ("ate_rmse_m", "rpe_t_m", "rpe_r_deg", "pairs")
EVAL_MAP_KEYS = ("psnr", "depth_l1_m", "coverage", "frames")
MAP_KEYS = ("keyframes", "map_mb", "peak_rss_mb")

# Depth limit the peers get with --peer-depth-max auto: sequences from a real sensor keep
# Open3D's dense-SLAM limit (the Xtion's depth beyond 3 m is noisy and coarse; bench/README.md,
# localisation peers), rendered ones keep everything up to the protocol's 10 m (the synthetic
# room's walls are 2-5 m away).
REAL_SENSOR_PREFIXES = ("tum_", "scannet")
PEER_DEPTH_MAX_REAL = 3.0
PEER_DEPTH_MAX_RENDERED = 10.0

# Goals (DESIGN / the SLAM brief): ATE after SE(3) alignment, default mode.
ATE_GOALS_M = {"tum_fr3_teddy": 0.015, "replica_room0": 0.005, "synthetic": 0.003}
FPS_GOAL = 5.0
REALTIME_ATE_RATIO = 1.5
DEPTH_L1_RATIO = 1.25

NOT_APPLICABLE = "–"


# ----------------------------------------------------------------------------------------
# Runs. Each returns (row dict, list of problem strings[, ...]).
# ----------------------------------------------------------------------------------------

def slam_available(plenox):
    """None when `plenox slam --help` works, else why not."""
    if not os.access(plenox, os.X_OK):
        return "plenox binary not found or not executable: %s" % plenox
    try:
        r = subprocess.run([plenox, "slam", "--help"], stdin=subprocess.DEVNULL,
                           capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.SubprocessError) as exc:
        return "cannot run %s slam --help: %s" % (plenox, exc)
    if r.returncode != 0:
        said = [l.strip() for l in (r.stderr + "\n" + r.stdout).splitlines() if l.strip()]
        return ("this plenox build has no working `slam` command (`plenox slam --help` exited "
                "%d: %s); build a plenox that has it (clients/plenox/cmd_slam.cc)"
                % (r.returncode, said[0] if said else "no output"))
    return None


def ours_slam(args, name, dataset, mode, work):
    """plenox slam in one mode. Returns (row, problems, trajectory or None, map or None,
    keyframes file or None, the JSON or None)."""
    system, extra, suffix = OURS_MODES[mode]
    label = "%s %s" % (name, system)
    row, problems = {}, []
    traj = os.path.join(work, "ours%s.txt" % suffix)
    map_path = os.path.join(work, "slam%s.plx" % suffix)
    kf_path = os.path.join(work, "kf%s.txt" % suffix)
    cmd = [args.plenox, "slam", "--dataset", dataset, "--out", traj, "--map-out", map_path,
           "--keyframes-out", kf_path, "--json"] + extra + args.plenox_arg + args.slam_arg
    try:
        j = run_json(label, cmd, args.timeout)
    except CommandError as exc:
        return row, [str(exc)], None, None, None, None
    problems += check_keys(label, j, SLAM_KEYS)
    copy_keys(j, row, ("keyframes", "lost", "ms_per_frame_median", "ms_per_frame_p95", "fps",
                       "map_mb", "peak_rss_mb"))
    if "processed" in j:
        row["frames"] = j["processed"]  # poses in the trajectory: one per processed frame
    outputs = []
    for path, what in ((traj, "trajectory"), (map_path, "map"), (kf_path, "keyframes")):
        if os.path.exists(path):
            outputs.append(path)
        else:
            problems.append("%s: `plenox slam` succeeded but wrote no %s (%s)"
                            % (label, what, path))
            outputs.append(None)
    return (row, problems) + tuple(outputs) + (j,)


def peer_run(args, name, dataset, peer, depth_max, work):
    system, script = PEERS[peer]
    label = "%s %s" % (name, system)
    row, problems = {}, []
    traj = os.path.join(work, system + ".txt")
    cmd = [PEER_PYTHON, os.path.join(PEERS_DIR, script), "--dataset", dataset, "--out", traj,
           "--depth-max", repr(depth_max), "--json"]
    try:
        p = run_json(label, cmd, args.timeout, env=peer_env())
    except CommandError as exc:
        return row, [str(exc)], None, None
    problems += check_keys(label, p, PEER_KEYS)
    copy_keys(p, row, PEER_KEYS + ("keyframes",))
    row["open3d"] = p.get("open3d")
    if not os.path.exists(traj):
        return row, problems + ["%s: the peer succeeded but wrote no %s" % (label, traj)], \
            None, p
    return row, problems, traj, p


def peer_detail(p):
    """One line of a peer's settings and diagnostics, from its own JSON."""
    if p.get("system") == "open3d_kinfu":
        s = ("KinectFusion: TSDF voxel %s m, depth_max %s m, ray cast at the previous "
             "estimate, projective point-to-plane ICP iterations %s (coarse to fine), "
             "every tracked frame fused; %s; median ms: ray cast %s, ICP %s, fusion %s; "
             "%s hash-map rehash(es), capacity %s blocks, %s active" % (
                 p.get("voxel_size"), p.get("depth_max"), p.get("iterations"),
                 "Open3D as shipped" if p.get("as_shipped")
                 else "half-pixel and half-voxel corrections on",
                 fmt_num(p.get("ray_cast_ms_median"), "%.0f"),
                 fmt_num(p.get("icp_ms_median"), "%.0f"),
                 fmt_num(p.get("fuse_ms_median"), "%.0f"), p.get("rehashes"),
                 p.get("block_count"), p.get("active_blocks")))
    else:
        s = ("frame-to-frame RGB-D odometry, %s Jacobian, iterations %s, depth_max %s m"
             % (p.get("jacobian"), p.get("iterations"), p.get("depth_max")))
    if p.get("lost_frames"):
        s += "; lost frames %s" % p.get("lost_frames")
    return s


def fmt_num(v, spec="%.1f"):
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        return spec % v
    return "?"


def score(args, name, system, dataset, traj, row):
    """Scores traj with `plenox eval-traj` (--align none, then se3) into row."""
    problems = []
    gt = os.path.join(dataset, "groundtruth.txt")
    for align in ("none", "se3"):
        label = "%s %s eval-traj --align %s" % (name, system, align)
        cmd = [args.plenox, "eval-traj", "--est", traj, "--gt", gt, "--align", align,
               "--delta", repr(args.rpe_delta), "--json"]
        try:
            e = run_json(label, cmd, args.timeout)
        except CommandError as exc:
            problems.append(str(exc))
            continue
        if e.get("pairs") == 0:  # no pose pair --delta metres of path apart: RPE undefined
            for k in ("rpe_t_m", "rpe_r_deg"):
                e.setdefault(k, None)
        problems += check_keys(label, e, EVAL_TRAJ_KEYS if align == "none"
                               else ("ate_rmse_m",))
        if "ate_rmse_m" in e:
            row["ate_" + align] = e["ate_rmse_m"]
        if align == "none":
            copy_keys(e, row, ("rpe_t_m", "rpe_r_deg", "pairs"))
    return problems


def eval_map(args, name, system, dataset, map_path, row):
    """`plenox eval-map` on the held-out frames (i % K == K // 2) at their ground-truth
    poses, every valid pixel."""
    label = "%s %s eval-map" % (name, system)
    cmd = [args.plenox, "eval-map", "--map", map_path, "--dataset", dataset,
           "--every", str(args.every), "--pixels", "0", "--json"] + args.plenox_arg
    try:
        e = run_json(label, cmd, args.timeout)
    except CommandError as exc:
        return [str(exc)]
    problems = check_keys(label, e, EVAL_MAP_KEYS)
    copy_keys(e, row, ("psnr", "depth_l1_m", "depth_l1_median_m", "coverage"))
    if "frames" in e:
        row["heldout_frames"] = e["frames"]
    return problems


def gt_map(args, name, dataset, work):
    """The reference: `plenox map` from every K-th frame at ground-truth poses."""
    row, problems = {}, []
    label = "%s gt map" % name
    map_path = os.path.join(work, "gt.plx")
    cmd = [args.plenox, "map", "--dataset", dataset, "--every", str(args.every), "--out",
           map_path, "--json"] + args.plenox_arg
    try:
        m = run_json(label, cmd, args.timeout)
    except CommandError as exc:
        return row, [str(exc)]
    problems += check_keys(label, m, MAP_KEYS)
    copy_keys(m, row, MAP_KEYS)
    if not os.path.exists(map_path):
        return row, problems + ["%s: `plenox map` succeeded but wrote no %s"
                                % (label, map_path)]
    return row, problems + eval_map(args, name, GT_MAP_SYSTEM, dataset, map_path, row)


def heldout_keyframes(dataset, every, kf_path):
    """How many held-out frames (i % K == K // 2) the SLAM run made keyframes, matched by RGB
    timestamp (1 ms). Returns (count, held-out frames) or None if the files cannot be read."""
    try:
        frames = read_frames(dataset)  # needs numpy only without associations.txt
        kf_stamps = [float(r[0]) for r in read_rows(kf_path)]
    except (OSError, ValueError, IndexError, AttributeError):
        return None
    held = [frames[i][0] for i in range(len(frames)) if i % every == every // 2]
    count = sum(1 for t in held if any(abs(t - k) < 1e-3 for k in kf_stamps))
    return count, len(held)


def peer_depth_max(args, name):
    if args.peer_depth_max != "auto":
        return float(args.peer_depth_max)
    if name.startswith(REAL_SENSOR_PREFIXES):
        return PEER_DEPTH_MAX_REAL
    return PEER_DEPTH_MAX_RENDERED


# ----------------------------------------------------------------------------------------
# Goals: measured, never assumed. Each is MET, NOT MET, or not measured (and why).
# ----------------------------------------------------------------------------------------

def number(row, key):
    v = row.get(key) if row else None
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return None
    return float(v)


def goal_notes(seq_names, rows, peer_systems, modes):
    table = {(seq, system): row for seq, system, row in rows}
    out = []

    def verdict(ok):
        return "MET" if ok else "NOT MET"

    def missing(what):
        return "not measured (%s)" % what

    for seq in seq_names:
        ours = table.get((seq, OURS_MODES["default"][0]))
        ate = number(ours, "ate_se3")
        if seq in ATE_GOALS_M:
            goal = ATE_GOALS_M[seq]
            res = missing("no ATE for ours") if ate is None else "%s (%.2f cm)" % (
                verdict(ate <= goal), 100 * ate)
            out.append("goal %s: ours ATE (SE(3)) <= %.1f cm: %s" % (seq, 100 * goal, res))
        for peer in peer_systems:
            p = number(table.get((seq, peer)), "ate_se3")
            if ate is None or p is None:
                res = missing("ATE of %s" % ("ours" if ate is None else peer))
            else:
                res = "%s (%.2f cm vs %.2f cm)" % (verdict(ate < p), 100 * ate, 100 * p)
            out.append("goal %s: ours ATE (SE(3)) below %s: %s" % (seq, peer, res))
        fps = number(ours, "fps")
        out.append("goal %s: ours >= %g frames/s (wall clock, default mode): %s" % (
            seq, FPS_GOAL, missing("no frames/s for ours") if fps is None
            else "%s (%.2f frames/s)" % (verdict(fps >= FPS_GOAL), fps)))
        if "realtime" in modes:
            rt = number(table.get((seq, OURS_MODES["realtime"][0])), "ate_se3")
            if ate is None or rt is None:
                res = missing("ATE of ours%s" % ("" if ate is None else " (realtime)"))
            else:
                res = "%s (%.2f cm vs %.2f cm)" % (
                    verdict(rt <= REALTIME_ATE_RATIO * ate), 100 * rt, 100 * ate)
            out.append("goal %s: ours (realtime) ATE (SE(3)) within %gx of the default "
                       "mode's: %s" % (seq, REALTIME_ATE_RATIO, res))
        l1 = number(ours, "depth_l1_m")
        ref = number(table.get((seq, GT_MAP_SYSTEM)), "depth_l1_m")
        if l1 is None or ref is None:
            res = missing("depth L1 of the %s" % ("SLAM map" if l1 is None else
                                                   "ground-truth-pose map"))
        else:
            res = "%s (%.2f cm vs %.2f cm)" % (verdict(l1 <= DEPTH_L1_RATIO * ref),
                                                100 * l1, 100 * ref)
        out.append("goal %s: SLAM map held-out depth L1 within %gx of the ground-truth-pose "
                   "map's: %s" % (seq, DEPTH_L1_RATIO, res))
    return out


# ----------------------------------------------------------------------------------------
# Report
# ----------------------------------------------------------------------------------------

COLUMNS = (  # (header, row key, format, scale)
    ("frames", "frames", "%d", 1.0),
    ("keyframes", "keyframes", "%d", 1.0),
    ("lost", "lost", "%d", 1.0),
    ("ATE none (cm)", "ate_none", "%.2f", 100.0),
    ("ATE se3 (cm)", "ate_se3", "%.2f", 100.0),
    ("RPE_t (cm)", "rpe_t_m", "%.2f", 100.0),
    ("RPE_r (deg)", "rpe_r_deg", "%.2f", 1.0),
    ("ms/frame median", "ms_per_frame_median", "%.1f", 1.0),
    ("ms/frame p95", "ms_per_frame_p95", "%.1f", 1.0),
    ("frames/s", "fps", "%.2f", 1.0),
    ("map MB", "map_mb", "%.1f", 1.0),
    ("peak RSS MB", "peak_rss_mb", "%.0f", 1.0),
    ("held-out depth L1 (cm)", "depth_l1_m", "%.2f", 100.0),
    ("held-out PSNR (dB)", "psnr", "%.2f", 1.0),
    ("coverage", "coverage", "%.3f", 1.0),
)
MAP_QUALITY = ("depth_l1_m", "psnr", "coverage")
TRAJECTORY = ("frames", "lost", "ate_none", "ate_se3", "rpe_t_m", "rpe_r_deg",
              "ms_per_frame_median", "ms_per_frame_p95", "fps")


def not_applicable(system, peer_systems):
    """Row keys that do not apply to a system (shown as '–', not 'failed')."""
    if system == GT_MAP_SYSTEM:
        return set(TRAJECTORY)
    if system in peer_systems:
        na = set(MAP_QUALITY) | {"keyframes"}
        if system == PEERS["odometry"][0]:
            na.add("map_mb")
        return na
    return set()


def table(rows, peer_systems, header_lines, notes):
    cols = ["sequence", "system"] + [c[0] for c in COLUMNS]
    body = []
    for seq, system, row in rows:
        na = not_applicable(system, peer_systems)
        body.append([seq, system] + [NOT_APPLICABLE if key in na else cell(row, key, spec, sc)
                                     for _, key, spec, sc in COLUMNS])
    return render_table(cols, body, header_lines, notes)


# ----------------------------------------------------------------------------------------
# Main
# ----------------------------------------------------------------------------------------

def parse_list(text):
    return [s.strip() for s in text.split(",") if s.strip()]


def main():
    set_log_prefix("slam_bench")
    ap = argparse.ArgumentParser(
        description="SLAM benchmark: plenox slam vs Open3D peers (bench/README.md).")
    ap.add_argument("--plenox", default=os.path.join(REPO, "build", "clients", "plenox",
                                                     "plenox"),
                    help="plenox binary (default build/clients/plenox/plenox in the repo)")
    ap.add_argument("--data", default=os.path.join(os.path.dirname(REPO), "shared", "data"),
                    help="folder of TUM-layout sequences (default ../shared/data)")
    ap.add_argument("--sequences", help="comma-separated folder names under --data "
                                        "(default: all)")
    ap.add_argument("--synthetic-frames", type=int, default=360,
                    help="frames of the `plenox synth` sequence (row `synthetic`; default "
                         "360 = one full 12 s turn at 30 frames/s, back to the start; 0 = "
                         "no synthetic sequence)")
    ap.add_argument("--modes", default="default,realtime",
                    help="our rows: comma-separated subset of default,realtime (default "
                         "both), or none")
    ap.add_argument("--peers", default=",".join(PEER_ORDER),
                    help="comma-separated subset of %s, or none (default: all)"
                         % ",".join(PEER_ORDER))
    ap.add_argument("--peer-depth-max", default="auto",
                    help="depth limit in metres passed to every peer as --depth-max, or auto "
                         "(default): %g m for real-sensor sequences (names starting with "
                         "%s), %g m for rendered ones" % (
                             PEER_DEPTH_MAX_REAL, " or ".join(REAL_SENSOR_PREFIXES),
                             PEER_DEPTH_MAX_RENDERED))
    ap.add_argument("--every", type=int, default=10,
                    help="held-out frames are i %% K == K // 2 and the ground-truth-pose map "
                         "uses frames 0, K, 2K, ... (default 10)")
    ap.add_argument("--rpe-delta", type=float, default=1.0,
                    help="RPE pose pairs this many metres of path apart (default 1)")
    ap.add_argument("--plenox-arg", action="append", default=[], metavar="ARG",
                    help="extra argument for every `plenox slam`/`map`/`eval-map` run, e.g. "
                         "--plenox-arg=--backend=cuda (repeatable; --opt=value form)")
    ap.add_argument("--slam-arg", action="append", default=[], metavar="ARG",
                    help="extra argument for `plenox slam` only (repeatable)")
    ap.add_argument("--timeout", type=float, default=3600.0,
                    help="limit per command in seconds (default 3600)")
    ap.add_argument("--keep", metavar="DIR",
                    help="keep trajectories, maps and the synthetic sequence in DIR (default: "
                         "a temporary folder, deleted at the end)")
    ap.add_argument("--out", help="also write the report to this file")
    args = ap.parse_args()
    if args.every < 2:
        ap.error("--every must be >= 2 (held-out frames are i %% K == K // 2)")
    if args.peer_depth_max != "auto":
        try:
            if float(args.peer_depth_max) <= 0:
                raise ValueError
        except ValueError:
            ap.error("--peer-depth-max: a positive number of metres, or auto")
    modes = [] if args.modes.strip().lower() == "none" else parse_list(args.modes)
    peers = [] if args.peers.strip().lower() == "none" else parse_list(args.peers)
    bad = [m for m in modes if m not in OURS_MODES] + [p for p in peers if p not in PEERS]
    if bad:
        ap.error("unknown mode(s)/peer(s): %s" % ", ".join(bad))
    args.plenox = os.path.abspath(args.plenox)
    data_dir = os.path.abspath(args.data)
    wanted = parse_list(args.sequences) if args.sequences else None
    peer_systems = [PEERS[p][0] for p in peers]

    notes = []
    started = datetime.datetime.now(datetime.timezone.utc)
    machine = machine_line()
    seqs = list_sequences(data_dir, wanted, notes)
    rows = []
    any_failed = False

    def problem(p):
        nonlocal any_failed
        notes.append(p)
        log("FAILED " + p.splitlines()[0])
        any_failed = True

    plenox_ok = os.access(args.plenox, os.X_OK)
    slam_missing = slam_available(args.plenox) if modes else None
    if slam_missing:
        problem("ours: %s" % slam_missing)

    if args.keep:
        root = os.path.abspath(args.keep)
        os.makedirs(root, exist_ok=True)
        cleanup = None
    else:
        cleanup = tempfile.TemporaryDirectory(prefix="slam_bench_")
        root = cleanup.name
    try:
        if args.synthetic_frames > 0:
            synth_dir = os.path.join(root, "synthetic")
            try:
                if os.path.exists(synth_dir):
                    shutil.rmtree(synth_dir)
                make_synthetic(args.plenox, synth_dir, args.timeout, args.synthetic_frames)
                seqs.append(("synthetic", synth_dir))
            except CommandError as exc:
                problem("synthetic: `plenox synth --frames %d` failed: %s"
                        % (args.synthetic_frames, exc))
                for mode in modes:
                    rows.append(("synthetic", OURS_MODES[mode][0], {}))
                for peer in peers:
                    rows.append(("synthetic", PEERS[peer][0], {}))

        for name, path in seqs:
            log("=== sequence %s (%s)" % (name, path))
            work = os.path.join(root, "runs", name)
            os.makedirs(work, exist_ok=True)
            if not os.path.exists(os.path.join(path, "groundtruth.txt")):
                problem("%s: no groundtruth.txt; every system needs frame 0's pose and the "
                        "scorer needs the rest" % name)
                for mode in modes:
                    rows.append((name, OURS_MODES[mode][0], {}))
                for peer in peers:
                    rows.append((name, PEERS[peer][0], {}))
                continue

            for mode in modes:
                system = OURS_MODES[mode][0]
                row = {}
                if not slam_missing:
                    row, problems, traj, map_path, kf_path, j = ours_slam(args, name, path,
                                                                          mode, work)
                    for p in problems:
                        problem(p)
                    if traj is not None:
                        for p in score(args, name, system, path, traj, row):
                            problem(p)
                    if map_path is not None:
                        for p in eval_map(args, name, system, path, map_path, row):
                            problem(p)
                    if j is not None:
                        notes.append(slam_note(name, system, j, row, path, args.every,
                                               kf_path))
                rows.append((name, system, row))

            if modes:
                row = {}
                if plenox_ok:
                    row, problems = gt_map(args, name, path, work)
                    for p in problems:
                        problem(p)
                rows.append((name, GT_MAP_SYSTEM, row))

            depth_max = peer_depth_max(args, name)
            for peer in peers:
                system = PEERS[peer][0]
                row, problems, traj, p = peer_run(args, name, path, peer, depth_max, work)
                for q in problems:
                    problem(q)
                if traj is not None:
                    if plenox_ok:
                        for q in score(args, name, system, path, traj, row):
                            problem(q)
                    else:
                        problem("%s %s: not scored: plenox binary not found or not "
                                "executable: %s" % (name, system, args.plenox))
                if p is not None:
                    notes.append("%s %s: %s" % (name, system, peer_detail(p)))
                rows.append((name, system, row))

            no_pairs = [system for seq, system, row in rows
                        if seq == name and row.get("pairs") == 0]
            if no_pairs:
                notes.append("%s: RPE is undefined (n/a) for %s: no pose pair is %g m of path "
                             "apart. eval-traj picks the pairs along the estimated path "
                             "(evo's rule), so an estimate that wanders further can have "
                             "pairs on the same sequence" % (name, ", ".join(no_pairs),
                                                              args.rpe_delta))
    finally:
        if cleanup is not None:
            cleanup.cleanup()

    seq_names = []
    for seq, _, _ in rows:
        if seq not in seq_names:
            seq_names.append(seq)
    goals = goal_notes(seq_names, rows, peer_systems, modes) if modes else []
    versions = sorted({str(r["open3d"]) for _, _, r in rows if r.get("open3d")})
    commit = git_commit()
    depth_rule = ("%s m for every sequence" % args.peer_depth_max
                  if args.peer_depth_max != "auto" else
                  "%g m on real-sensor sequences (%s*), %g m on rendered ones" % (
                      PEER_DEPTH_MAX_REAL, "*, ".join(REAL_SENSOR_PREFIXES),
                      PEER_DEPTH_MAX_RENDERED))
    header = [
        "## SLAM benchmark",
        "",
        "- date: %s" % started.strftime("%Y-%m-%d %H:%M UTC"),
        "- machine: %s" % machine,
        "- protocol: every system starts at frame 0's ground-truth pose and uses no other "
        "ground truth; every trajectory is scored by `plenox eval-traj` (ATE RMSE with no "
        "alignment and after SE(3) alignment; RPE over pose pairs %g m of path apart). Map "
        "quality: `plenox eval-map --every %d --pixels 0` on the held-out frames "
        "(i %% %d == %d) at their ground-truth poses, for the SLAM map and for a map built "
        "by `plenox map --every %d` from ground-truth poses"
        % (args.rpe_delta, args.every, args.every, args.every // 2, args.every),
        "- plenox: %s (repository at commit %s); `plenox slam` modes: %s%s" % (
            args.plenox, commit or "unknown",
            ", ".join(modes) or "none",
            "; extra slam flags: %s" % " ".join(args.slam_arg) if args.slam_arg else ""),
        "- peers: %s" % ("%s (Open3D %s, CPU, OMP_WAIT_POLICY=passive); depth limit %s" % (
            ", ".join(peer_systems), ", ".join(versions) or "version not reported",
            depth_rule) if peers else "none"),
        "- synthetic: `plenox synth --frames %d`" % args.synthetic_frames
        if args.synthetic_frames > 0 else "- synthetic: not run",
        "- `%s`: does not apply to that system; `n/a`: the system reported null; `failed`: "
        "see the notes. Timings are wall-clock on a possibly shared machine: compare them "
        "only between runs on the same machine at similar load" % NOT_APPLICABLE,
    ]
    if modes:
        notes.insert(0, "held-out frames are scored at their ground-truth poses as they are: "
                        "`plenox eval-map` has no option to align a map to ground truth first. "
                        "The SLAM map lives in the frame of the SLAM trajectory, which starts "
                        "at frame 0's ground-truth pose, so its drift counts against its depth "
                        "L1 and PSNR. An `--align` option (SE(3) from the SLAM trajectory to "
                        "the ground truth) for eval-map is a follow-up. The SLAM run also "
                        "tracked the held-out frames, and may have made some of them keyframes "
                        "(counted per row below); the ground-truth-pose map never saw them.")
    text = table(rows, peer_systems, header, goals + notes)
    write_report(text, args.out)
    return 1 if any_failed else 0


def slam_note(name, system, j, row, dataset, every, kf_path):
    """One line of `plenox slam`'s own counts and self-scored ATE (for cross-checking)."""
    s = "%s %s: %s frames, %s processed, %s dropped; ok %s, degraded %s, lost %s, relocalised " \
        "%s; %s mapping iterations; keyframe store %s MB; wall %s s; started from ground " \
        "truth: %s" % (name, system, j.get("frames"), j.get("processed"), j.get("dropped"),
                       j.get("ok"), j.get("degraded"), j.get("lost"), j.get("relocalised"),
                       j.get("mapping_iterations"), fmt_num(j.get("keyframe_mb")),
                       fmt_num(j.get("wall_s")), j.get("started_from_ground_truth"))
    own = [(k, j.get(k)) for k in ("ate_none_m", "ate_se3_m")]
    if all(isinstance(v, (int, float)) for _, v in own):
        s += "; its own ATE none %.2f cm, se3 %.2f cm" % (100 * own[0][1], 100 * own[1][1])
        for (k, v), key in zip(own, ("ate_none", "ate_se3")):
            # More than 1 mm apart is more than the trajectory file's rounding.
            if isinstance(row.get(key), (int, float)) and abs(row[key] - v) > 1e-3:
                s += " (differs from eval-traj's %.2f cm: check!)" % (100 * row[key])
    if kf_path:
        h = heldout_keyframes(dataset, every, kf_path)
        if h is not None:
            s += "; %d of %d held-out frames were keyframes" % h
    return s


if __name__ == "__main__":
    sys.exit(main())
