#!/usr/bin/python3
"""Snapshots and keyframes in map files (issue 24, parts 1-2): what they cost and what they save.

Three measurements, each with plenoxd on 127.0.0.1 only, every command bounded by --timeout:

1. Track p99 with and without snapshots. A map built once (Integrate of the synthetic room's
   keyframes) is loaded by a fresh daemon; an Integrate stream re-integrates the same keyframes
   into it over and over, so the map changes all the time, while one `plenox --server track`
   client localises every frame in it (lock-step). Runs alternate --snapshot-seconds 0 and
   --snapshot-seconds S (default 1: the whole map is written about every S seconds, the worst
   case), --rounds times each. Reported: the Track client's round trip and the daemon's latency
   at p50 and p99, the snapshots written and their mean time (plenoxd's /metrics).
2. Bytes per keyframe. `plenox --server slam` maps a real sequence (infinitam_teddy when
   ../shared/data has it, else the synthetic room), the map is saved, and its file's header
   gives the keyframe section's size (map_file.h); beside it, what the keyframes' images would
   add as PNGs (colour and 16-bit depth, encoded with OpenCV).
3. Data lost on kill -9. The same SLAM stream into a daemon with --snapshot-seconds N; /metrics
   is read every 0.25 s (keyframes the streams handed to mapping, the age of the oldest unsaved
   change); the daemon is killed with SIGKILL at a few points of the stream, restarted, and the
   reloaded map's keyframes counted. A SIGTERM row shows the drain's save (0 lost).

    /usr/bin/python3 bench/snapshot_bench.py --out /tmp/snapshot_bench.md
"""

import argparse
import datetime
import json
import os
import shutil
import struct
import subprocess
import sys
import tempfile
import time
import urllib.request

from bench_common import (REPO, CommandError, CommandLoop, DaemonProcess, free_port, git_commit,
                          machine_line, make_synthetic, percentile, read_timings, run_cmd,
                          set_log_prefix, write_report)

MAP_NAME = "bench"


class Daemon(DaemonProcess):
    """plenoxd on free loopback ports (gRPC and metrics) with `data_dir`."""

    def __init__(self, args, data_dir, log_path, snapshot_s):
        self.args = args
        self.metrics_port = free_port()
        super().__init__(args.plenoxd, args.plenox,
                         ["--data-dir", data_dir, "--metrics-port", str(self.metrics_port),
                          "--snapshot-seconds", str(snapshot_s)], log_path)

    def metrics(self):
        """{name: value} of the unlabelled metrics; {} when the daemon does not answer."""
        try:
            with urllib.request.urlopen("http://127.0.0.1:%d/metrics" % self.metrics_port,
                                        timeout=5) as r:
                text = r.read().decode()
        except OSError:
            return {}
        out = {}
        for line in text.splitlines():
            if line.startswith("#") or "{" in line:
                continue
            parts = line.split()
            if len(parts) == 2:
                try:
                    out[parts[0]] = float(parts[1])
                except ValueError:
                    pass
        return out

    def maps(self):
        r = subprocess.run([self.args.plenox, "--server", self.address, "maps", "--json"],
                           capture_output=True, text=True, timeout=60)
        if r.returncode != 0:
            raise CommandError("maps: %s" % r.stderr[-400:])
        maps = [json.loads(l) for l in r.stdout.splitlines() if l.strip()]  # JSON Lines
        return {m["name"]: m for m in maps}


def map_file_header(path):
    """(format version, map version, keyframes, keyframe section bytes, file bytes) from the
    header of a map file (core/formats/map_file.h)."""
    with open(path, "rb") as f:
        head = f.read(80)
        version, = struct.unpack_from("<I", head, 8)
        source_len, = struct.unpack_from("<I", head, 76)
        f.seek(80 + source_len)
        rest = f.read(28)
    if version < 2:
        return version, 0, 0, 0, os.path.getsize(path)
    _bricks, map_version, keyframes, section = struct.unpack_from("<QQIQ", rest, 0)
    return version, map_version, keyframes, section, os.path.getsize(path)


def integrate_loop(args, daemon, dataset):
    """Re-integrates the dataset's keyframes into MAP_NAME until stop(): the map changes all
    the time, as under a live mapping job."""
    cmd = [args.plenox, "--server", daemon.address, "map", "--dataset", dataset,
           "--every", str(args.every), "--name", MAP_NAME, "--quiet", "--json"]
    return CommandLoop(lambda n: cmd)


# ----------------------------------------------------------------------------------------------
# 1. Track p99 with and without snapshots


def build_seed_map(args, dataset, workdir):
    """The map every p99 run starts from: the dataset's keyframes integrated, saved."""
    data = os.path.join(workdir, "seed")
    os.makedirs(data)
    daemon = Daemon(args, data, os.path.join(workdir, "seed.log"), 0)
    try:
        run_cmd("seed map", [args.plenox, "--server", daemon.address, "map", "--dataset",
                             dataset, "--every", str(args.every), "--name", MAP_NAME, "--quiet",
                             "--json"], args.timeout)
        run_cmd("seed save", [args.plenox, "--server", daemon.address, "save", "--map",
                              MAP_NAME],
                args.timeout)
    finally:
        daemon.stop()
    return os.path.join(data, MAP_NAME + ".plx")


def track_run(args, dataset, seed, workdir, tag, snapshot_s):
    data = os.path.join(workdir, tag)
    os.makedirs(data)
    shutil.copy(seed, os.path.join(data, MAP_NAME + ".plx"))
    daemon = Daemon(args, data, os.path.join(workdir, tag + ".log"), snapshot_s)
    load = None
    try:
        load = integrate_loop(args, daemon, dataset)
        # The map is being changed before the client starts.
        deadline = time.monotonic() + args.timeout
        while daemon.metrics().get("plenoxd_unsaved_maps", 0) < 1:
            if time.monotonic() > deadline or load.failures:
                raise CommandError("%s: the mapping load never changed the map: %s"
                                   % (tag, load.failures))
            time.sleep(0.2)
        before = daemon.metrics()
        window_start = time.monotonic()
        timing_files = []
        for n in range(args.track_passes):
            timings = os.path.join(workdir, "%s_pass%d_timings.txt" % (tag, n))
            run_cmd("%s track %d" % (tag, n),
                    [args.plenox, "--server", daemon.address, "track", "--map", MAP_NAME,
                     "--dataset", dataset, "--out", os.path.join(workdir, tag + "_traj.txt"),
                     "--timings", timings, "--encoding", "raw", "--json", "--quiet"],
                    args.timeout)
            timing_files.append(timings)
        after = daemon.metrics()
        window_s = time.monotonic() - window_start
    finally:
        if load is not None:
            load.stop()
        daemon.stop()
    if load.failures:
        raise CommandError("%s: mapping load failed: %s" % (tag, load.failures[0]))
    roundtrip, daemon_ms = [], []
    for path in timing_files:
        r, d = read_timings(path)
        roundtrip += r
        daemon_ms += d
    snaps = after.get("plenoxd_snapshots_total", 0) - before.get("plenoxd_snapshots_total", 0)
    snap_s = (after.get("plenoxd_snapshot_seconds_sum", 0) -
              before.get("plenoxd_snapshot_seconds_sum", 0))
    snap_bytes = (after.get("plenoxd_snapshot_bytes_total", 0) -
                  before.get("plenoxd_snapshot_bytes_total", 0))
    return {"tag": tag, "snapshot_s": snapshot_s, "frames": len(roundtrip),
            "rt_p50": percentile(roundtrip, 50), "rt_p99": percentile(roundtrip, 99),
            "d_p50": percentile(daemon_ms, 50), "d_p99": percentile(daemon_ms, 99),
            "snapshots": int(snaps), "snapshot_mean_s": snap_s / snaps if snaps else None,
            "snapshot_mb": snap_bytes / snaps / 1e6 if snaps else None,
            "failures": int(after.get("plenoxd_snapshot_failures_total", 0)),
            "writing_share": snap_s / window_s if window_s > 0 else 0.0,
            "integrate_jobs": load.jobs, "roundtrip": roundtrip, "daemon": daemon_ms}


def p99_section(args, dataset, workdir, notes):
    seed = build_seed_map(args, dataset, workdir)
    seed_mb = os.path.getsize(seed) / 1e6
    rows = []
    for r in range(args.rounds):
        for snapshot_s in ((0, args.snapshot_s) if r % 2 == 0 else (args.snapshot_s, 0)):
            tag = "p99_r%d_%s" % (r, "on" if snapshot_s else "off")
            rows.append(track_run(args, dataset, seed, workdir, tag, snapshot_s))
    out = ["### Track latency with and without snapshots", "",
           "Map file %.1f MB (the synthetic room at %sx%s, keyframes every %d frames), "
           "re-integrated all the time by an Integrate stream; one lock-step Track client "
           "(raw frames) localises every frame in it, %d passes over the %d frames per run."
           % (seed_mb, args.width, args.height, args.every, args.track_passes, args.frames), "",
           "| run | --snapshot-seconds | frames | round trip p50 / p99 (ms) | daemon p50 / p99 "
           "(ms) | snapshots | mean snapshot (s, MB) | time spent writing |",
           "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for row in rows:
        out.append("| %s | %s | %d | %.1f / %.1f | %.1f / %.1f | %d | %s | %.0f %% |" % (
            row["tag"], row["snapshot_s"] or "0 (off)", row["frames"], row["rt_p50"],
            row["rt_p99"], row["d_p50"], row["d_p99"], row["snapshots"],
            "%.3f, %.1f" % (row["snapshot_mean_s"], row["snapshot_mb"])
            if row["snapshots"] else "-", 100.0 * row["writing_share"]))
        if row["failures"]:
            notes.append("%s: %d snapshot failures" % (row["tag"], row["failures"]))
    pooled = {}
    for on in (False, True):
        rt = [v for row in rows if bool(row["snapshot_s"]) == on for v in row["roundtrip"]]
        dm = [v for row in rows if bool(row["snapshot_s"]) == on for v in row["daemon"]]
        pooled[on] = (percentile(rt, 99), percentile(dm, 99), len(rt))
    change = 100.0 * (pooled[True][0] / pooled[False][0] - 1.0)
    out += ["", "Pooled over the rounds: round-trip p99 %.1f ms without snapshots, %.1f ms with "
            "(%+.1f %%; goal: at most +10 %%); daemon p99 %.1f / %.1f ms (%d / %d frames)." % (
                pooled[False][0], pooled[True][0], change, pooled[False][1], pooled[True][1],
                pooled[False][2], pooled[True][2])]
    return "\n".join(out)


# ----------------------------------------------------------------------------------------------
# 2. Bytes per keyframe, 3. data lost on kill -9


def png_bytes_per_frame(dataset, count):
    """Mean bytes of the dataset's first `count` frames as PNG colour + 16-bit PNG depth."""
    import cv2  # python3-opencv
    pairs = []
    with open(os.path.join(dataset, "associations.txt")) as f:
        for line in f:
            parts = line.split()
            if len(parts) >= 4 and not line.startswith("#"):
                pairs.append((parts[1], parts[3]))
    total = 0
    pairs = pairs[:count]
    for rgb, depth in pairs:
        colour = cv2.imread(os.path.join(dataset, rgb), cv2.IMREAD_COLOR)
        d = cv2.imread(os.path.join(dataset, depth), cv2.IMREAD_UNCHANGED)
        total += len(cv2.imencode(".png", colour)[1]) + len(cv2.imencode(".png", d)[1])
    return total / max(1, len(pairs))


def slam_cmd(args, daemon, dataset, workdir, tag, save=False):
    cmd = [args.plenox, "--server", daemon.address, "slam", "--dataset", dataset, "--name",
           "slam", "--out", os.path.join(workdir, tag + "_traj.txt"), "--max-frames",
           str(args.slam_frames), "--encoding", "raw", "--quiet", "--json"]
    return cmd + (["--save"] if save else [])


def keyframe_section(args, dataset, workdir):
    data = os.path.join(workdir, "kf")
    os.makedirs(data)
    daemon = Daemon(args, data, os.path.join(workdir, "kf.log"), 0)
    try:
        run_cmd("kf slam", slam_cmd(args, daemon, dataset, workdir, "kf", save=True),
                args.timeout)
    finally:
        daemon.stop()
    version, map_version, keyframes, section, size = map_file_header(
        os.path.join(data, "slam.plx"))
    png = png_bytes_per_frame(dataset, 30)
    per_kf = section / keyframes if keyframes else 0
    return "\n".join([
        "### Bytes per keyframe in the map file", "",
        "`plenox --server slam` over %s frames of %s, saved: format version %d, "
        "map version %d." % (args.slam_frames or "all", os.path.basename(dataset.rstrip("/")),
                             version, map_version), "",
        "| keyframes | keyframe section | per keyframe | share of the file | file | their "
        "images as PNG (colour + depth16), per keyframe |",
        "| --- | --- | --- | --- | --- | --- |",
        "| %d | %.2f MB | %.1f KB | %.2f %% | %.1f MB | %.0f KB (%.0fx the keyframe) |" % (
            keyframes, section / 1e6, per_kf / 1e3, 100.0 * section / size, size / 1e6,
            png / 1e3, png / per_kf if per_kf else 0)])


def kill_run(args, dataset, workdir, tag, kill_after_s, signal_kind):
    data = os.path.join(workdir, tag)
    os.makedirs(data)
    daemon = Daemon(args, data, os.path.join(workdir, tag + ".log"), args.kill_snapshot_s)
    slam = subprocess.Popen(slam_cmd(args, daemon, dataset, workdir, tag),
                            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    start = time.monotonic()
    last = {}
    history = []  # (wall-clock time, keyframes handed to mapping)
    while time.monotonic() - start < kill_after_s:
        if slam.poll() is not None:
            break
        m = daemon.metrics()
        if m:
            last = m
            history.append((time.time(), int(m.get("plenoxd_slam_keyframes_total", 0))))
        time.sleep(0.25)
    killed_at = time.monotonic() - start
    killed_wall = time.time()
    mid_stream = slam.poll() is None
    accepted = int(last.get("plenoxd_slam_keyframes_total", 0))
    unsaved_s = last.get("plenoxd_unsaved_seconds", 0.0)
    snapshots = int(last.get("plenoxd_snapshots_total", 0))
    if signal_kind == "SIGKILL":
        daemon.kill()
    else:
        daemon.stop()
        # The drain may integrate keyframes accepted after the last poll: count what it saved.
    slam.kill()
    slam.wait()
    # Restarted without snapshots: the file is read back as it was left.
    again = Daemon(args, data, os.path.join(workdir, tag + "_again.log"), 0)
    try:
        reloaded = again.maps().get("slam", {})
    finally:
        again.stop()
    kept = int(reloaded.get("keyframes", 0))
    # The reloaded map is the version the last finished snapshot took when it started: what
    # happened after that start is what the kill lost.
    taken = last_snapshot_start(os.path.join(workdir, tag + ".log"))
    age_s = killed_wall - taken if taken is not None else None
    window = [n for (t, n) in history if t <= killed_wall - args.kill_snapshot_s]
    accepted_in_interval = accepted - (window[-1] if window else 0)
    return {"tag": tag, "signal": signal_kind, "at_s": killed_at, "mid_stream": mid_stream,
            "age_s": age_s, "accepted_in_interval": accepted_in_interval,
            "accepted": accepted,
            "kept": kept, "unsaved_s": unsaved_s, "snapshots": snapshots,
            "version": reloaded.get("version", 0)}


def last_snapshot_start(log_path):
    """Wall-clock time the last finished snapshot in a plenoxd log started (None: none)."""
    start = None
    with open(log_path) as f:
        for line in f:
            if "event=snapshot_saved" not in line:
                continue
            fields = dict(kv.split("=", 1) for kv in line.split() if "=" in kv)
            ts = datetime.datetime.strptime(fields["ts"], "%Y-%m-%dT%H:%M:%S.%fZ")
            ts = ts.replace(tzinfo=datetime.timezone.utc).timestamp()
            start = ts - float(fields.get("seconds", 0))
    return start


def kill_section(args, dataset, workdir):
    rows = []
    for i, at in enumerate(args.kill_at):
        rows.append(kill_run(args, dataset, workdir, "kill%d" % i, at, "SIGKILL"))
    rows.append(kill_run(args, dataset, workdir, "term", args.kill_at[-1], "SIGTERM"))
    out = ["### Data lost on kill -9", "",
           "A Slam stream (`plenox --server slam`, frames one at a time, %s) into a daemon with "
           "--snapshot-seconds %g; /metrics read every 0.25 s; the daemon killed at the time "
           "given, then restarted on its data dir." % (os.path.basename(dataset.rstrip("/")),
                                                      args.kill_snapshot_s), "",
           "| signal | after (s) | stream running | snapshots | keyframes accepted (last "
           "read) | of them in the last interval | in the reloaded map | lost | mapping lost "
           "(s): the reloaded state's age at the kill | reloaded version |",
           "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in rows:
        age = "-" if r["signal"] != "SIGKILL" else (
            "%.1f" % r["age_s"] if r["age_s"] is not None else "no snapshot yet")
        out.append("| %s | %.1f | %s | %d | %d | %d | %d | %d | %s | %d |" % (
            r["signal"], r["at_s"], "yes" if r["mid_stream"] else "no (ended)", r["snapshots"],
            r["accepted"], r["accepted_in_interval"], r["kept"],
            max(0, r["accepted"] - r["kept"]), age, r["version"]))
    return "\n".join(out)


def main():
    set_log_prefix("snapshot_bench")
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--plenoxd", default=os.path.join(REPO, "build", "server", "plenoxd"))
    p.add_argument("--plenox", default=os.path.join(REPO, "build", "clients", "plenox",
                                                    "plenox"))
    p.add_argument("--data", default=os.path.join(os.path.dirname(REPO), "shared", "data"))
    p.add_argument("--sections", default="p99,bytes,kill",
                   help="which measurements, comma-separated (p99, bytes, kill)")
    p.add_argument("--width", type=int, default=320)
    p.add_argument("--height", type=int, default=240)
    p.add_argument("--frames", type=int, default=200, help="synthetic frames tracked per run")
    p.add_argument("--every", type=int, default=10, help="keyframe stride of the mapping load")
    p.add_argument("--snapshot-s", type=float, default=1.0,
                   help="--snapshot-seconds of the p99 runs with snapshots")
    p.add_argument("--rounds", type=int, default=2, help="off/on pairs of p99 runs")
    p.add_argument("--track-passes", type=int, default=4,
                   help="Track clients run one after the other per p99 run")
    p.add_argument("--slam-frames", type=int, default=0, help="0: every frame")
    p.add_argument("--kill-snapshot-s", type=float, default=5.0)
    p.add_argument("--kill-at", default="8,16,24,45",
                   help="seconds into the Slam stream at which the daemon is killed")
    p.add_argument("--timeout", type=float, default=900.0, help="limit per command (s)")
    p.add_argument("--out", default=None)
    args = p.parse_args()
    args.kill_at = [float(v) for v in args.kill_at.split(",") if v]
    sections = set(args.sections.split(","))

    started = time.monotonic()
    header = ["## Snapshots and keyframes in map files (issue 24, parts 1-2)", "",
              "Machine: %s. Commit %s, %s. `bench/snapshot_bench.py`." % (
                  machine_line(), git_commit() or "?", datetime.date.today().isoformat())]
    notes = []
    parts = []
    workdir = tempfile.mkdtemp(prefix="plx_snapshot_bench_")
    try:
        synth = os.path.join(workdir, "synth")
        make_synthetic(args.plenox, synth, args.timeout, frames=args.frames,
                       extra=("--width", str(args.width), "--height", str(args.height)))
        real = os.path.join(args.data, "infinitam_teddy")
        slam_dataset = real if os.path.isdir(real) else synth
        if "p99" in sections:
            parts.append(p99_section(args, synth, workdir, notes))
        if "bytes" in sections:
            parts.append(keyframe_section(args, slam_dataset, workdir))
        if "kill" in sections:
            parts.append(kill_section(args, slam_dataset, workdir))
    except CommandError as e:
        notes.append("failed: %s" % e)
    finally:
        shutil.rmtree(workdir, ignore_errors=True)
    text = "\n".join(header) + "\n\n" + "\n\n".join(parts) + "\n"
    if notes:
        text += "\nNotes:\n\n" + "\n".join("- " + n for n in notes) + "\n"
    text += "\nWall time %.0f s.\n" % (time.monotonic() - started)
    write_report(text, args.out)
    return 1 if any(n.startswith("failed") for n in notes) else 0


if __name__ == "__main__":
    sys.exit(main())
