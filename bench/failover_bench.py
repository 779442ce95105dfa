#!/usr/bin/python3
"""Clients riding through a failover (issue 24, part 5): what a kill -9 of the daemon costs a
`plenox --server ... slam` run that reconnects.

Each run: plenoxd on a loopback port with --snapshot-seconds S streams the synthetic room from
`plenox --server ADDR --retry-seconds 60 slam` (lock-step, or --realtime at the sequence's 30
fps); once the map's snapshot is on disk and --kill-after seconds have passed the daemon is
killed with SIGKILL, and after --gap seconds a new daemon is started on the same port and data
directory (it loads the snapshot before it listens). The CLI reconnects, relocalises and
finishes. Reported per run: how long the daemon was gone (kill to the new one listening), the
time from the kill to the first frame tracked after the reconnect (the CLI's
failover_resume_s, from the stream breaking, which on loopback is the kill itself), the frames
lost, and the position RMSE (no alignment) of the frames after the reconnect and of the whole
run, next to a run without a kill.

    /usr/bin/python3 bench/failover_bench.py --out /tmp/failover_bench.md
"""

import argparse
import datetime
import json
import math
import os
import re
import shutil
import signal
import subprocess
import tempfile
import time

from bench_common import (REPO, CommandError, free_port, git_commit, log, machine_line,
                          make_synthetic, read_rows, render_table, set_log_prefix, write_report)


def start_daemon(args, address, data_dir, log_path):
    """plenoxd on `address`; (process, seconds until it said it listens)."""
    started = time.monotonic()
    log_file = open(log_path, "w")
    proc = subprocess.Popen([args.plenoxd, "--listen", address, "--data-dir", data_dir,
                             "--snapshot-seconds", str(args.snapshot_seconds), "--backend",
                             "cpu"], stdin=subprocess.DEVNULL, stdout=log_file,
                            stderr=subprocess.STDOUT, start_new_session=True)
    while time.monotonic() - started < 60:
        with open(log_path) as f:
            if "plenoxd listening on port" in f.read():
                return proc, time.monotonic() - started
        if proc.poll() is not None:
            raise CommandError("plenoxd exited with %d at start (log: %s)"
                               % (proc.returncode, log_path))
        time.sleep(0.01)
    proc.kill()
    raise CommandError("plenoxd did not listen within 60 s (log: %s)" % log_path)


def stop(proc):
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=120)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def position_rmse(traj_path, truth, first_stamp):
    """RMSE (m) of the positions in a TUM trajectory from timestamp first_stamp on."""
    errors = []
    for row in read_rows(traj_path):
        t = float(row[0])
        if t + 1e-9 < first_stamp:
            continue
        key = round(t, 6)
        if key in truth:
            errors.append(sum((float(row[1 + c]) - truth[key][c]) ** 2 for c in range(3)))
    return math.sqrt(sum(errors) / len(errors)) if errors else float("nan")


def one_run(args, work, seq, truth, stamps, mode, gap, kill, tag):
    data = os.path.join(work, tag, "data")
    os.makedirs(data)
    address = "127.0.0.1:%d" % free_port()
    first, _ = start_daemon(args, address, data, os.path.join(work, tag, "first.log"))
    traj = os.path.join(work, tag, "traj.txt")
    cmd = [args.plenox, "--server", address, "--retry-seconds", "60", "slam", "--dataset", seq,
           "--name", "room", "--out", traj, "--json", "--quiet"]
    if mode == "realtime":
        cmd.append("--realtime")
    err_path = os.path.join(work, tag, "plenox.err")
    out_path = os.path.join(work, tag, "plenox.out")
    log("%s: %s" % (tag, " ".join(cmd)))
    began = time.monotonic()
    with open(out_path, "w") as out, open(err_path, "w") as err:
        cli = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=out, stderr=err)
    row = {"mode": mode, "gap": gap if kill else None}
    second = None
    try:
        if kill:
            snapshot = os.path.join(data, "room.plx")
            while cli.poll() is None and not (os.path.exists(snapshot) and
                                              time.monotonic() - began >= args.kill_after):
                time.sleep(0.01)
            if cli.poll() is not None:
                raise CommandError("%s: the run ended before the kill" % tag)
            first.kill()
            first.wait()
            killed = time.monotonic()
            row["killed_at_s"] = killed - began
            time.sleep(gap)
            second, _ = start_daemon(args, address, data, os.path.join(work, tag, "second.log"))
            row["daemon_back_s"] = time.monotonic() - killed
        cli.wait(timeout=args.timeout)
    finally:
        if cli.poll() is None:
            cli.kill()
        for proc in (first, second):
            if proc is not None:
                stop(proc)
    with open(err_path) as f:
        err_text = f.read()
    if cli.returncode != 0:
        raise CommandError("%s: plenox exited %d\n%s" % (tag, cli.returncode, err_text[-2000:]))
    with open(out_path) as f:
        result = json.loads([l for l in f.read().splitlines() if l.strip()][-1])
    row.update({k: result.get(k) for k in ("reconnects", "frames_lost_in_failover",
                                           "failover_resume_s", "processed", "dropped",
                                           "ate_none_m", "frames")})
    m = re.search(r"going on from frame (\d+)", err_text)
    if m:
        resumed = int(m.group(1))
        row["resumed_at"] = resumed
        row["ate_after_m"] = position_rmse(traj, truth, stamps[resumed])
    return row


def fmt(value, spec, scale=1.0):
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    return spec % (value * scale)


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    build = os.path.join(REPO, "build")
    parser.add_argument("--plenoxd", default=os.path.join(build, "server", "plenoxd"))
    parser.add_argument("--plenox", default=os.path.join(build, "clients", "plenox", "plenox"))
    parser.add_argument("--frames", type=int, default=150)
    parser.add_argument("--width", type=int, default=160)
    parser.add_argument("--height", type=int, default=120)
    parser.add_argument("--snapshot-seconds", type=float, default=1.0)
    parser.add_argument("--kill-after", type=float, default=2.5,
                        help="seconds into the run (and a snapshot on disk) before the kill")
    parser.add_argument("--gaps", type=float, nargs="+", default=[0.0, 3.0],
                        help="seconds between the kill and the new daemon's start")
    parser.add_argument("--runs", type=int, default=2)
    parser.add_argument("--timeout", type=float, default=600)
    parser.add_argument("--out")
    parser.add_argument("--keep", action="store_true")
    args = parser.parse_args()
    set_log_prefix("failover")
    machine = machine_line()
    work = tempfile.mkdtemp(prefix="plx_failover_bench_")
    seq = os.path.join(work, "sequence")
    make_synthetic(args.plenox, seq, 300, args.frames,
                   ["--width", str(args.width), "--height", str(args.height)])
    truth = {round(float(r[0]), 6): [float(v) for v in r[1:4]]
             for r in read_rows(os.path.join(seq, "groundtruth.txt"))}
    stamps = [float(r[0]) for r in read_rows(os.path.join(seq, "rgb.txt"))]
    rows = []
    for mode in ("lockstep", "realtime"):
        rows.append(one_run(args, work, seq, truth, stamps, mode, 0.0, False,
                            "%s_base" % mode))
        for gap in args.gaps:
            for r in range(args.runs):
                rows.append(one_run(args, work, seq, truth, stamps, mode, gap, True,
                                    "%s_gap%g_r%d" % (mode, gap, r)))
    cols = ["mode", "restart gap (s)", "daemon gone (s)", "kill -> first tracked frame (s)",
            "reconnects", "frames lost", "processed / dropped", "RMSE after reconnect (cm)",
            "RMSE whole run (cm)"]
    body = []
    for row in rows:
        body.append([row["mode"], fmt(row["gap"], "%.0f") if row["gap"] is not None else
                     "no kill", fmt(row.get("daemon_back_s"), "%.2f"),
                     fmt(row.get("failover_resume_s"), "%.2f"), str(row["reconnects"]),
                     str(row["frames_lost_in_failover"]),
                     "%s / %s" % (row["processed"], row["dropped"]),
                     fmt(row.get("ate_after_m"), "%.2f", 100),
                     fmt(row.get("ate_none_m"), "%.2f", 100)])
    header = ["Machine: %s. %s, commit %s (plus the working tree)." % (
        machine, datetime.date.today().isoformat(), git_commit()),
        "Synthetic room, %d frames %dx%d at 30 fps; plenoxd --backend cpu --snapshot-seconds "
        "%g; SIGKILL %.1f s into the run once a snapshot was on disk." % (
            args.frames, args.width, args.height, args.snapshot_seconds, args.kill_after)]
    write_report(render_table(cols, body, header, []), args.out)
    if not args.keep:
        shutil.rmtree(work, ignore_errors=True)
    else:
        log("work folder kept: %s" % work)


if __name__ == "__main__":
    main()
