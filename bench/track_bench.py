#!/usr/bin/python3
"""Localisation benchmark: plenox tracking (ours) against Open3D peers, same protocol.

Protocol (DESIGN.md section 11): map from every K-th frame (0, K, 2K, ...) at ground-truth
poses, then track every frame starting from frame 0's ground-truth pose. For every sequence
this runs

    plenox map --dataset DIR --out TMP/map.plx --every K --json
    plenox track --map TMP/map.plx --dataset DIR --out TMP/ours.txt --json [--mode M]
    /usr/bin/python3 bench/peers/open3d_odometry.py --dataset DIR --out TMP/P.txt --json
    /usr/bin/python3 bench/peers/open3d_f2m.py --dataset DIR --every K --method icp ...
    /usr/bin/python3 bench/peers/open3d_f2m.py --dataset DIR --every K --method odometry ...

and scores every trajectory with the one scorer,

    plenox eval-traj --est T --gt DIR/groundtruth.txt --align none --json
    plenox eval-traj --est T --gt DIR/groundtruth.txt --align se3 --json

then prints one markdown table (a row per sequence and system) with the machine, the date and
the commit. See bench/README.md ("Localisation benchmark") for what each column means.

    /usr/bin/python3 bench/track_bench.py --synthetic --out docs/bench_track.md
"""

import argparse
import datetime
import os
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from bench_common import (PEER_PYTHON, PEERS_DIR, REPO, CommandError, cell,  # noqa: E402
                          check_keys, copy_keys, git_commit, list_sequences, log,
                          machine_line, make_synthetic, peer_env, render_table, run_json,
                          set_log_prefix, write_report)

# Peer name (--peers) -> (system label, script, extra arguments).
PEERS = {
    "odometry": ("open3d_odometry", "open3d_odometry.py", []),
    "f2m_icp": ("open3d_f2m_icp", "open3d_f2m.py", ["--method", "icp"]),
    "f2m_odometry": ("open3d_f2m_odometry", "open3d_f2m.py", ["--method", "odometry"]),
}
PEER_ORDER = ("odometry", "f2m_icp", "f2m_odometry")
MAPPING_PEERS = ("f2m_icp", "f2m_odometry")  # these build their own map and take --every

TRACK_KEYS = ("frames", "ms_per_frame_median", "ms_per_frame_p95", "lost")
EVAL_KEYS = ("ate_rmse_m", "rpe_t_m", "rpe_r_deg", "pairs")


# ----------------------------------------------------------------------------------------
# Runs. Each returns (row dict, list of problem strings).
# ----------------------------------------------------------------------------------------

def ours_map(args, name, dataset, workdir):
    """plenox map, once per sequence. Returns (map path or None, problems, note or None)."""
    if not os.access(args.plenox, os.X_OK):
        return None, ["%s ours: plenox binary not found or not executable: %s"
                      % (name, args.plenox)], None
    map_path = os.path.join(workdir, "map.plx")
    cmd = [args.plenox, "map", "--dataset", dataset, "--out", map_path,
           "--every", str(args.every), "--json"] + args.plenox_arg
    try:
        m = run_json("%s ours map" % name, cmd, args.timeout)
    except CommandError as exc:
        return None, [str(exc)], None
    if not os.path.exists(map_path):
        return None, ["%s ours map: `plenox map` succeeded but wrote no %s"
                      % (name, map_path)], None
    note = "%s ours map: %s keyframes, %s s, %s MB" % (
        name, m.get("keyframes", "?"), fmt_num(m.get("seconds")), fmt_num(m.get("map_mb")))
    return map_path, [], note


def fmt_num(v, spec="%.1f"):
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        return spec % v
    return "?"


def ours_track(args, name, dataset, map_path, mode, workdir):
    label = "%s %s track" % (name, system_name(mode))
    row, problems = {}, []
    traj = os.path.join(workdir, "ours%s.txt" % ("_" + mode if mode else ""))
    cmd = [args.plenox, "track", "--map", map_path, "--dataset", dataset, "--out", traj,
           "--json"] + args.plenox_arg
    if mode:
        cmd += ["--mode", mode]
    try:
        t = run_json(label, cmd, args.timeout)
    except CommandError as exc:
        return row, [str(exc)], None
    problems += check_keys(label, t, TRACK_KEYS)
    copy_keys(t, row, TRACK_KEYS)
    if not os.path.exists(traj):
        return row, problems + ["%s: `plenox track` succeeded but wrote no %s"
                                % (label, traj)], None
    return row, problems, traj


def peer_track(args, name, dataset, peer, workdir):
    system, script, extra = PEERS[peer]
    label = "%s %s" % (name, system)
    row, problems = {}, []
    traj = os.path.join(workdir, system + ".txt")
    cmd = [PEER_PYTHON, os.path.join(PEERS_DIR, script), "--dataset", dataset, "--out", traj]
    if peer in MAPPING_PEERS:
        cmd += ["--every", str(args.every)]
    if args.peer_depth_max is not None:
        cmd += ["--depth-max", repr(args.peer_depth_max)]
    cmd += extra + ["--json"]
    try:
        p = run_json(label, cmd, args.timeout, env=peer_env())
    except CommandError as exc:
        return row, [str(exc)], None
    problems += check_keys(label, p, TRACK_KEYS)
    copy_keys(p, row, TRACK_KEYS)
    row["detail"] = peer_detail(p)
    row["open3d"] = p.get("open3d")
    if not os.path.exists(traj):
        return row, problems + ["%s: the peer succeeded but wrote no %s" % (label, traj)], None
    return row, problems, traj


def peer_detail(p):
    """One line of the peer's settings, from its own JSON."""
    method = p.get("method")
    if method is None:  # frame-to-frame odometry
        s = "frame-to-frame RGB-D odometry, %s Jacobian, iterations %s, depth_max %s m" % (
            p.get("jacobian"), p.get("iterations"), p.get("depth_max"))
    else:
        s = ("TSDF from %s keyframes at GT poses (voxel %s m, integration depth_max %s m), "
             "ray-cast at the previous estimate, " % (p.get("keyframes"), p.get("voxel_size"),
                                                      p.get("map_depth_max")))
        if method == "icp":
            s += ("point-to-plane ICP (frame and model voxel %s m, max distance %s m, %s "
                  "iterations, frame depth_max %s m, lost below fitness %s)" % (
                      p.get("icp_voxel"), p.get("icp_max_distance"), p.get("icp_iterations"),
                      p.get("depth_max"), p.get("icp_min_fitness")))
        else:
            s += "RGB-D odometry against the render (%s Jacobian, iterations %s, " \
                 "depth_max %s m)" % (p.get("jacobian"), p.get("iterations"),
                                      p.get("depth_max"))
    lost = p.get("lost_frames")
    if lost:
        s += "; lost frames %s, each given %s" % (
            lost, "the previous relative motion" if p.get("on_failure") == "previous"
            else "no motion")
    return s


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
        if e.get("pairs") == 0:
            # No pose pair is 1 m of path apart: RPE is undefined. A scorer that leaves the
            # RPE keys out then (rather than reporting null) gets 'n/a', not 'failed'.
            for k in ("rpe_t_m", "rpe_r_deg"):
                e.setdefault(k, None)
        # RPE does not depend on a global alignment: it is read from the --align none run.
        problems += check_keys(label, e, EVAL_KEYS if align == "none" else ("ate_rmse_m",))
        if "ate_rmse_m" in e:
            row["ate_" + align] = e["ate_rmse_m"]
        if align == "none":
            copy_keys(e, row, ("rpe_t_m", "rpe_r_deg", "pairs"))
    return problems


def system_name(mode):
    return "ours (%s)" % mode if mode else "ours"


# ----------------------------------------------------------------------------------------
# Report
# ----------------------------------------------------------------------------------------

def table(rows, header_lines, notes):
    cols = ["sequence", "system", "frames", "ATE none (cm)", "ATE se3 (cm)", "RPE_t (cm)",
            "RPE_r (deg)", "RPE pairs", "ms/frame median", "ms/frame p95", "lost"]
    body = []
    for seq, system, row in rows:
        body.append([seq, system,
                     cell(row, "frames", "%d"),
                     cell(row, "ate_none", "%.2f", 100.0),
                     cell(row, "ate_se3", "%.2f", 100.0),
                     cell(row, "rpe_t_m", "%.2f", 100.0),
                     cell(row, "rpe_r_deg", "%.2f"),
                     cell(row, "pairs", "%d"),
                     cell(row, "ms_per_frame_median", "%.1f"),
                     cell(row, "ms_per_frame_p95", "%.1f"),
                     cell(row, "lost", "%d")])
    return render_table(cols, body, header_lines, notes)


# ----------------------------------------------------------------------------------------
# Main
# ----------------------------------------------------------------------------------------

def parse_list(values):
    out = []
    for v in values or []:
        out += [s.strip() for s in v.split(",") if s.strip()]
    return out


def main():
    set_log_prefix("track_bench")
    ap = argparse.ArgumentParser(
        description="Localisation benchmark: plenox tracking vs Open3D peers "
                    "(bench/README.md).")
    ap.add_argument("--plenox", default=os.path.join(REPO, "build", "clients", "plenox",
                                                     "plenox"),
                    help="plenox binary (default build/clients/plenox/plenox in the repo)")
    ap.add_argument("--data", default=os.path.join(os.path.dirname(REPO), "shared", "data"),
                    help="folder of TUM-layout sequences (default ../shared/data)")
    ap.add_argument("--sequences", help="comma-separated folder names under --data "
                                        "(default: all)")
    ap.add_argument("--synthetic", action="store_true",
                    help="also run a sequence generated by `plenox synth`")
    ap.add_argument("--every", type=int, default=10,
                    help="map keyframe stride K (default 10)")
    ap.add_argument("--peers", default=",".join(PEER_ORDER),
                    help="comma-separated peers out of %s, or 'none' (default: all)"
                         % ", ".join(PEER_ORDER))
    ap.add_argument("--peer-depth-max", type=float,
                    help="passed to every peer as --depth-max: the depth (metres) beyond "
                         "which frame depth is ignored while tracking (default: the peers' "
                         "default, 4 m)")
    ap.add_argument("--mode", action="append",
                    help="plenox track --mode (gn, adam, ...); repeat it or separate with "
                         "commas for a row per mode. Default: one row with the CLI's default "
                         "mode, no --mode passed.")
    ap.add_argument("--rpe-delta", type=float, default=1.0,
                    help="RPE pose pairs this many metres of path apart (default 1; the dev "
                         "sequences are too short for 1 m pairs under evo's rule)")
    ap.add_argument("--plenox-arg", action="append", default=[], metavar="ARG",
                    help="extra argument for every `plenox map`/`eval-map`/`track` run, "
                         "e.g. --plenox-arg=--backend=cuda (repeatable; --opt=value form)")
    ap.add_argument("--timeout", type=float, default=3600.0,
                    help="limit per command in seconds (default 3600)")
    ap.add_argument("--out", help="also write the markdown table to this file")
    args = ap.parse_args()
    if args.every < 1:
        ap.error("--every must be >= 1")
    peers = [] if args.peers.strip().lower() == "none" else parse_list([args.peers])
    unknown = [p for p in peers if p not in PEERS]
    if unknown:
        ap.error("unknown peer(s) %s; choose from %s" % (", ".join(unknown),
                                                        ", ".join(PEER_ORDER)))
    modes = parse_list(args.mode) or [None]
    args.plenox = os.path.abspath(args.plenox)
    data_dir = os.path.abspath(args.data)
    wanted = None
    if args.sequences:
        wanted = [s.strip() for s in args.sequences.split(",") if s.strip()]

    notes = []
    started = datetime.datetime.now(datetime.timezone.utc)
    machine = machine_line()
    seqs = list_sequences(data_dir, wanted, notes, need_ground_truth=True)

    rows = []
    any_failed = False
    synth_failed = False

    def problem(p):
        nonlocal any_failed
        notes.append(p)
        log("FAILED " + p.splitlines()[0])
        any_failed = True

    with tempfile.TemporaryDirectory(prefix="track_bench_") as tmp:
        if args.synthetic:
            synth_dir = os.path.join(tmp, "synthetic")
            try:
                make_synthetic(args.plenox, synth_dir, args.timeout)
                seqs.append(("synthetic", synth_dir))
            except CommandError as exc:
                problem("synthetic: `plenox synth` failed: %s" % exc)
                synth_failed = True

        for name, path in seqs:
            log("=== sequence %s (%s)" % (name, path))
            work = os.path.join(tmp, name)
            os.makedirs(work, exist_ok=True)
            if not os.path.exists(os.path.join(path, "groundtruth.txt")):
                problem("%s: no groundtruth.txt; every system needs frame 0's pose and the "
                        "scorer needs the rest" % name)
                for mode in modes:
                    rows.append((name, system_name(mode), {}))
                for peer in peers:
                    rows.append((name, PEERS[peer][0], {}))
                continue

            map_path, problems, map_note = ours_map(args, name, path, work)
            for p in problems:
                problem(p)
            if map_note:
                notes.append(map_note)
            for mode in modes:
                system = system_name(mode)
                row = {}
                if map_path is not None:
                    row, problems, traj = ours_track(args, name, path, map_path, mode, work)
                    for p in problems:
                        problem(p)
                    if traj is not None:
                        for p in score(args, name, system, path, traj, row):
                            problem(p)
                rows.append((name, system, row))

            for peer in peers:
                system = PEERS[peer][0]
                row, problems, traj = peer_track(args, name, path, peer, work)
                for p in problems:
                    problem(p)
                if traj is not None:
                    if os.access(args.plenox, os.X_OK):
                        for p in score(args, name, system, path, traj, row):
                            problem(p)
                    else:
                        problem("%s %s: not scored: plenox binary not found or not "
                                "executable: %s" % (name, system, args.plenox))
                rows.append((name, system, row))
                if "detail" in row:
                    notes.append("%s %s: %s" % (name, system, row["detail"]))

            for seq, system, row in rows:
                if seq == name and row.get("pairs") == 0:
                    notes.append("%s: no pose pair is %g m of path apart (evo's rule), so RPE "
                                 "is undefined (n/a)" % (name, args.rpe_delta))
                    break

    if synth_failed:
        for mode in modes:
            rows.append(("synthetic", system_name(mode), {}))
        for peer in peers:
            rows.append(("synthetic", PEERS[peer][0], {}))

    peer_list = ", ".join(PEERS[p][0] for p in peers)
    versions = sorted({str(r["open3d"]) for _, _, r in rows if r.get("open3d")})
    commit = git_commit()
    header = [
        "## Localisation benchmark",
        "",
        "- date: %s" % started.strftime("%Y-%m-%d %H:%M UTC"),
        "- machine: %s" % machine,
        "- protocol: map frames 0, %d, %d, ... (--every %d) at ground-truth poses, track "
        "every frame from frame 0's ground-truth pose; every trajectory is scored by `plenox "
        "eval-traj` (RPE over pose pairs %g m of path apart)"
        % (args.every, 2 * args.every, args.every, args.rpe_delta),
        "- plenox: %s%s; track mode: %s" % (
            args.plenox, " (commit %s)" % commit if commit else "",
            ", ".join(m for m in modes if m) or "CLI default"),
        "- peers: %s" % (peer_list + " (Open3D %s, CPU, OMP_WAIT_POLICY=passive)"
                         % (", ".join(versions) or "version not reported") if peers else "none"),
        "- timings are wall-clock on a possibly shared machine: compare them only between "
        "runs on the same machine at similar load",
    ]
    text = table(rows, header, notes)
    write_report(text, args.out)
    return 1 if any_failed else 0


if __name__ == "__main__":
    sys.exit(main())
