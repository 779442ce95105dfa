"""Pieces shared by the benchmark scripts in bench/ (see bench/README.md).

- TUM-layout dataset reading: intrinsics, frame association, ground-truth pose interpolation,
  image loading, TUM trajectory writing. Used by the Open3D peers in bench/peers/. Association
  and slerp are the Python client's (clients/python/plenoxd_client/timestamps.py).
- Orchestration: running a command with its stderr passed through live, reading the JSON
  object on the last line of its stdout, turning every failure into a CommandError, and
  printing a markdown table with notes. Used by map_bench.py and track_bench.py.

Only the standard library is needed at import time. numpy is needed by the pose and
trajectory helpers and cv2 (python3-opencv) by load_rgbd, so the orchestrators run without
them. Run everything with Debian's interpreter, /usr/bin/python3.
"""

import bisect
import collections
import functools
import importlib.util
import json
import math
import os
import platform
import signal
import socket
import subprocess
import sys
import threading
import time

try:
    import numpy as np
except ImportError:  # only the dataset helpers need it
    np = None

BENCH_DIR = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(BENCH_DIR)
PEERS_DIR = os.path.join(BENCH_DIR, "peers")
PEER_PYTHON = "/usr/bin/python3"  # Debian's interpreter: python3-open3d, python3-opencv
STDERR_TAIL = 3000  # characters of a failed command's stderr kept for the report
ASSOC_MAX_DT = 0.02  # s, rgb<->depth association and GT look-up tolerance

_log_prefix = "[bench] "


def set_log_prefix(name):
    """Messages from log() and run_cmd() start with '[name] '."""
    global _log_prefix
    _log_prefix = "[%s] " % name


def log(msg):
    print(_log_prefix + msg, file=sys.stderr, flush=True)


# ----------------------------------------------------------------------------------------
# TUM-layout dataset reading
# ----------------------------------------------------------------------------------------

def read_rows(path):
    """Whitespace-split, non-empty, non-comment lines of a TUM text file."""
    rows = []
    with open(path) as f:
        for line in f:
            line = line.strip()
            if line and not line.startswith("#"):
                rows.append(line.split())
    return rows


def read_intrinsics(dataset):
    rows = read_rows(os.path.join(dataset, "intrinsics.txt"))
    if not rows or len(rows[0]) < 7:
        raise ValueError("intrinsics.txt: expected 'fx fy cx cy width height depth_scale ...'")
    v = rows[0]
    return {
        "fx": float(v[0]), "fy": float(v[1]), "cx": float(v[2]), "cy": float(v[3]),
        "width": int(float(v[4])), "height": int(float(v[5])), "depth_scale": float(v[6]),
    }


@functools.lru_cache(maxsize=None)
def _timestamps():
    """clients/python/plenoxd_client/timestamps.py: TUM association and slerp, written once for
    the Python client and the bench. Loaded by its path, because importing the plenoxd_client
    package needs grpc and the stubs a build generates, which the peers' interpreter need not
    have. Needs numpy."""
    path = os.path.join(REPO, "clients", "python", "plenoxd_client", "timestamps.py")
    spec = importlib.util.spec_from_file_location("plenoxd_client_timestamps", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def read_frames(dataset):
    """Frame list in associations.txt order: (t_rgb, rgb_path, t_depth, depth_path)."""
    assoc = os.path.join(dataset, "associations.txt")
    if os.path.exists(assoc):
        frames = [(float(r[0]), r[1], float(r[2]), r[3]) for r in read_rows(assoc)]
    else:
        # Paired one-to-one, closest stamps first (the TUM associate.py rule).
        rgb = read_rows(os.path.join(dataset, "rgb.txt"))
        depth = read_rows(os.path.join(dataset, "depth.txt"))
        pairs = _timestamps().associate([float(r[0]) for r in rgb], [float(r[0]) for r in depth],
                                        ASSOC_MAX_DT)
        frames = [(float(rgb[i][0]), rgb[i][1], float(depth[j][0]), depth[j][1])
                  for i, j in pairs]
    return [(tr, os.path.join(dataset, pr), td, os.path.join(dataset, pd))
            for tr, pr, td, pd in frames]


def quat_to_rot(q):
    """Rotation matrix of the unit quaternion (qx, qy, qz, qw)."""
    x, y, z, w = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def rot_to_quat(R):
    """Unit quaternion (qx, qy, qz, qw) with qw >= 0 of a rotation matrix. The matrix is first
    made exactly orthonormal (nearest rotation by SVD), since chained products drift."""
    U, _, Vt = np.linalg.svd(np.asarray(R, dtype=np.float64))
    R = U @ Vt
    if np.linalg.det(R) < 0:  # cannot happen for a product of rotations; be safe
        R = U @ np.diag([1.0, 1.0, -1.0]) @ Vt
    tr = R[0, 0] + R[1, 1] + R[2, 2]
    if tr > 0.0:
        s = math.sqrt(tr + 1.0) * 2.0
        q = [(R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s,
             0.25 * s]
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = math.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2]) * 2.0
        q = [0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s,
             (R[2, 1] - R[1, 2]) / s]
    elif R[1, 1] > R[2, 2]:
        s = math.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2]) * 2.0
        q = [(R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s,
             (R[0, 2] - R[2, 0]) / s]
    else:
        s = math.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1]) * 2.0
        q = [(R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s,
             (R[1, 0] - R[0, 1]) / s]
    q = np.array(q)
    q /= np.linalg.norm(q)
    return -q if q[3] < 0.0 else q


class GroundTruth:
    """groundtruth.txt ('t tx ty tz qx qy qz qw', camera-to-world) with interpolation."""

    def __init__(self, path):
        rows = sorted((float(r[0]), [float(x) for x in r[1:8]]) for r in read_rows(path))
        if not rows:
            raise ValueError("%s has no poses" % path)
        self.t = [r[0] for r in rows]
        self.p = [np.array(r[1]) for r in rows]

    def pose(self, t, max_dt=ASSOC_MAX_DT):
        """4x4 camera-to-world at time t, or None when t is off the ends by more than max_dt."""
        i = bisect.bisect_left(self.t, t)
        if i < len(self.t) and self.t[i] == t:
            tr, q = self.p[i][:3], self.p[i][3:]
        elif i == 0 or i == len(self.t):
            j = 0 if i == 0 else len(self.t) - 1
            if abs(self.t[j] - t) > max_dt:
                return None
            tr, q = self.p[j][:3], self.p[j][3:]
        else:
            t0, t1 = self.t[i - 1], self.t[i]
            a = (t - t0) / (t1 - t0)
            p0, p1 = self.p[i - 1], self.p[i]
            tr = (1.0 - a) * p0[:3] + a * p1[:3]
            q = _timestamps().slerp(p0[3:], p1[3:], a)
        T = np.eye(4)
        T[:3, :3] = quat_to_rot(np.asarray(q) / np.linalg.norm(q))
        T[:3, 3] = tr
        return T


def load_rgbd(frame, intr):
    """Decodes a frame: (uint16 HxW depth, uint8 HxWx3 RGB), checked against intrinsics."""
    import cv2  # python3-opencv; imported here so the orchestrators do not need it
    _, rgb_path, _, depth_path = frame
    depth = cv2.imread(depth_path, cv2.IMREAD_UNCHANGED)
    bgr = cv2.imread(rgb_path, cv2.IMREAD_COLOR)
    if depth is None or bgr is None:
        raise IOError("cannot read %s or %s" % (depth_path, rgb_path))
    if depth.dtype != np.uint16 or depth.ndim != 2:
        raise ValueError("%s: expected 16-bit single-channel depth, got %s %s"
                         % (depth_path, depth.dtype, depth.shape))
    want = (intr["height"], intr["width"])
    if depth.shape != want or bgr.shape[:2] != want:
        raise ValueError("%s: image size %s / %s does not match intrinsics.txt %s"
                         % (rgb_path, bgr.shape[:2], depth.shape, want))
    rgb = np.ascontiguousarray(bgr[:, :, ::-1])
    return depth, rgb


def write_tum(path, stamps, poses):
    """Writes 't tx ty tz qx qy qz qw' lines (camera-to-world 4x4 poses), atomically."""
    tmp = path + ".tmp.%d" % os.getpid()
    with open(tmp, "w") as f:
        for t, T in zip(stamps, poses):
            q = rot_to_quat(T[:3, :3])
            f.write("%.6f %.7f %.7f %.7f %.9f %.9f %.9f %.9f\n"
                    % (t, T[0, 3], T[1, 3], T[2, 3], q[0], q[1], q[2], q[3]))
    os.replace(tmp, path)


def peak_rss_mb():
    """This process's peak resident set size in MB (ru_maxrss KiB / 1024, as plenox reports
    it)."""
    import resource  # Unix only; imported here so the module still imports elsewhere
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def percentile(values, p):
    """Linear-interpolation percentile (numpy's default), without numpy."""
    v = sorted(values)
    if not v:
        return None
    k = (len(v) - 1) * p / 100.0
    lo = int(math.floor(k))
    hi = min(lo + 1, len(v) - 1)
    return v[lo] + (v[hi] - v[lo]) * (k - lo)


# ----------------------------------------------------------------------------------------
# Running commands
# ----------------------------------------------------------------------------------------

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


def read_timings(path):
    """(roundtrip_ms, daemon_ms) lists from `plenox track --timings`."""
    roundtrip, daemon = [], []
    with open(path) as f:
        for line in f:
            if line.startswith("#") or not line.strip():
                continue
            parts = line.split()
            roundtrip.append(float(parts[2]))
            daemon.append(float(parts[3]))
    return roundtrip, daemon


def free_port():
    """A free TCP port on 127.0.0.1 (servers in benchmarks listen on loopback only)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class DaemonProcess:
    """plenoxd on a free loopback port with `args` after --listen, its output in `log_path`.
    Returns once `plenox maps` answers and `ready(its stdout)` holds (60 s at most, else
    CommandError). stop() drains it with SIGTERM and returns the exit status; kill() is
    kill -9."""

    def __init__(self, plenoxd, plenox, args, log_path, ready=lambda listing: True):
        self.address = "127.0.0.1:%d" % free_port()
        self.plenox = plenox
        self.log = open(log_path, "w")
        cmd = [plenoxd, "--listen", self.address] + list(args)
        log("plenoxd: %s" % " ".join(cmd))
        self.proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=self.log,
                                     stderr=subprocess.STDOUT, start_new_session=True)
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise CommandError("plenoxd exited with status %d at start (log: %s)"
                                   % (self.proc.returncode, log_path))
            probe = subprocess.run([plenox, "--server", self.address, "maps"],
                                   capture_output=True, text=True)
            if probe.returncode == 0 and ready(probe.stdout):
                return
            time.sleep(0.3)
        self.kill()
        raise CommandError("plenoxd was not ready within 60 s (log: %s)" % log_path)

    def stop(self, timeout_s=120):
        self.proc.send_signal(signal.SIGTERM)
        try:
            code = self.proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            self.kill()
            return "killed after %d s" % timeout_s
        self.log.close()
        return code

    def kill(self):
        self.proc.send_signal(signal.SIGKILL)
        self.proc.wait()
        self.log.close()


class CommandLoop:
    """Runs a command again and again in a thread until stop() (a client that keeps the daemon
    busy while a benchmark measures something else). `command(n)` gives the n-th run's argv
    (1, 2, ...). `jobs` counts the runs that exited 0; the first failing run ends the loop and
    its stderr's end is in `failures`. stop() sends the running command SIGINT (a client
    leaving; the daemon cancels its job) and waits for the thread."""

    def __init__(self, command, join_timeout_s=120):
        self.command = command
        self.join_timeout_s = join_timeout_s
        self.stopping = threading.Event()
        self.proc = None
        self.jobs = 0
        self.failures = []
        self.lock = threading.Lock()
        self.thread = threading.Thread(target=self._loop, daemon=True)
        self.thread.start()

    def _loop(self):
        n = 0
        while not self.stopping.is_set():
            n += 1
            with self.lock:
                if self.stopping.is_set():
                    return
                self.proc = subprocess.Popen(self.command(n), stdin=subprocess.DEVNULL,
                                             stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                             start_new_session=True)
            _, err = self.proc.communicate()
            if self.stopping.is_set():
                return
            if self.proc.returncode == 0:
                self.jobs += 1
            else:
                self.failures.append(err.decode("utf-8", "replace")[-400:])
                return

    def stop(self):
        with self.lock:
            self.stopping.set()
            if self.proc is not None and self.proc.poll() is None:
                self.proc.send_signal(signal.SIGINT)
        self.thread.join(timeout=self.join_timeout_s)


def peer_env():
    """Environment for an Open3D peer: OpenMP x TBB oversubscription otherwise."""
    env = dict(os.environ)
    env["OMP_WAIT_POLICY"] = "passive"
    return env


def copy_keys(src, dst, keys):
    """Copies the keys src has; a key it lacks stays absent, so its cell says 'failed'."""
    for k in keys:
        if k in src:
            dst[k] = src[k]


def check_keys(label, obj, keys):
    missing = [k for k in keys if k not in obj]
    return ["%s: JSON lacks %s" % (label, ", ".join(missing))] if missing else []


def make_synthetic(plenox, synth_dir, timeout, frames=None, extra=()):
    """`plenox synth --out synth_dir [--frames N] [extra...]` (extra: more synth flags, e.g.
    --width 640 --path walk-out); raises CommandError when it fails or writes no
    intrinsics.txt."""
    cmd = [plenox, "synth", "--out", synth_dir]
    if frames:
        cmd += ["--frames", str(frames)]
    cmd += list(extra)
    if not os.access(plenox, os.X_OK):
        raise CommandError("plenox binary not found or not executable: %s" % plenox)
    stdout, _ = run_cmd("synthetic synth", cmd, timeout)
    if stdout.strip():
        sys.stderr.write(stdout)
    if not os.path.exists(os.path.join(synth_dir, "intrinsics.txt")):
        raise CommandError("%s has no intrinsics.txt after `plenox synth`" % synth_dir)


def list_sequences(data_dir, wanted, notes, need_ground_truth=False):
    """(name, path) of the TUM-layout subfolders of data_dir (only `wanted` ones if given);
    with need_ground_truth, only those with a groundtruth.txt (a benchmark that maps or scores
    with known poses); what is skipped or missing goes to notes."""
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
        if need_ground_truth and not os.path.exists(os.path.join(path, "groundtruth.txt")):
            notes.append("%s skipped: no groundtruth.txt (this benchmark needs known poses)" % name)
            continue
        seqs.append((name, path))
    if wanted is not None:
        found = {s[0] for s in seqs}
        for w in wanted:
            if w not in found and not os.path.isdir(os.path.join(data_dir, w)):
                notes.append("sequence %s not found under %s" % (w, data_dir))
    return seqs


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


def render_table(cols, body, header_lines, notes):
    """Markdown: header lines, a blank line, the table (body: lists of cell strings), then
    the notes as a list; a multi-line note's later lines go in a code block."""
    out = list(header_lines) + [""]
    out.append("| " + " | ".join(cols) + " |")
    out.append("|" + "|".join(" --- " for _ in cols) + "|")
    for vals in body:
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


def write_report(text, out_path):
    """Prints the report on stdout and, with out_path, writes it there too."""
    sys.stdout.write("\n" + text)
    sys.stdout.flush()
    if out_path:
        out = os.path.abspath(out_path)
        os.makedirs(os.path.dirname(out), exist_ok=True)
        with open(out, "w") as f:
            f.write(text)
        log("wrote %s" % out)
