#!/usr/bin/python3
"""Mapping benchmark: plenox (ours) against an Open3D TSDF peer, same protocol.

For every sequence this runs

    plenox map --dataset DIR --out TMP/map.plx --every K [--voxel-size M] [--time-budget S] --json
    plenox eval-map --map TMP/map.plx --dataset DIR --every K --pixels 0 --json
    /usr/bin/python3 bench/peers/open3d_tsdf.py --dataset DIR --every K [--voxel-size M] --json

and prints one markdown table (a row per sequence and system) with the machine and the date.
See bench/README.md for the protocol and what each column means.

    /usr/bin/python3 bench/map_bench.py --synthetic --out docs/bench_map.md
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

PEER = os.path.join(PEERS_DIR, "open3d_tsdf.py")

MAP_KEYS = ("keyframes", "seconds", "seconds_per_keyframe", "map_mb", "peak_rss_mb",
            "iterations")
EVAL_KEYS = ("psnr", "depth_l1_m", "depth_l1_median_m", "coverage", "frames", "pixels")
PEER_KEYS = ("keyframes", "heldout_frames", "seconds_per_keyframe", "psnr", "depth_l1_m",
             "depth_l1_median_m", "coverage", "map_mb", "peak_rss_mb")


# ----------------------------------------------------------------------------------------
# Per-system runs. Each returns (row dict, list of problem strings).
# ----------------------------------------------------------------------------------------

def run_ours(args, name, dataset, workdir):
    row, problems = {}, []
    if not os.access(args.plenox, os.X_OK):
        return row, ["%s ours: plenox binary not found or not executable: %s"
                     % (name, args.plenox)]
    map_path = os.path.join(workdir, "map.plx")
    cmd = [args.plenox, "map", "--dataset", dataset, "--out", map_path,
           "--every", str(args.every)] + args.plenox_arg
    if args.voxel_size is not None:
        cmd += ["--voxel-size", repr(args.voxel_size)]
    if args.time_budget is not None:
        cmd += ["--time-budget", repr(args.time_budget)]
    cmd.append("--json")
    try:
        m = run_json("%s ours map" % name, cmd, args.timeout)
    except CommandError as exc:
        return row, [str(exc)]
    problems += check_keys("%s ours map" % name, m, MAP_KEYS)
    copy_keys(m, row, ("keyframes", "seconds_per_keyframe", "map_mb", "peak_rss_mb",
                       "iterations"))
    cmd = [args.plenox, "eval-map", "--map", map_path, "--dataset", dataset,
           "--every", str(args.every), "--pixels", "0", "--json"] + args.plenox_arg
    try:
        e = run_json("%s ours eval-map" % name, cmd, args.timeout)
    except CommandError as exc:
        return row, problems + [str(exc)]
    problems += check_keys("%s ours eval-map" % name, e, EVAL_KEYS)
    copy_keys(e, row, ("psnr", "depth_l1_m", "depth_l1_median_m", "coverage"))
    if "frames" in e:
        row["heldout_frames"] = e["frames"]
    return row, problems


def run_peer(args, name, dataset):
    row, problems = {}, []
    cmd = [PEER_PYTHON, PEER, "--dataset", dataset, "--every", str(args.every),
           "--depth-max", repr(args.peer_depth_max)]
    if args.voxel_size is not None:
        cmd += ["--voxel-size", repr(args.voxel_size)]
    cmd.append("--json")
    try:
        p = run_json("%s open3d_tsdf" % name, cmd, args.timeout, env=peer_env())
    except CommandError as exc:
        return row, [str(exc)]
    problems += check_keys("%s open3d_tsdf" % name, p, PEER_KEYS)
    copy_keys(p, row, PEER_KEYS)
    row["detail"] = "voxel %s m, depth_max %s m, weight_threshold %s" % (
        p.get("voxel_size"), p.get("depth_max"), p.get("weight_threshold"))
    return row, problems


# ----------------------------------------------------------------------------------------
# Report
# ----------------------------------------------------------------------------------------

def table(rows, header_lines, notes):
    cols = ["sequence", "system", "keyframes", "held-out", "s/keyframe", "PSNR (dB)",
            "depth L1 mean (cm)", "depth L1 median (cm)", "coverage", "map MB",
            "peak RSS MB"]
    body = []
    for seq, system, row in rows:
        body.append([seq, system,
                     cell(row, "keyframes", "%d"),
                     cell(row, "heldout_frames", "%d"),
                     cell(row, "seconds_per_keyframe", "%.3f"),
                     cell(row, "psnr", "%.2f"),
                     cell(row, "depth_l1_m", "%.2f", 100.0),
                     cell(row, "depth_l1_median_m", "%.2f", 100.0),
                     cell(row, "coverage", "%.3f"),
                     cell(row, "map_mb", "%.1f"),
                     cell(row, "peak_rss_mb", "%.0f")])
    return render_table(cols, body, header_lines, notes)


# ----------------------------------------------------------------------------------------
# Main
# ----------------------------------------------------------------------------------------

def main():
    set_log_prefix("map_bench")
    ap = argparse.ArgumentParser(
        description="Mapping benchmark: plenox vs an Open3D TSDF peer (bench/README.md).")
    ap.add_argument("--plenox", default=os.path.join(REPO, "build", "clients", "plenox",
                                                     "plenox"),
                    help="plenox binary (default build/clients/plenox/plenox in the repo)")
    ap.add_argument("--data", default=os.path.join(os.path.dirname(REPO), "shared", "data"),
                    help="folder of TUM-layout sequences (default ../shared/data)")
    ap.add_argument("--sequences", help="comma-separated folder names under --data "
                                        "(default: all)")
    ap.add_argument("--synthetic", action="store_true",
                    help="also run a sequence generated by `plenox synth`")
    ap.add_argument("--time-budget", type=float, help="plenox map --time-budget, seconds")
    ap.add_argument("--voxel-size", type=float,
                    help="voxel edge in metres for both systems (default: each system's "
                         "default; the peer's is 0.01)")
    ap.add_argument("--every", type=int, default=10, help="keyframe stride K (default 10)")
    ap.add_argument("--peer-depth-max", type=float, default=10.0,
                    help="Open3D integration / ray-cast depth limit, metres (default 10)")
    ap.add_argument("--plenox-arg", action="append", default=[], metavar="ARG",
                    help="extra argument for every `plenox map`/`eval-map`/`track` run, "
                         "e.g. --plenox-arg=--backend=cuda (repeatable; --opt=value form)")
    ap.add_argument("--timeout", type=float, default=3600.0,
                    help="limit per command in seconds (default 3600)")
    ap.add_argument("--out", help="also write the markdown table to this file")
    args = ap.parse_args()
    if args.every < 2:
        ap.error("--every must be >= 2 (held-out frames are i %% K == K // 2)")
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
    with tempfile.TemporaryDirectory(prefix="map_bench_") as tmp:
        if args.synthetic:
            synth_dir = os.path.join(tmp, "synthetic")
            try:
                make_synthetic(args.plenox, synth_dir, args.timeout)
                seqs.append(("synthetic", synth_dir))
            except CommandError as exc:
                notes.append("synthetic: `plenox synth` failed: %s" % exc)
                log("FAILED synthetic: `plenox synth` failed: %s" % exc)
                synth_failed = True
                any_failed = True

        for name, path in seqs:
            log("=== sequence %s (%s)" % (name, path))
            work = os.path.join(tmp, "ours_" + name)
            os.makedirs(work, exist_ok=True)
            ours, problems = run_ours(args, name, path, work)
            rows.append((name, "ours", ours))
            peer, peer_problems = run_peer(args, name, path)
            rows.append((name, "open3d_tsdf", peer))
            for p in problems + peer_problems:
                notes.append(p)
                log("FAILED " + p)
                any_failed = True
            if "iterations" in ours:
                notes.append("%s ours: %s optimisation iterations" % (name, ours["iterations"]))
            if "detail" in peer:
                notes.append("%s open3d_tsdf: %s" % (name, peer["detail"]))

    if synth_failed:
        rows.append(("synthetic", "ours", {}))
        rows.append(("synthetic", "open3d_tsdf", {}))

    settings = "every %d (keyframes i %% %d == 0, held-out i %% %d == %d)" % (
        args.every, args.every, args.every, args.every // 2)
    if args.voxel_size is not None:
        settings += ", voxel size %g m (both systems)" % args.voxel_size
    else:
        settings += ", voxel size: each system's default (open3d_tsdf 0.01 m)"
    if args.time_budget is not None:
        settings += ", plenox time budget %g s" % args.time_budget
    commit = git_commit()
    header = [
        "## Mapping benchmark",
        "",
        "- date: %s" % started.strftime("%Y-%m-%d %H:%M UTC"),
        "- machine: %s" % machine,
        "- settings: %s" % settings,
        "- plenox: %s%s" % (args.plenox, " (commit %s)" % commit if commit else ""),
    ]
    text = table(rows, header, notes)
    write_report(text, args.out)
    return 1 if any_failed else 0


if __name__ == "__main__":
    sys.exit(main())
