#!/usr/bin/python3
"""A plenoxd fleet on one machine: N replicas on one shared map folder behind HAProxy.

    python3 scripts/fleet.py [--replicas 3] [--port 50051] [--dir plenoxd_fleet]

Starts N `plenoxd --shared-dir` replicas on loopback ports (each with its metrics port), then
HAProxy (deploy/haproxy/haproxy.cfg.template: HTTP/2, consistent hash on x-plenoxd-map, gRPC
health checks) on 127.0.0.1:PORT, prints where to point `plenox --server` and each replica's
pid and metrics, and stops everything on Ctrl-C (replicas get SIGTERM: they save their maps
and give their leases up). Lease and snapshot intervals are short, for a failover in seconds
(deploy/README.md, "A fleet on one machine").

tests/deploy/fleet_test.py drives the same Fleet class (kill -9 of a replica, a replica added
with a reload of HAProxy). Python's standard library only.
"""

import argparse
import os
import re
import signal
import socket
import subprocess
import sys
import time
import urllib.request

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TEMPLATE = os.path.join(ROOT, "deploy", "haproxy", "haproxy.cfg.template")


def wait_for(predicate, timeout, every=0.05):
    """Polls `predicate` until it returns something true or `timeout` seconds pass."""
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value or time.monotonic() >= deadline:
            return value
        time.sleep(every)


def read(path):
    try:
        with open(path, encoding="utf-8", errors="replace") as f:
            return f.read()
    except FileNotFoundError:
        return ""


class Replica:
    """One plenoxd process; its port and metrics port come from its stdout."""

    def __init__(self, binary, name, work, shared, server_id, flags):
        self.name, self.server_id = name, server_id
        self.dir = os.path.join(work, name)
        os.makedirs(self.dir, exist_ok=True)
        self.out = os.path.join(self.dir, "plenoxd.out")
        self.err = os.path.join(self.dir, "plenoxd.err")
        args = [binary, "--listen", "127.0.0.1:0", "--shared-dir", shared,
                "--metrics-port", "0"] + flags
        with open(self.out, "wb") as out, open(self.err, "wb") as err:
            # Own process group: a terminal's Ctrl-C reaches the fleet script, which stops the
            # replicas in order, not every replica at once.
            self.proc = subprocess.Popen(args, stdout=out, stderr=err, stdin=subprocess.DEVNULL,
                                         start_new_session=True)
        self.port = self.metrics_port = None

    def wait_listening(self, timeout=30):
        def ports():
            text = read(self.out)
            listen = re.search(r"plenoxd listening on port (\d+)", text)
            metrics = re.search(r"metrics on port (\d+)", text)
            if self.proc.poll() is not None:
                raise RuntimeError(f"replica {self.name} exited ({self.proc.returncode}):\n"
                                   f"{read(self.err)[-2000:]}")
            return (int(listen.group(1)), int(metrics.group(1))) if listen and metrics else None
        found = wait_for(ports, timeout)
        if not found:
            raise RuntimeError(f"replica {self.name} did not start in {timeout} s")
        self.port, self.metrics_port = found
        return self

    @property
    def address(self):
        return f"127.0.0.1:{self.port}"

    def alive(self):
        return self.proc.poll() is None

    def metrics(self):
        """The replica's Prometheus metrics as {name: value} (unlabelled series only)."""
        url = f"http://127.0.0.1:{self.metrics_port}/metrics"
        with urllib.request.urlopen(url, timeout=5) as response:
            text = response.read().decode()
        values = {}
        for line in text.splitlines():
            parts = line.split()
            if len(parts) == 2 and not line.startswith("#") and "{" not in parts[0]:
                values[parts[0]] = float(parts[1])
        return values

    def kill(self):
        """SIGKILL: no drain, no save, the lease left to expire."""
        self.proc.kill()
        self.proc.wait()

    def stop(self, timeout=60):
        """SIGTERM: drains, saves its maps, gives its leases up; returns the exit code."""
        if self.alive():
            self.proc.terminate()
        try:
            return self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            return self.proc.wait()

    def log(self):
        return read(self.out) + read(self.err)


class Fleet:
    """Replicas on one shared folder and the HAProxy in front of them."""

    def __init__(self, plenoxd, work, lease_seconds=3.0, snapshot_seconds=2.0, flags=(),
                 haproxy="haproxy"):
        self.plenoxd, self.work, self.haproxy = plenoxd, os.path.abspath(work), haproxy
        self.shared = os.path.join(self.work, "shared")
        os.makedirs(self.shared, exist_ok=True)
        self.flags = ["--lease-seconds", str(lease_seconds),
                      "--snapshot-seconds", str(snapshot_seconds)] + list(flags)
        self.replicas = []
        self.proxy = None
        self.proxy_address = None
        self.config = os.path.join(self.work, "haproxy.cfg")
        self.stats_socket = os.path.join(self.work, "haproxy.sock")
        self.proxy_log = os.path.join(self.work, "haproxy.log")

    def add_replica(self):
        """Starts one more replica (not yet in the proxy: reload_proxy())."""
        server_id = len(self.replicas) + 1
        replica = Replica(self.plenoxd, f"r{server_id}", self.work, self.shared, server_id,
                          self.flags)
        self.replicas.append(replica)
        return replica.wait_listening()

    def live(self):
        return [r for r in self.replicas if r.alive()]

    def render_config(self, listen):
        with open(TEMPLATE, encoding="utf-8") as f:
            text = f.read()
        servers = "\n".join(f"    server {r.name} {r.address} id {r.server_id}"
                            for r in self.live())
        return (text.replace("@LISTEN@", listen).replace("@STATS_SOCKET@", self.stats_socket)
                .replace("@SERVERS@", servers))

    def start_proxy(self, port=0):
        """Starts HAProxy on 127.0.0.1:port (0: a free port) in front of the live replicas."""
        if port == 0:
            with socket.socket() as s:
                s.bind(("127.0.0.1", 0))
                port = s.getsockname()[1]
        self.proxy_address = f"127.0.0.1:{port}"
        self._run_proxy([])
        if not wait_for(self._proxy_accepts, 10):
            raise RuntimeError(f"haproxy did not listen on {self.proxy_address}:\n"
                               f"{read(self.proxy_log)[-2000:]}")
        return self.proxy_address

    def reload_proxy(self):
        """A new HAProxy with the live replicas takes over the port; the old one finishes its
        streams (-sf: soft stop, GOAWAY to its clients) and exits."""
        old = self.proxy
        self._run_proxy(["-sf", str(old.pid)])
        # The new process listens once it is up; the old one is gone soon after.
        wait_for(lambda: old.poll() is not None, 10)

    def _run_proxy(self, extra):
        with open(self.config, "w", encoding="utf-8") as f:
            f.write(self.render_config(self.proxy_address))
        check = subprocess.run([self.haproxy, "-c", "-q", "-f", self.config],
                               capture_output=True, text=True)
        if check.returncode != 0:
            raise RuntimeError(f"haproxy rejects {self.config}:\n{check.stdout}{check.stderr}")
        with open(self.proxy_log, "ab") as log:
            self.proxy = subprocess.Popen([self.haproxy, "-db", "-f", self.config] + extra,
                                          stdout=log, stderr=log, stdin=subprocess.DEVNULL,
                                          start_new_session=True)

    def _proxy_accepts(self):
        host, port = self.proxy_address.rsplit(":", 1)
        try:
            with socket.create_connection((host, int(port)), timeout=0.5):
                return True
        except OSError:
            return False

    def server_states(self):
        """{replica name: "UP" | "DOWN" | ...} from HAProxy's stats socket."""
        with socket.socket(socket.AF_UNIX) as s:
            s.settimeout(5)
            s.connect(self.stats_socket)
            s.sendall(b"show stat\n")
            data = b""
            while chunk := s.recv(65536):
                data += chunk
        states = {}
        for line in data.decode().splitlines():
            fields = line.split(",")
            if len(fields) > 17 and fields[0] == "replicas" and fields[1] not in (
                    "FRONTEND", "BACKEND"):
                states[fields[1]] = fields[17]
        return states

    def stop(self):
        codes = {r.name: r.stop() for r in self.replicas if r.alive()}
        if self.proxy is not None and self.proxy.poll() is None:
            self.proxy.terminate()
            try:
                self.proxy.wait(10)
            except subprocess.TimeoutExpired:
                self.proxy.kill()
        return codes


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--replicas", type=int, default=3)
    parser.add_argument("--port", type=int, default=50051, help="the proxy's port (0: any)")
    parser.add_argument("--dir", default="plenoxd_fleet",
                        help="work folder: shared/ (the maps), one folder per replica, the "
                             "proxy's config and log")
    parser.add_argument("--plenoxd", default=os.path.join(ROOT, "build", "server", "plenoxd"))
    parser.add_argument("--lease-seconds", type=float, default=3.0)
    parser.add_argument("--snapshot-seconds", type=float, default=2.0)
    parser.add_argument("--threads", type=int, default=0,
                        help="CPU threads per replica (0: all cores)")
    args = parser.parse_args()
    for binary, hint in ((args.plenoxd, "bash scripts/build.sh plenoxd"),
                         ("haproxy", "bash scripts/install_deps.sh (as root)")):
        if not (os.access(binary, os.X_OK) or
                subprocess.run(["which", binary], capture_output=True).returncode == 0):
            sys.exit(f"fleet: {binary} not found; {hint}")
    fleet = Fleet(args.plenoxd, args.dir, args.lease_seconds, args.snapshot_seconds,
                  ["--threads", str(args.threads)])
    stop = []
    signal.signal(signal.SIGINT, lambda *_: stop.append(1))
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    try:
        for _ in range(args.replicas):
            fleet.add_replica()
        address = fleet.start_proxy(args.port)
        print(f"fleet: {args.replicas} plenoxd replicas (maps in {fleet.shared}, lease "
              f"{args.lease_seconds:g} s, snapshots every {args.snapshot_seconds:g} s) behind "
              f"haproxy on {address}")
        for r in fleet.replicas:
            print(f"fleet:   {r.name} {r.address} pid {r.proc.pid} "
                  f"metrics http://127.0.0.1:{r.metrics_port}/metrics log {r.dir}/")
        print(f"fleet: stream SLAM through it, e.g.\n"
              f"  ./build/clients/plenox/plenox synth --out demo_seq\n"
              f"  ./build/clients/plenox/plenox --server {address} slam --dataset demo_seq "
              f"--name hall --out slam.txt\n"
              f"fleet: Ctrl-C stops everything", flush=True)
        while not stop:
            for r in fleet.replicas:
                if r.proc.poll() is not None and not getattr(r, "reported", False):
                    r.reported = True
                    print(f"fleet: {r.name} exited ({r.proc.returncode}); its maps move to "
                          f"the others within a lease", flush=True)
            time.sleep(0.5)
    finally:
        codes = fleet.stop()
        print("fleet: stopped " + ", ".join(f"{n} (exit {c})" for n, c in codes.items()))


if __name__ == "__main__":
    main()
