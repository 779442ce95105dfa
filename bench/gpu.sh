#!/usr/bin/env bash
# Build, test and benchmark the CUDA backend on a machine with an NVIDIA GPU, in one command:
#
#   bench/gpu.sh                 everything: build, tests, mapping + tracking benchmarks
#   bench/gpu.sh --no-bench      build and tests only
#   bench/gpu.sh --no-tests      build and benchmarks only
#   bench/gpu.sh --quick         benchmarks on the synthetic sequence only (no ../shared/data)
#
# Environment:
#   PLX_GPU=N            the GPU to use (default 0; nvidia-smi index, also sets CUDA_VISIBLE_DEVICES)
#   PLX_GPU_BUILD=DIR    build directory (default build-gpu in the repo)
#   PLX_CMAKE_ARGS="..." extra CMake options
#   PLX_BENCH_ARGS="..." extra options for bench/map_bench.py and bench/track_bench.py
#                        (e.g. "--sequences tum_fr3_teddy --time-budget 60")
#   JOBS=N               build parallelism (default: all cores)
#
# Needs: nvidia-smi and a working driver, nvcc (CUDA 12.x/13.x; /usr/local/cuda/bin is searched),
# cmake >= 3.25, ninja, and the build dependencies of scripts/install_deps.sh. It configures a
# Release build for the GPU's own architecture (nvidia-smi --query-gpu=compute_cap), runs the
# whole test suite (the CUDA test instances must then run: a skipped one fails this script),
# then runs bench/map_bench.py and bench/track_bench.py with `plenox ... --backend=cuda`.
# Results (logs, markdown tables, nvidia-smi report) go to bench/results/gpu-<date>-<host>/;
# the last line printed says where.
set -euo pipefail
cd "$(dirname "$0")/.."
repo=$(pwd)

run_tests=1 run_bench=1 quick=0
for arg in "$@"; do
  case "$arg" in
    --no-tests) run_tests=0 ;;
    --no-bench) run_bench=0 ;;
    --quick) quick=1 ;;
    -h|--help) sed -n '2,24p' "$0"; exit 0 ;;
    *) echo "gpu.sh: unknown option $arg (see --help)" >&2; exit 2 ;;
  esac
done

die() { echo "gpu.sh: $*" >&2; exit 1; }

# 1. The GPU, its driver and the compiler.
command -v nvidia-smi > /dev/null || die "nvidia-smi not found: install the NVIDIA driver"
gpu=${PLX_GPU:-0}
nvidia-smi -i "$gpu" > /dev/null 2>&1 || die "nvidia-smi cannot see GPU $gpu (driver not loaded?)"
cap=$(nvidia-smi -i "$gpu" --query-gpu=compute_cap --format=csv,noheader | head -n1 | tr -d ' .')
[[ "$cap" =~ ^[0-9]+$ ]] || die "could not read the compute capability of GPU $gpu (got '$cap')"
gpu_name=$(nvidia-smi -i "$gpu" --query-gpu=name --format=csv,noheader | head -n1)
if ! command -v nvcc > /dev/null; then
  [[ -x /usr/local/cuda/bin/nvcc ]] || die "nvcc not found: install the CUDA toolkit"
  export PATH=/usr/local/cuda/bin:$PATH
fi
export CUDA_VISIBLE_DEVICES=$gpu  # the tests and benchmarks use CUDA device 0 = this GPU

stamp=$(date +%Y%m%d-%H%M%S)
results="$repo/bench/results/gpu-$stamp-$(hostname -s 2>/dev/null || echo host)"
mkdir -p "$results"
nvidia-smi -i "$gpu" > "$results/nvidia-smi.txt" 2>&1 || true
nvcc --version > "$results/nvcc.txt" 2>&1 || true
git -C "$repo" rev-parse HEAD > "$results/commit.txt" 2>/dev/null || true
echo "gpu.sh: GPU $gpu: $gpu_name (sm_$cap), $(nvcc --version | tail -n1)"

# 2. Release build for this GPU's architecture only.
build=${PLX_GPU_BUILD:-$repo/build-gpu}
launcher=()
if command -v ccache > /dev/null; then
  launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_CUDA_COMPILER_LAUNCHER=ccache)
fi
echo "gpu.sh: building in $build (log: $results/build.log)"
# shellcheck disable=SC2086
cmake -S "$repo" -B "$build" -G Ninja -DCMAKE_BUILD_TYPE=Release -DPLX_WITH_CUDA=ON \
  -DPLX_CUDA_ARCHITECTURES="$cap" -DPLX_BUILD_TESTS=ON "${launcher[@]}" ${PLX_CMAKE_ARGS:-} \
  > "$results/build.log" 2>&1 || { tail -n 40 "$results/build.log"; die "configure failed"; }
cmake --build "$build" -j "${JOBS:-$(nproc)}" >> "$results/build.log" 2>&1 ||
  { tail -n 40 "$results/build.log"; die "build failed"; }

status=0
# 3. Tests. With a GPU the CUDA instances must run: any skip in the backend tests is a failure.
if (( run_tests )); then
  echo "gpu.sh: CUDA backend tests (log: $results/backend_tests.log)"
  if ! "$build/tests/plx_backend_tests" > "$results/backend_tests.log" 2>&1; then
    tail -n 40 "$results/backend_tests.log"; echo "gpu.sh: backend tests FAILED" >&2; status=1
  fi
  if grep -q '^\[  SKIPPED \]' "$results/backend_tests.log"; then
    grep '^\[  SKIPPED \]\|no CUDA device' "$results/backend_tests.log" | head -n 20
    echo "gpu.sh: CUDA tests were skipped although a GPU is present" >&2; status=1
  fi
  echo "gpu.sh: whole test suite (log: $results/ctest.log)"
  if ! ctest --test-dir "$build" --output-on-failure -j "${JOBS:-$(nproc)}" \
      > "$results/ctest.log" 2>&1; then
    tail -n 60 "$results/ctest.log"; echo "gpu.sh: ctest FAILED" >&2; status=1
  fi
  tail -n 3 "$results/ctest.log"
fi

# 4. Benchmarks on the CUDA backend (plenox map/eval-map/track --backend=cuda).
if (( run_bench )); then
  py=python3
  [[ -x /usr/bin/python3 ]] && py=/usr/bin/python3  # Debian's, which sees python3-open3d
  bench_args=(--plenox "$build/clients/plenox/plenox" --plenox-arg=--backend=cuda --synthetic)
  # --quick: a data folder with no sequences, so only the synthetic one runs.
  if (( quick )); then mkdir -p "$results/no-data"; bench_args+=(--data "$results/no-data"); fi
  # shellcheck disable=SC2206
  extra=(${PLX_BENCH_ARGS:-})
  for b in map track; do
    echo "gpu.sh: ${b} benchmark (log: $results/${b}_bench.log)"
    if ! OMP_WAIT_POLICY=passive "$py" "$repo/bench/${b}_bench.py" "${bench_args[@]}" \
        "${extra[@]}" --out "$results/${b}_bench.md" > "$results/${b}_bench.log" 2>&1; then
      tail -n 20 "$results/${b}_bench.log"; echo "gpu.sh: ${b} benchmark FAILED" >&2; status=1
    fi
    [[ -f "$results/${b}_bench.md" ]] && cat "$results/${b}_bench.md"
  done
fi

echo "gpu.sh: results in $results"
exit "$status"
