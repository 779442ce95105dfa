#!/usr/bin/env bash
# Configures (once) and builds plenoxd in ./build (Release, Ninja).
#   scripts/build.sh            everything (the CUDA kernels too when nvcc is installed)
#   scripts/build.sh plenox     just the named targets
# Extra CMake options can be passed in $PLX_CMAKE_ARGS, e.g. "-DPLX_WITH_CUDA=OFF". CUDA kernels
# are built for one architecture (sm_86) unless PLX_CMAKE_ARGS names PLX_CUDA_ARCHITECTURES
# (release builds: the CMake default list; a GPU machine: bench/gpu.sh uses the GPU's own).
set -euo pipefail
cd "$(dirname "$0")/.."

launcher=()
if command -v ccache > /dev/null; then
  launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_CUDA_COMPILER_LAUNCHER=ccache)
  # Paths relative to the checkout, so every clone of the project (CI's, a worktree) shares
  # cache entries.
  export CCACHE_BASEDIR="${CCACHE_BASEDIR:-$PWD}"
fi
if [[ "${PLX_CMAKE_ARGS:-}" != *PLX_CUDA_ARCHITECTURES* ]]; then
  PLX_CMAKE_ARGS="${PLX_CMAKE_ARGS:-} -DPLX_CUDA_ARCHITECTURES=86"
fi
if [[ ! -f build/build.ninja ]]; then
  # shellcheck disable=SC2086
  cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release "${launcher[@]}" ${PLX_CMAKE_ARGS:-}
fi
if (( $# > 0 )); then
  cmake --build build --target "$@"
else
  cmake --build build
fi
