#!/usr/bin/env bash
# Installs dependencies, builds everything and runs the whole test suite (what CI runs).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install_deps.sh
# One CUDA architecture keeps CI's nvcc time small (the CMake default builds five); the kernels
# only need to compile here, no machine in CI has a GPU.
if [[ "${PLX_CMAKE_ARGS:-}" != *PLX_CUDA_ARCHITECTURES* ]]; then
  export PLX_CMAKE_ARGS="${PLX_CMAKE_ARGS:-} -DPLX_CUDA_ARCHITECTURES=86"
fi
bash scripts/build.sh
ctest --test-dir build --output-on-failure -j2
