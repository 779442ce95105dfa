#!/usr/bin/env bash
# Installs the Debian 12 packages plenoxd builds and tests with (run as root).
#   scripts/install_deps.sh          build + test dependencies
#   scripts/install_deps.sh --bench  also the benchmark's peer (Open3D) and Python packages
#   scripts/install_deps.sh --fuzz   also clang, its sanitizer and libFuzzer runtimes and
#                                    llvm-symbolizer (scripts/fuzz.sh, scripts/test.sh --asan)
# Packages already present are not fetched again, so a second run takes seconds.
set -euo pipefail

packages=(cmake ninja-build g++ pkg-config ccache
          # libpng-dev: PNG frames are decoded with libpng itself (core/io/png_decode.h).
          libeigen3-dev libopencv-dev libpng-dev libabsl-dev libgtest-dev libgmock-dev libbenchmark-dev
          # The daemon (gRPC + Protobuf, health/reflection protos) and the Python client.
          libgrpc++-dev libgrpc-dev protobuf-compiler-grpc libprotobuf-dev protobuf-compiler
          grpc-proto python3-grpcio python3-grpc-tools python3-protobuf python3-numpy
          # The Python client as a package: pip builds and installs it offline
          # (--no-build-isolation: setuptools and wheel from here) into venvs that see the
          # packages above.
          python3-pip python3-setuptools python3-wheel python3-venv
          # The daemon's metrics HTTP server; OpenSSL to check TLS files before serving.
          libssl-dev
          # Loop closure: the pose graph is solved with Ceres (core/slam/pose_graph.h).
          libceres-dev
          # Meshes as binary glTF (tinygltf; nlohmann's JSON reads a GLB's JSON chunk back) and
          # their levels of detail (meshoptimizer): core/formats/glb_mesh.h,
          # core/mesh/mesh_simplify.h.
          libtinygltf-dev nlohmann-json3-dev libmeshoptimizer-dev
          # The web viewer (plenoxd --viewer, plenox view) runs on Debian's three.js; its
          # browser test loads the page in headless Chromium (WebGL on SwiftShader).
          libjs-three chromium
          # The fleet on one machine (scripts/fleet.py, tests/deploy/fleet_test.py): three
          # replicas behind an HTTP/2 proxy hashing calls on x-plenoxd-map.
          haproxy
          # The Kubernetes manifests' render check (tests/deploy/kustomize_test.py) reads them
          # with PyYAML.
          python3-yaml)
# ... and renders them with kubectl kustomize: Debian's kubernetes-client (kubectl 1.20, whose
# built-in kustomize renders deploy/k8s), unless a kubectl is installed already (another
# vendor's package, e.g. Google Cloud's, owns /usr/bin/kubectl and would conflict).
if ! command -v kubectl > /dev/null; then
  packages+=(kubernetes-client)
fi
if [[ "${1:-}" == "--bench" ]]; then
  packages+=(python3-open3d python3-numpy python3-opencv)
fi
if [[ "${1:-}" == "--fuzz" ]]; then
  # libclang-rt-14-dev holds libFuzzer and the ASan/UBSan runtimes; llvm, llvm-symbolizer,
  # which turns sanitizer reports' addresses into file:line.
  packages+=(clang libclang-rt-14-dev llvm)
fi

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if (( ${#missing[@]} == 0 )); then
  echo "install_deps: all ${#packages[@]} packages present"
  exit 0
fi
if [[ $(id -u) -ne 0 ]]; then
  echo "install_deps: run as root (or with sudo) to install: ${missing[*]}" >&2
  exit 1
fi
echo "install_deps: installing ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
apt-get update -qq
apt-get install -y -qq --no-install-recommends "${missing[@]}" > /dev/null
echo "install_deps: done"
