#!/usr/bin/env bash
# Configures (once) and builds plenoxd in ./build (Release, Ninja).
#   scripts/build.sh            everything (the CUDA kernels too when nvcc is installed)
#   scripts/build.sh plenox     just the named targets
# Extra CMake options can be passed in $PLX_CMAKE_ARGS, e.g. "-DPLX_WITH_CUDA=OFF".
set -euo pipefail
cd "$(dirname "$0")/.."

launcher=()
if command -v ccache > /dev/null; then
  launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_CUDA_COMPILER_LAUNCHER=ccache)
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
