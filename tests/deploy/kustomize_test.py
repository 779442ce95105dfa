#!/usr/bin/python3
"""The Kubernetes manifests (deploy/k8s) render and keep the fleet's design (issue 24, part 4):

    /usr/bin/python3 tests/deploy/kustomize_test.py

Renders `kubectl kustomize deploy/k8s` and checks: one ReadWriteMany claim mounted by the
plenoxd pods at their --shared-dir, with --lease-seconds and --snapshot-seconds; gRPC
readiness and liveness probes on the port plenoxd listens on; Envoy hashing on the header the
clients send (x-plenoxd-map, as HAProxy does in deploy/haproxy) over a ring of HTTP/2
endpoints, with gRPC health checks. Nothing is applied: no cluster is needed.
Exits 0 when everything passed, 1 with the failures, 77 (skip) without kubectl or PyYAML.
"""

import os
import shutil
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
HASH_HEADER = "x-plenoxd-map"

try:
    import yaml
except ImportError:
    print("SKIP: no PyYAML for /usr/bin/python3 (Debian's python3-yaml; "
          "bash scripts/install_deps.sh installs it)")
    sys.exit(77)


def check(failures, condition, what):
    print(f"  [{'ok  ' if condition else 'FAIL'}] {what}", flush=True)
    if not condition:
        failures.append(what)
    return condition


def flag(args, name):
    """The value after `name` in a container's args, or None."""
    return args[args.index(name) + 1] if name in args and args.index(name) + 1 < len(args) \
        else None


def check_plenoxd(docs, failures):
    claims = [d for d in docs if d["kind"] == "PersistentVolumeClaim"]
    shared = [c for c in claims if "ReadWriteMany" in c["spec"].get("accessModes", [])]
    names = [c["metadata"]["name"] for c in claims]
    check(failures, len(shared) == 1, f"one ReadWriteMany claim among {names}")
    sets = [d for d in docs if d["kind"] == "StatefulSet" and d["metadata"]["name"] == "plenoxd"]
    if not check(failures, len(sets) == 1, "the plenoxd StatefulSet"):
        return
    pod = sets[0]["spec"]["template"]["spec"]
    check(failures, not sets[0]["spec"].get("volumeClaimTemplates"),
          "no per-pod volume: maps are shared")
    container = next(c for c in pod["containers"] if c["name"] == "plenoxd")
    args = container["args"]
    volumes = {v["name"]: v for v in pod.get("volumes", [])}
    claim = shared[0]["metadata"]["name"] if shared else None
    mounts = [m["mountPath"] for m in container.get("volumeMounts", [])
              if volumes.get(m["name"], {}).get("persistentVolumeClaim", {}).get("claimName")
              == claim]
    shared_dir = flag(args, "--shared-dir")
    check(failures, shared_dir is not None and mounts == [shared_dir],
          f"--shared-dir {shared_dir} is where the claim is mounted ({mounts})")
    check(failures, "--data-dir" not in args, "no --data-dir beside it")
    for name in ("--lease-seconds", "--snapshot-seconds"):
        value = flag(args, name)
        check(failures, value is not None and float(value) > 0, f"{name} {value}")
    listen_port = int(flag(args, "--listen").rsplit(":", 1)[1])
    for probe in ("readinessProbe", "livenessProbe"):
        grpc = container.get(probe, {}).get("grpc", {})
        check(failures, grpc.get("port") == listen_port,
              f"{probe}: gRPC health on port {grpc.get('port')} (plenoxd listens on "
              f"{listen_port})")


def check_envoy(docs, failures):
    maps = [d for d in docs if d["kind"] == "ConfigMap" and "envoy.yaml" in d.get("data", {})]
    if not check(failures, len(maps) == 1, "Envoy's config map"):
        return
    envoy = yaml.safe_load(maps[0]["data"]["envoy.yaml"])
    resources = envoy["static_resources"]
    routes = [route for listener in resources["listeners"]
              for chain in listener["filter_chains"] for f in chain["filters"]
              for host in f["typed_config"]["route_config"]["virtual_hosts"]
              for route in host["routes"]]
    headers = [h["header"]["header_name"] for r in routes
               for h in r["route"].get("hash_policy", []) if "header" in h]
    check(failures, headers == [HASH_HEADER] * len(routes) and routes,
          f"every route hashes on {HASH_HEADER}: {headers}")
    cluster = next(c for c in resources["clusters"] if c["name"] == "plenoxd")
    check(failures, cluster["lb_policy"] == "RING_HASH", f"lb_policy {cluster['lb_policy']}")
    checks = cluster.get("health_checks", [])
    check(failures, any("grpc_health_check" in c for c in checks),
          "gRPC health checks on the endpoints")
    options = cluster.get("typed_extension_protocol_options", {})
    check(failures, "http2_protocol_options" in str(options), "HTTP/2 to the pods")


def main():
    kubectl = shutil.which("kubectl")
    if kubectl is None:
        print("SKIP: kubectl is not installed (Debian's kubernetes-client; "
              "bash scripts/install_deps.sh installs it)")
        return 77
    rendered = subprocess.run([kubectl, "kustomize", os.path.join(ROOT, "deploy", "k8s")],
                              capture_output=True, text=True, timeout=60)
    failures = []
    if not check(failures, rendered.returncode == 0,
                 f"kubectl kustomize deploy/k8s renders: {rendered.stderr.strip() or 'yes'}"):
        return 1
    docs = [d for d in yaml.safe_load_all(rendered.stdout) if d]
    check_plenoxd(docs, failures)
    check_envoy(docs, failures)
    with open(os.path.join(ROOT, "deploy", "haproxy", "haproxy.cfg.template"),
              encoding="utf-8") as f:
        haproxy = f.read()
    check(failures,
          f"balance hdr({HASH_HEADER})" in haproxy and "hash-type consistent" in haproxy,
          f"HAProxy hashes on the same header ({HASH_HEADER}), consistently")
    if failures:
        print("FAILED:\n  " + "\n  ".join(failures))
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
