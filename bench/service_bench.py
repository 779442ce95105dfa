#!/usr/bin/python3
"""End-to-end service benchmark: tracking through plenoxd over loopback (bench/README.md).

One sequence (tum_fr3_teddy when ../shared/data has it, else the synthetic one) is mapped
in-process, tracked in-process for the reference time, then served by a plenoxd on 127.0.0.1:
1 and 4 concurrent `plenox --server track` clients, with and without a mapping job running on
the same daemon. Each client streams every frame in lock-step (the next frame after the
previous estimate), so every frame is served. Reported per scenario: frames per second of all
clients together, the client-side round trip (frame sent -> estimate read; encoding
excluded) at p50 and p99, the daemon's own latency (frame decoded -> estimate sent), and the
service's overhead: round trip p50 over the in-process tracking median. Same map, frames,
tracker options and start pose in every run.

SLAM rows (issue 12): `plenox --server slam` streams the sequence (no poses) into a new map on the
same daemon, lock-step; alone, with 2 Track clients localising in its live map, and with 1 Track
client on the other (loaded) map. Reported: the Slam stream's pose latency (the daemon's, frame
received -> pose sent, and the round trip) at p50 and p99, its ATE beside in-process `plenox slam`
of the same frames, the Track clients' latencies, lost frames. The goals of point 3: the Slam
stream's p99 <= 1.5x its p50; the Track client on the other map keeps its p99 within 1.5x of its
p99 without the Slam stream (the 1:off:raw row).
"""

import argparse
import datetime
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time

from bench_common import (REPO, CommandError, CommandLoop, DaemonProcess, git_commit, log,
                          machine_line, make_synthetic, percentile, read_timings, render_table,
                          run_json, set_log_prefix, write_report)

MAP_NAME = "bench"
DEFAULT_SCENARIOS = "1:off:raw,1:off:png,4:off:raw,1:on:raw,4:on:raw,slam,slam+live,slam+other"
SLAM_SCENARIOS = ("slam", "slam+live", "slam+other")


def start_daemon(plenoxd, plenox, data_dir, log_path, extra_args=()):
    """plenoxd with `data_dir`, once it lists MAP_NAME (loaded from the data dir)."""
    return DaemonProcess(plenoxd, plenox, ["--data-dir", data_dir] + list(extra_args), log_path,
                         ready=lambda listing: MAP_NAME in listing)


def mapping_load(args, daemon, dataset):
    """Keeps a mapping job running on the daemon (a fresh map per job, the same keyframes)
    until stop()."""
    base = [args.plenox, "--server", daemon.address, "map", "--dataset", dataset,
            "--every", str(args.every), "--quiet", "--json"]
    return CommandLoop(lambda n: base + ["--name", "load%d_%d" % (os.getpid(), n)],
                       join_timeout_s=60)


def start_trackers(args, daemon, dataset, workdir, tag, clients, encoding, map_name=MAP_NAME):
    """Starts `clients` trackers on `map_name` at once; finish_clients() collects them."""
    procs = []
    for c in range(clients):
        traj = os.path.join(workdir, "%s_c%d.txt" % (tag, c))
        timings = os.path.join(workdir, "%s_c%d_timings.txt" % (tag, c))
        cmd = [args.plenox, "--server", daemon.address, "track", "--map", map_name,
               "--dataset", dataset, "--out", traj, "--timings", timings, "--encoding",
               encoding, "--json", "--quiet"]
        if c == 0:
            log("%s: %d x %s" % (tag, clients, " ".join(cmd)))
        procs.append((subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                       stderr=subprocess.PIPE), traj, timings))
    return procs


def finish_clients(args, tag, procs, what="tracking"):
    """Waits for started clients; returns (JSON summary, trajectory, timings) of each."""
    results = []
    for proc, traj, timings in procs:
        out, err = proc.communicate(timeout=args.timeout)
        if proc.returncode != 0:
            raise CommandError("%s: a %s client failed (status %d): %s"
                               % (tag, what, proc.returncode,
                                  err.decode("utf-8", "replace")[-600:]))
        lines = [l for l in out.decode().splitlines() if l.strip()]
        results.append((json.loads(lines[-1]), traj, timings))
    return results


def run_clients(args, daemon, dataset, workdir, tag, clients, encoding):
    """Starts `clients` trackers at once; returns their JSON summaries and timing files."""
    return finish_clients(args, tag,
                          start_trackers(args, daemon, dataset, workdir, tag, clients, encoding))


def start_slam(args, daemon, dataset, workdir, tag, map_name):
    """One `plenox --server slam` stream into a new map `map_name`, lock-step, raw frames."""
    traj = os.path.join(workdir, "%s_slam.txt" % tag)
    timings = os.path.join(workdir, "%s_slam_timings.txt" % tag)
    cmd = [args.plenox, "--server", daemon.address, "slam", "--dataset", dataset, "--name",
           map_name, "--out", traj, "--timings", timings, "--encoding", "raw", "--json",
           "--quiet"] + slam_frame_flags(args) + args.slam_args.split()
    log("%s: %s" % (tag, " ".join(cmd)))
    return [(subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE), traj, timings)]


def slam_frame_flags(args):
    return ["--max-frames", str(args.slam_frames)] if args.slam_frames > 0 else []


def wait_for_map_version(args, daemon, map_name, deadline_s=600.0):
    """Blocks until the daemon lists `map_name` with a published version (the SLAM stream's
    first keyframe is integrated), so Track clients have a map to localise in."""
    deadline = time.monotonic() + deadline_s
    while time.monotonic() < deadline:
        probe = subprocess.run([args.plenox, "--server", daemon.address, "maps", "--json"],
                               capture_output=True, text=True)
        if probe.returncode == 0:
            for line in probe.stdout.splitlines():
                if '"%s"' % map_name in line and '"version":0' not in line.replace(" ", ""):
                    return
        time.sleep(0.5)
    raise CommandError("map %s had no published version after %.0f s" % (map_name, deadline_s))


def latency_stats(timing_files):
    roundtrip, daemon_ms = [], []
    for path in timing_files:
        r, d = read_timings(path)
        roundtrip += r
        daemon_ms += d
    return {"frames": len(roundtrip),
            "rt_p50": percentile(roundtrip, 50), "rt_p99": percentile(roundtrip, 99),
            "daemon_p50": percentile(daemon_ms, 50), "daemon_p99": percentile(daemon_ms, 99)}


def read_slam_timings(path):
    """Rows of `plenox --server slam --timings`: frame, daemon_ms, whether the frame before it
    was a keyframe."""
    rows = []
    previous_keyframe = False
    with open(path) as f:
        for line in f:
            if line.startswith("#") or not line.strip():
                continue
            parts = line.split()
            rows.append({"frame": int(parts[0]), "daemon_ms": float(parts[3]),
                         "after_keyframe": previous_keyframe})
            previous_keyframe = len(parts) > 5 and parts[5] == "keyframe"
    return rows


def run_slam_scenario(args, daemon, dataset, workdir, index, scenario):
    """One Slam stream into a fresh map; with 2 Track clients on its live map (slam+live) or 1
    Track client on the loaded map (slam+other), started once the live map has a version."""
    tag = "s%d_%s" % (index, scenario.replace("+", "_"))
    map_name = "slam%d" % index
    wall0 = time.monotonic()
    slam = start_slam(args, daemon, dataset, workdir, tag, map_name)
    trackers = []
    try:
        if scenario != "slam":
            wait_for_map_version(args, daemon, map_name)
            if scenario == "slam+live":
                trackers = start_trackers(args, daemon, dataset, workdir, tag, 2, "raw", map_name)
            else:
                trackers = start_trackers(args, daemon, dataset, workdir, tag, 1, "raw")
        track_results = finish_clients(args, tag, trackers)
        slam_result = finish_clients(args, tag, slam, "slam")[0]
    except BaseException:
        for proc, _, _ in slam + trackers:
            if proc.poll() is None:
                proc.kill()
        raise
    wall = time.monotonic() - wall0
    summary, traj, timings = slam_result
    frames = read_slam_timings(timings)
    # Frame 1 can only be tracked once keyframe 0 is integrated (there is no map before it):
    # the steady-state latency leaves frames 0 and 1 out.
    steady = [f["daemon_ms"] for f in frames if f["frame"] >= 2]
    slowest = sorted(frames, key=lambda f: -f["daemon_ms"])[:3]
    row = {"scenario": scenario, "wall": wall, "slam": summary,
           "steady_p50": percentile(steady, 50), "steady_p99": percentile(steady, 99),
           "slowest": ", ".join("frame %d %.0f ms%s" % (f["frame"], f["daemon_ms"],
                                                        " (after a keyframe)"
                                                        if f["after_keyframe"] else "")
                                for f in slowest),
           "slam_lat": latency_stats([timings]), "slam_ate": summary.get("ate_se3_m"),
           "track_lat": latency_stats([t for _, _, t in track_results]) if trackers else None,
           "track_lost": sum(r[0]["lost"] for r in track_results),
           "track_fps": sum(r[0]["fps"] for r in track_results),
           "track_frames": sum(r[0].get("frames", 0) for r in track_results)}
    log("%s: slam %.2f fps, pose latency p50 %.0f ms p99 %.0f ms, ATE %s"
        % (tag, summary.get("fps", 0), row["slam_lat"]["daemon_p50"],
           row["slam_lat"]["daemon_p99"], summary.get("ate_se3_m")))
    return row


def slam_report(rows, ref, alone, name):
    cols = ["scenario", "frames", "FPS", "keyframes", "pose latency p50 ms (daemon)",
            "p99 ms (daemon)", "p99 / p50", "from frame 2: p50 / p99 ms",
            "round trip p50 / p99 ms", "lost",
            "ATE SE(3) cm (in-process %s)" % ("%.2f" % (100 * ref["ate_se3_m"])
                                              if ref and ref.get("ate_se3_m") is not None
                                              else "n/a"),
            "Track clients: frames, p50 / p99 ms, lost"]
    body = []
    for r in rows:
        s, lat = r["slam"], r["slam_lat"]
        ratio = lat["daemon_p99"] / lat["daemon_p50"] if lat["daemon_p50"] else float("nan")
        track = "—"
        if r["track_lat"] is not None:
            t = r["track_lat"]
            track = "%d, %.0f / %.0f, %d" % (t["frames"], t["daemon_p50"], t["daemon_p99"],
                                             r["track_lost"])
        body.append([r["scenario"], "%d" % s.get("processed", 0), "%.2f" % s.get("fps", 0),
                     "%d" % s.get("keyframes", 0), "%.0f" % lat["daemon_p50"],
                     "%.0f" % lat["daemon_p99"], "%.2f" % ratio,
                     "%.0f / %.0f" % (r["steady_p50"], r["steady_p99"]),
                     "%.0f / %.0f" % (lat["rt_p50"], lat["rt_p99"]), "%d" % s.get("lost", 0),
                     "%.2f" % (100 * r["slam_ate"]) if r["slam_ate"] is not None else "n/a",
                     track])
    header = ["", "### SLAM through plenoxd (`plenox --server slam`, lock-step, raw frames)", "",
              "Sequence %s; in-process `plenox slam` of the same frames: %s frames/s, median %s "
              "ms per frame, ATE SE(3) %s cm." % (
                  name, "%.2f" % ref["fps"] if ref else "n/a",
                  "%.0f" % ref["ms_per_frame_median"] if ref else "n/a",
                  "%.2f" % (100 * ref["ate_se3_m"]) if ref and ref.get("ate_se3_m") is not None
                  else "n/a")]
    notes = ["scenarios: slam = one Slam stream alone; slam+live = with 2 Track clients "
             "localising in its live map (started once it has a version); slam+other = with 1 "
             "Track client on the loaded map",
             "goal (issue 12, point 3): the Slam stream's pose latency p99 <= 1.5x its p50"]
    for r in rows:
        lat = r["slam_lat"]
        met = lat["daemon_p99"] <= 1.5 * lat["daemon_p50"]
        steady_met = r["steady_p99"] <= 1.5 * r["steady_p50"]
        notes.append("%s: p99 / p50 = %.2f: %s; from frame 2 (keyframe 0 integrated): %.2f: %s; "
                     "slowest: %s" % (r["scenario"], lat["daemon_p99"] / lat["daemon_p50"],
                                      "met" if met else "NOT met",
                                      r["steady_p99"] / r["steady_p50"],
                                      "met" if steady_met else "NOT met", r["slowest"]))
        if r["scenario"] == "slam+other" and alone is not None and r["track_lat"]:
            p99 = r["track_lat"]["daemon_p99"]
            notes.append("slam+other: the Track client's p99 %.0f ms against %.0f ms without the "
                         "Slam stream (1:off:raw): %.2fx, goal <= 1.5x: %s"
                         % (p99, alone["daemon_p99"], p99 / alone["daemon_p99"],
                            "met" if p99 <= 1.5 * alone["daemon_p99"] else "NOT met"))
    return "\n" + render_table(cols, body, header, notes)


def ate(args, traj, dataset):
    r = run_json("ate", [args.plenox, "eval-traj", "--est", traj, "--gt",
                         os.path.join(dataset, "groundtruth.txt"), "--json"], args.timeout)
    return r.get("ate_rmse_m")


def parse_scenarios(text):
    out = []
    for item in text.split(","):
        if item.strip() in SLAM_SCENARIOS:
            out.append(item.strip())
            continue
        parts = item.strip().split(":")
        if len(parts) != 3 or not parts[0].isdigit() or parts[1] not in ("on", "off") \
                or parts[2] not in ("raw", "png"):
            raise ValueError("scenario %r is not CLIENTS:on|off:raw|png or one of %s"
                             % (item, ", ".join(SLAM_SCENARIOS)))
        out.append((int(parts[0]), parts[1] == "on", parts[2]))
    return out


def main():
    set_log_prefix("service_bench")
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--plenox", default=os.path.join(REPO, "build", "clients", "plenox", "plenox"))
    ap.add_argument("--plenoxd", default=os.path.join(REPO, "build", "server", "plenoxd"))
    ap.add_argument("--data", default=os.path.join(os.path.dirname(REPO), "shared", "data"),
                    help="folder of sequences (default ../shared/data)")
    ap.add_argument("--sequence", default="tum_fr3_teddy",
                    help="sequence under --data, or 'synthetic' (default tum_fr3_teddy; the "
                         "synthetic one when it is absent)")
    ap.add_argument("--every", type=int, default=10, help="keyframe stride for mapping")
    ap.add_argument("--map", help="use this map file of the sequence instead of mapping it "
                                  "(e.g. the bench.plx of an earlier run)")
    ap.add_argument("--scenarios", default=DEFAULT_SCENARIOS,
                    help="comma-separated CLIENTS:MAPPING:ENCODING, mapping on|off, encoding "
                         "raw|png (default %s)" % DEFAULT_SCENARIOS)
    ap.add_argument("--slam-frames", type=int, default=0,
                    help="frames of the sequence the SLAM rows stream (0 = all)")
    ap.add_argument("--slam-args", default="",
                    help="extra flags of the daemon's Slam client, space-separated (e.g. "
                         "'--max-pending-keyframes 1')")
    ap.add_argument("--plenoxd-args", default="",
                    help="extra plenoxd flags, space-separated (e.g. '--mapping-worker off')")
    ap.add_argument("--timeout", type=float, default=1800.0, help="limit per command (s)")
    ap.add_argument("--out", help="also write the markdown report to this file")
    args = ap.parse_args()
    try:
        scenarios = parse_scenarios(args.scenarios)
    except ValueError as exc:
        ap.error(str(exc))
    for binary in (args.plenox, args.plenoxd):
        if not os.access(binary, os.X_OK):
            ap.error("%s is not an executable (build it: bash scripts/build.sh)" % binary)

    notes = []
    started = datetime.datetime.now(datetime.timezone.utc)
    machine = machine_line()
    with tempfile.TemporaryDirectory(prefix="service_bench_") as tmp:
        dataset = os.path.join(os.path.abspath(args.data), args.sequence)
        name = args.sequence
        if args.sequence == "synthetic" or not os.path.isdir(dataset):
            if args.sequence != "synthetic":
                notes.append("%s not found under %s; ran the synthetic sequence instead"
                             % (args.sequence, args.data))
            dataset, name = os.path.join(tmp, "synthetic"), "synthetic"
            make_synthetic(args.plenox, dataset, args.timeout)

        data_dir = os.path.join(tmp, "daemon_data")
        os.makedirs(data_dir)
        map_path = os.path.join(data_dir, MAP_NAME + ".plx")
        if args.map:
            shutil.copyfile(args.map, map_path)
            notes.append("map: %s (given with --map); the daemon loads a copy" % args.map)
        else:
            m = run_json("map", [args.plenox, "map", "--dataset", dataset, "--out", map_path,
                                 "--every", str(args.every), "--json"], args.timeout)
            notes.append("map: %s keyframes of %s mapped in-process in %.0f s (every %d-th "
                         "frame, ground-truth poses); the daemon loads the same file"
                         % (m.get("keyframes"), name, m.get("seconds", 0), args.every))
        inproc_traj = os.path.join(tmp, "inprocess.txt")

        def in_process(label):
            return run_json(label, [args.plenox, "track", "--map", map_path, "--dataset",
                                    dataset, "--out", inproc_traj, "--json", "--quiet"],
                            args.timeout)

        # Before and after the daemon runs, so a load change in between shows.
        refs = [in_process("in-process track (before)")]
        inproc_ate = ate(args, inproc_traj, dataset)

        slam_ref = None
        if any(isinstance(sc, str) for sc in scenarios):
            # The reference trajectory: in-process SLAM (concurrent mapping) of the same frames.
            slam_ref = run_json("in-process slam",
                                [args.plenox, "slam", "--dataset", dataset, "--out",
                                 os.path.join(tmp, "inprocess_slam.txt"), "--json", "--quiet"]
                                + slam_frame_flags(args), args.timeout)
        daemon = start_daemon(args.plenoxd, args.plenox, data_dir,
                              os.path.join(tmp, "plenoxd.log"), args.plenoxd_args.split())
        rows = []
        slam_rows = []
        try:
            for i, scenario in enumerate(scenarios):
                if isinstance(scenario, str):
                    slam_rows.append(run_slam_scenario(args, daemon, dataset, tmp, i, scenario))
                    continue
                clients, mapping, encoding = scenario
                tag = "s%d_%dc_%s_%s" % (i, clients, "map" if mapping else "idle", encoding)
                load = None
                if mapping:
                    load = mapping_load(args, daemon, dataset)
                    time.sleep(3.0)  # the first keyframes are on the daemon and the job runs
                wall0 = time.monotonic()
                try:
                    results = run_clients(args, daemon, dataset, tmp, tag, clients, encoding)
                finally:
                    wall = time.monotonic() - wall0
                    if load is not None:
                        load.stop()
                if load is not None and load.failures:
                    notes.append("%s: the mapping job failed: %s" % (tag, load.failures[0]))
                row = latency_stats([timings for _, _, timings in results])
                row.update({
                    "clients": clients, "mapping": mapping, "encoding": encoding,
                    # Sum of each client's rate: every client streams for the whole window.
                    "fps": sum(r[0]["fps"] for r in results),
                    "lost": sum(r[0]["lost"] for r in results),
                    "ate": ate(args, results[0][1], dataset),
                    "wall": wall,
                    "map_jobs": load.jobs if load else None,
                })
                rows.append(row)
                if load is not None:
                    notes.append("%s: %d mapping jobs completed during the %.0f s window"
                                 % (tag, load.jobs, wall))
                log("%s: %.1f fps, round trip p50 %.1f ms p99 %.1f ms"
                    % (tag, rows[-1]["fps"], rows[-1]["rt_p50"], rows[-1]["rt_p99"]))
        finally:
            drain = daemon.stop()
        notes.append("plenoxd drained on SIGTERM with exit status %s" % drain)
        refs.append(in_process("in-process track (after)"))
    inproc_ms = sum(r["ms_per_frame_median"] for r in refs) / len(refs)

    cols = ["clients", "mapping job", "frames", "encoding", "FPS (all clients)",
            "round trip p50 ms", "round trip p99 ms", "daemon p50 ms", "daemon p99 ms",
            "overhead (p50 / in-process)", "lost", "ATE client 0 cm"]
    body = []
    for r in rows:
        body.append([str(r["clients"]), "yes" if r["mapping"] else "no", str(r["frames"]),
                     r["encoding"], "%.2f" % r["fps"], "%.1f" % r["rt_p50"],
                     "%.1f" % r["rt_p99"], "%.1f" % r["daemon_p50"], "%.1f" % r["daemon_p99"],
                     "%+.1f%%" % (100.0 * (r["rt_p50"] / inproc_ms - 1.0)), str(r["lost"]),
                     "%.2f" % (100.0 * r["ate"]) if r["ate"] is not None else "n/a"])
    header = [
        "## Service benchmark (`bench/service_bench.py`): tracking through plenoxd on loopback",
        "",
        "Run %s UTC, commit %s, on %s." % (started.strftime("%Y-%m-%d %H:%M"),
                                           git_commit() or "?", machine),
        "Sequence %s; in-process tracking of the same frames (`plenox track`, before and "
        "after the daemon runs): median %s ms per frame (mean %.1f used below), ATE %.2f cm."
        % (name, " / ".join("%.1f" % r["ms_per_frame_median"] for r in refs), inproc_ms,
           100.0 * inproc_ate if inproc_ate is not None else -1),
    ]
    notes.append("round trip: client-side, frame written to estimate read (encoding excluded); "
                 "daemon: the daemon's latency field (frame decoded to estimate sent); "
                 "overhead compares the round-trip median with the in-process median")
    notes.append("FPS: sum of the clients' rates, each = frames / its streaming time "
                 "(loading and encoding frames included); clients run in lock-step, so the "
                 "daemon never drops a frame")
    notes.append("mapping job: `plenox --server map` of the same sequence into a fresh map, "
                 "restarted whenever it finishes, for the whole window")
    if args.plenoxd_args:
        notes.append("plenoxd ran with %s" % args.plenoxd_args)
    if args.slam_args:
        notes.append("the Slam client ran with %s" % args.slam_args)
    report = render_table(cols, body, header, notes) if rows else ""
    if slam_rows:
        alone = next((r for r in rows if r["clients"] == 1 and not r["mapping"]
                      and r["encoding"] == "raw"), None)
        report += slam_report(slam_rows, slam_ref, alone, name)
    write_report(report, args.out)


if __name__ == "__main__":
    try:
        main()
    except CommandError as exc:
        log("FAILED: %s" % exc)
        sys.exit(1)
