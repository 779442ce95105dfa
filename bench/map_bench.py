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
import collections
import datetime
import json
import math
import os
import platform
import signal
import subprocess
import sys
import tempfile
import threading
import time

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PEER = os.path.join(REPO, "bench", "peers", "open3d_tsdf.py")
PEER_PYTHON = "/usr/bin/python3"  # Debian's interpreter: python3-open3d, python3-opencv
STDERR_TAIL = 3000  # characters of a failed command's stderr kept for the report

MAP_KEYS = ("keyframes", "seconds", "seconds_per_keyframe", "map_mb", "peak_rss_mb",
            "iterations")
EVAL_KEYS = ("psnr", "depth_l1_m", "depth_l1_median_m", "coverage", "frames", "pixels")
PEER_KEYS = ("keyframes", "heldout_frames", "seconds_per_keyframe", "psnr", "depth_l1_m",
             "depth_l1_median_m", "coverage", "map_mb", "peak_rss_mb")


def log(msg):
    print("[map_bench] " + msg, file=sys.stderr, flush=True)


class CommandError(Exception):
    pass


def run_cmd(label, cmd, timeout, env=None):
    """Runs cmd, passing its stderr through live, and returns (stdout, stderr tail).
    Raises CommandError with the stderr tail when it cannot start, times out or fails."""
    log("%s: %s" % (label, " ".join(cmd)))
    tail = collections.deque()
    tail_len = [0]
    out_chunks = []

    def pump_stderr(pipe):
        while True:
            chunk = os.read(pipe.fileno(), 65536)
            if not chunk:
                break
            sys.stderr.buffer.write(chunk)
            sys.stderr.buffer.flush()
            tail.append(chunk)
            tail_len[0] += len(chunk)
            while tail_len[0] - len(tail[0]) > STDERR_TAIL:
                tail_len[0] -= len(tail.popleft())

    def pump_stdout(pipe):
        out_chunks.append(pipe.read())

    def stderr_tail():
        text = b"".join(tail).decode("utf-8", "replace")[-STDERR_TAIL:]
        return text.replace("\r", "\n").strip()

    start = time.monotonic()
    try:
        proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, env=env, start_new_session=True)
    except OSError as exc:
        raise CommandError("%s: cannot start %s: %s" % (label, cmd[0], exc))
    threads = [threading.Thread(target=pump_stderr, args=(proc.stderr,), daemon=True),
               threading.Thread(target=pump_stdout, args=(proc.stdout,), daemon=True)]
    for t in threads:
        t.start()
    timed_out = False
    try:
        proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        timed_out = True
    except KeyboardInterrupt:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        raise
    if timed_out:
        os.killpg(proc.pid, signal.SIGKILL)  # the session we started for this command
        proc.wait()
    for t in threads:
        t.join(timeout=10)
    elapsed = time.monotonic() - start
    stdout = (out_chunks[0] if out_chunks else b"").decode("utf-8", "replace")

    if timed_out:
        raise CommandError("%s: timed out after %.0f s\n--- stderr tail ---\n%s"
                           % (label, timeout, stderr_tail()))
    if proc.returncode != 0:
        raise CommandError("%s: exit status %d after %.1f s\n--- stderr tail ---\n%s"
                           % (label, proc.returncode, elapsed, stderr_tail()))
    log("%s: done in %.1f s" % (label, elapsed))
    return stdout, stderr_tail()


def run_json(label, cmd, timeout, env=None):
    """run_cmd, then the JSON object on the last non-empty stdout line (the lines before it
    are shown on stderr). Raises CommandError on any failure."""
    stdout, tail = run_cmd(label, cmd, timeout, env)
    lines = [l for l in stdout.splitlines() if l.strip()]
    for line in lines[:-1]:  # human-readable output: show it, it is not parsed
        print(line, file=sys.stderr, flush=True)
    try:
        obj = json.loads(lines[-1]) if lines else None
    except ValueError:
        obj = None
    if not isinstance(obj, dict):
        raise CommandError("%s: the last stdout line is not a JSON object: %r\n"
                           "--- stderr tail ---\n%s"
                           % (label, lines[-1][-300:] if lines else "(no output)", tail))
    return obj


def copy_keys(src, dst, keys):
    """Copies the keys src has; a key it lacks stays absent, so its cell says 'failed'."""
    for k in keys:
        if k in src:
            dst[k] = src[k]


def check_keys(label, obj, keys):
    missing = [k for k in keys if k not in obj]
    return ["%s: JSON lacks %s" % (label, ", ".join(missing))] if missing else []


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
           "--every", str(args.every)]
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
           "--every", str(args.every), "--pixels", "0", "--json"]
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
    env = dict(os.environ)
    env["OMP_WAIT_POLICY"] = "passive"  # Open3D: OpenMP x TBB oversubscription otherwise
    try:
        p = run_json("%s open3d_tsdf" % name, cmd, args.timeout, env=env)
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

def cell(row, key, spec, scale=1.0):
    """Formats row[key]; 'failed' when the system did not report it, 'n/a' when it reported
    null (e.g. depth error with zero coverage)."""
    if key not in row:
        return "failed"
    v = row[key]
    if v is None:
        return "n/a"
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return "failed"
    if isinstance(v, float) and math.isinf(v):
        return "inf"
    if isinstance(v, float) and math.isnan(v):
        return "failed"
    return spec % (v * scale)


def machine_line():
    model = None
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    model = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    cores = os.cpu_count()
    try:
        usable = len(os.sched_getaffinity(0))
    except AttributeError:
        usable = cores
    try:
        load = "%.2f" % os.getloadavg()[0]
    except OSError:
        load = "?"
    return "%s, %s logical cores (%s usable), %s; 1-min load average at start %s" % (
        model or platform.processor() or "unknown CPU", cores, usable, platform.system(),
        load)


def git_commit():
    try:
        r = subprocess.run(["git", "-C", REPO, "rev-parse", "--short", "HEAD"],
                           capture_output=True, text=True, timeout=10)
        return r.stdout.strip() if r.returncode == 0 else None
    except (OSError, subprocess.SubprocessError):
        return None


def render_table(rows, header_lines, notes):
    cols = ["sequence", "system", "keyframes", "held-out", "s/keyframe", "PSNR (dB)",
            "depth L1 mean (cm)", "depth L1 median (cm)", "coverage", "map MB",
            "peak RSS MB"]
    out = list(header_lines) + [""]
    out.append("| " + " | ".join(cols) + " |")
    out.append("|" + "|".join(" --- " for _ in cols) + "|")
    for seq, system, row in rows:
        vals = [seq, system,
                cell(row, "keyframes", "%d"),
                cell(row, "heldout_frames", "%d"),
                cell(row, "seconds_per_keyframe", "%.3f"),
                cell(row, "psnr", "%.2f"),
                cell(row, "depth_l1_m", "%.2f", 100.0),
                cell(row, "depth_l1_median_m", "%.2f", 100.0),
                cell(row, "coverage", "%.3f"),
                cell(row, "map_mb", "%.1f"),
                cell(row, "peak_rss_mb", "%.0f")]
        out.append("| " + " | ".join(vals) + " |")
    if notes:
        out.append("")
        out.append("Notes:")
        out.append("")
        for n in notes:
            lines = n.rstrip().splitlines()
            if len(lines) == 1:
                out.append("- " + lines[0])
            else:
                out.append("- " + lines[0])
                out.append("")
                out.append("  ```")
                out.extend("  " + l for l in lines[1:])
                out.append("  ```")
    return "\n".join(out) + "\n"


# ----------------------------------------------------------------------------------------
# Main
# ----------------------------------------------------------------------------------------

def list_sequences(data_dir, wanted, notes):
    if not os.path.isdir(data_dir):
        notes.append("data folder %s does not exist; no dataset sequences were run" % data_dir)
        return []
    seqs = []
    for name in sorted(os.listdir(data_dir)):
        path = os.path.join(data_dir, name)
        if not os.path.isdir(path):
            continue
        if wanted is not None and name not in wanted:
            continue
        if not os.path.exists(os.path.join(path, "intrinsics.txt")):
            notes.append("%s skipped: no intrinsics.txt (not a TUM-layout sequence)" % name)
            continue
        seqs.append((name, path))
    if wanted is not None:
        found = {s[0] for s in seqs}
        for w in wanted:
            if w not in found and not os.path.isdir(os.path.join(data_dir, w)):
                notes.append("sequence %s not found under %s" % (w, data_dir))
    return seqs


def main():
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
    seqs = list_sequences(data_dir, wanted, notes)

    rows = []
    any_failed = False
    synth_failed = False
    with tempfile.TemporaryDirectory(prefix="map_bench_") as tmp:
        if args.synthetic:
            synth_dir = os.path.join(tmp, "synthetic")
            cmd = [args.plenox, "synth", "--out", synth_dir]
            try:
                if not os.access(args.plenox, os.X_OK):
                    raise CommandError("plenox binary not found or not executable: %s"
                                       % args.plenox)
                stdout, _ = run_cmd("synthetic synth", cmd, args.timeout)
                if stdout.strip():
                    sys.stderr.write(stdout)
                if not os.path.exists(os.path.join(synth_dir, "intrinsics.txt")):
                    raise CommandError("%s has no intrinsics.txt after `plenox synth`"
                                       % synth_dir)
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
    text = render_table(rows, header, notes)
    sys.stdout.write("\n" + text)
    sys.stdout.flush()
    if args.out:
        out = os.path.abspath(args.out)
        os.makedirs(os.path.dirname(out), exist_ok=True)
        with open(out, "w") as f:
            f.write(text)
        log("wrote %s" % out)
    return 1 if any_failed else 0


if __name__ == "__main__":
    sys.exit(main())
