#!/usr/bin/python3
"""A plenoxd fleet on one machine, end to end (issue 24, part 4): three replicas on one shared
folder behind HAProxy (scripts/fleet.py), driven with the plenox CLI through the proxy.

    /usr/bin/python3 tests/deploy/fleet_test.py --plenoxd <plenoxd> --plenox <plenox> [--keep]

1. Maps made through the proxy spread over the replicas, and every call naming a map reaches
   the one replica holding it (HAProxy's log: replica per x-plenoxd-map value).
2. Once a map's snapshot is on the shared folder, its owner is killed (SIGKILL). The next call
   for the map through the proxy (plenox --retry-seconds) is answered by another replica with
   the snapshot's content, within 10 s of the kill; HAProxy's health check (gRPC Health/Check)
   marks the dead replica DOWN.
3. A fourth replica joins (HAProxy reloaded with it): the maps the ring now gives it are handed
   over (their owners save and release them; the newcomer's retried calls load them), each map
   is then held by exactly one replica, and nothing was written by two owners: no fenced save,
   no lease lost, and every lease's fencing token only grew.
Prints the failover and handoff times (docs/BENCHMARKS.md, "Fleet"). Exits 0 when everything
passed, 1 with the failures, 77 (skip) when haproxy is not installed.
"""

import argparse
import glob
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import threading
import time

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, os.path.join(ROOT, "scripts"))
from fleet import Fleet, wait_for  # noqa: E402

MAPS = [f"room{i}" for i in range(8)]
LEASE_S, SNAPSHOT_S = 3.0, 1.0
FAILOVER_GOAL_S = 10.0


def check(failures, condition, what):
    print(f"  [{'ok  ' if condition else 'FAIL'}] {what}", flush=True)
    if not condition:
        failures.append(what)
    return condition


class Cli:
    def __init__(self, plenox):
        self.plenox = plenox

    def run(self, server, *args, retry=30, timeout=120):
        cmd = [self.plenox, "--server", server, "--retry-seconds", str(retry)] + list(args)
        return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)

    def json(self, server, *args, retry=30):
        done = self.run(server, *args, "--json", retry=retry)
        if done.returncode != 0:
            raise RuntimeError(f"plenox {' '.join(args)} on {server}: {done.stderr.strip()}")
        return json.loads(done.stdout.strip().splitlines()[-1])

    def maps(self, server):
        done = self.run(server, "maps", "--json", retry=0)
        if done.returncode != 0:
            raise RuntimeError(f"plenox maps on {server}: {done.stderr.strip()}")
        listed = [json.loads(line) for line in done.stdout.splitlines() if line.strip()]
        return {m["name"]: m for m in listed}


class LeaseWatch(threading.Thread):
    """Reads every lease record of the shared folder every 20 ms: a fencing token that ever
    goes down means two owners."""

    def __init__(self, shared):
        super().__init__(daemon=True)
        self.shared, self.tokens, self.regressions = shared, {}, []
        self.stopping = threading.Event()

    def run(self):
        while not self.stopping.is_set():
            for path in glob.glob(os.path.join(self.shared, "*.plx.lease")):
                try:
                    with open(path, encoding="utf-8") as f:
                        found = re.search(r"^token (\d+)$", f.read(), re.M)
                except FileNotFoundError:
                    continue
                if not found:
                    continue
                token, name = int(found.group(1)), os.path.basename(path)
                if token < self.tokens.get(name, 0):
                    self.regressions.append(f"{name}: {self.tokens[name]} -> {token}")
                self.tokens[name] = max(token, self.tokens.get(name, 0))
            time.sleep(0.02)


def routes(log_text):
    """{map: set of replicas} from HAProxy's log lines with a captured x-plenoxd-map."""
    out = {}
    for found in re.finditer(r"replicas/(r\d+) .*?\{([^}]*)\} \"POST", log_text):
        if found.group(2):
            out.setdefault(found.group(2), set()).add(found.group(1))
    return out


def holders(fleet, cli):
    """{map: [replica names listing it]} over the live replicas."""
    held = {}
    for r in fleet.live():
        for name in cli.maps(r.address):
            held.setdefault(name, []).append(r.name)
    return held


def read(path):
    with open(path, encoding="utf-8", errors="replace") as f:
        return f.read()


def scenario(fleet, cli, dataset, failures, numbers):
    for _ in range(3):
        fleet.add_replica()
    proxy = fleet.start_proxy()
    watch = LeaseWatch(fleet.shared)
    watch.start()

    print("1. maps through the proxy, one replica each", flush=True)
    for name in MAPS:
        cli.json(proxy, "map", "--dataset", dataset, "--name", name, "--every", "10",
                 "--voxel-size", "0.1", "--iterations-per-keyframe", "5", "--batch", "1024",
                 "--quiet")
    for name in MAPS:  # more calls naming each map
        cli.json(proxy, "save", "--map", name)
    held = holders(fleet, cli)
    owners = {name: held.get(name, ["?"])[0] for name in MAPS}
    check(failures, all(len(held.get(name, [])) == 1 for name in MAPS),
          f"every map is held by exactly one replica: {held}")
    check(failures, len(set(owners.values())) >= 2, f"the maps spread: {owners}")
    seen = routes(read(fleet.proxy_log))
    check(failures, all(seen.get(name) == {owners[name]} for name in MAPS),
          f"every call for a map reached its owner: {seen}")

    print("2. kill -9 of a map's owner", flush=True)
    target = MAPS[0]
    victim = next(r for r in fleet.replicas if r.name == owners[target])
    saved = wait_for(lambda: victim.metrics().get("plenoxd_unsaved_maps") == 0, 15)
    check(failures, saved, f"{victim.name}'s snapshots are on the shared folder")
    before = cli.maps(victim.address)[target]
    victim.kill()
    killed_at = time.monotonic()
    after = cli.json(proxy, "save", "--map", target)
    failover_s = time.monotonic() - killed_at
    numbers["failover_s"] = round(failover_s, 2)
    new_owner = [r.name for r in fleet.live() if target in cli.maps(r.address)]
    check(failures, failover_s <= FAILOVER_GOAL_S,
          f"first call for {target} answered {failover_s:.2f} s after the kill "
          f"(goal {FAILOVER_GOAL_S:g} s) by {new_owner}")
    check(failures, after["keyframes"] == before["keyframes"] and after["bricks"] > 0 and
          after["bricks"] == before["bricks"],
          f"it serves the snapshot: keyframes {after['keyframes']} (were "
          f"{before['keyframes']}), bricks {after['bricks']} (were {before['bricks']})")
    down = wait_for(lambda: fleet.server_states().get(victim.name, "").startswith("DOWN"), 5)
    check(failures, down, f"HAProxy's gRPC health check marks {victim.name} DOWN: "
                          f"{fleet.server_states()}")
    for name in MAPS:  # the rest of the dead replica's maps move too
        cli.json(proxy, "save", "--map", name)

    print("3. a fourth replica joins", flush=True)
    held = holders(fleet, cli)
    owners = {name: held[name][0] for name in MAPS if name in held}
    leases_before = {r.name: r.metrics()["plenoxd_leases_held"] for r in fleet.live()}
    newcomer = fleet.add_replica()
    fleet.reload_proxy()
    mark = len(read(fleet.proxy_log))
    reloaded_at = time.monotonic()
    call_s = {}
    for name in MAPS:
        start = time.monotonic()
        cli.json(proxy, "save", "--map", name)
        call_s[name] = time.monotonic() - start
    handoff_total_s = time.monotonic() - reloaded_at
    held = holders(fleet, cli)
    moved = sorted(name for name in MAPS if held.get(name) == [newcomer.name])
    check(failures, len(moved) >= 1, f"the newcomer took maps over: {moved}")
    check(failures, all(len(held.get(name, [])) == 1 for name in MAPS),
          f"every map is held by exactly one replica: {held}")
    numbers["handoff_s_max"] = round(max((call_s[m] for m in moved), default=0), 2)
    numbers["handoff_total_s"] = round(handoff_total_s, 2)
    numbers["moved"] = len(moved)
    metrics = {r.name: r.metrics() for r in fleet.live()}
    given = sum(m.get("plenoxd_handoffs_given_total", 0) for m in metrics.values())
    check(failures, given == len(moved) and
          metrics[newcomer.name].get("plenoxd_handoffs_taken_total") == len(moved),
          f"handoffs given {given:g}, taken by the newcomer "
          f"{metrics[newcomer.name].get('plenoxd_handoffs_taken_total')}")
    for old in {owners[m] for m in moved}:
        lost = sum(1 for m in moved if owners[m] == old)
        check(failures, metrics[old]["plenoxd_leases_held"] == leases_before[old] - lost,
              f"{old} released {lost} lease(s): held {leases_before[old]:g} -> "
              f"{metrics[old]['plenoxd_leases_held']:g}")
    check(failures, metrics[newcomer.name]["plenoxd_leases_held"] == len(moved),
          f"the newcomer holds {metrics[newcomer.name]['plenoxd_leases_held']:g} lease(s)")
    for name in MAPS:  # settled: one more call each, all to the holder
        cli.json(proxy, "save", "--map", name)
    seen = routes(read(fleet.proxy_log)[mark:])
    check(failures, all(seen.get(name) == {held[name][0]} for name in MAPS),
          f"after the reload each map's calls reach its holder: {seen}")

    print("4. one owner at a time", flush=True)
    watch.stopping.set()
    watch.join()
    fenced = sum(m.get("plenoxd_fenced_saves_refused_total", 0) for m in metrics.values())
    losses = sum(m.get("plenoxd_lease_losses_total", 0) for m in metrics.values())
    check(failures, fenced == 0 and losses == 0,
          f"no fenced save ({fenced:g}) and no lease lost ({losses:g})")
    check(failures, not watch.regressions and len(watch.tokens) == len(MAPS),
          f"fencing tokens only grew over {len(watch.tokens)} leases: "
          f"{watch.regressions or 'no regression'}")
    codes = fleet.stop()
    check(failures, all(code == 0 for code in codes.values()),
          f"the live replicas drained and stopped: {codes}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--plenoxd", required=True)
    parser.add_argument("--plenox", required=True)
    parser.add_argument("--keep", action="store_true", help="keep the work folder")
    args = parser.parse_args()
    haproxy = shutil.which("haproxy") or shutil.which("haproxy", path="/usr/sbin")
    if haproxy is None:
        print("SKIP: haproxy is not installed (bash scripts/install_deps.sh installs it)")
        return 77
    work = tempfile.mkdtemp(prefix="plx_fleet_")
    failures, numbers = [], {}
    started = time.monotonic()
    cli = Cli(args.plenox)
    dataset = os.path.join(work, "seq")
    subprocess.run([args.plenox, "synth", "--out", dataset, "--frames", "20", "--width", "96",
                    "--height", "72"], check=True, capture_output=True)
    fleet = Fleet(args.plenoxd, os.path.join(work, "fleet"), LEASE_S, SNAPSHOT_S,
                  ["--threads", "1", "--backend", "cpu"], haproxy=haproxy)
    try:
        scenario(fleet, cli, dataset, failures, numbers)
    except Exception as error:  # noqa: BLE001  (reported with the logs below)
        failures.append(f"{type(error).__name__}: {error}")
    finally:
        fleet.stop()
    numbers["wall_s"] = round(time.monotonic() - started, 1)
    print("fleet: " + json.dumps(numbers), flush=True)
    if failures:
        for r in fleet.replicas:
            print(f"--- {r.name} ---\n{r.log()[-3000:]}")
        print(f"--- haproxy ---\n{read(fleet.proxy_log)[-3000:]}")
        print("FAILED:\n  " + "\n  ".join(failures))
    if not args.keep:
        shutil.rmtree(work, ignore_errors=True)
    else:
        print(f"kept {work}")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
