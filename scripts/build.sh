#!/usr/bin/env bash
# Configures (once) and builds plenoxd in ./build (Release, Ninja).
#   scripts/build.sh            everything (the CUDA kernels too when nvcc is installed)
#   scripts/build.sh plenox     just the named targets
#   scripts/build.sh python-wheel
#                               the Python client's wheel, for other machines (CMake target
#                               plx_python_wheel; `all` builds it too), and where it is
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
  # The test binaries' precompiled headers (tests/CMakeLists.txt): without these, ccache
  # compiles every file that uses one instead of caching it.
  export CCACHE_SLOPPINESS="${CCACHE_SLOPPINESS:-pch_defines,time_macros}"
fi
if [[ "${PLX_CMAKE_ARGS:-}" != *PLX_CUDA_ARCHITECTURES* ]]; then
  PLX_CMAKE_ARGS="${PLX_CMAKE_ARGS:-} -DPLX_CUDA_ARCHITECTURES=86"
fi
if [[ ! -f build/build.ninja ]]; then
  # shellcheck disable=SC2086
  cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release "${launcher[@]}" ${PLX_CMAKE_ARGS:-}
fi
targets=()
wheel=0
for target in "$@"; do
  if [[ "$target" == python-wheel ]]; then
    target=plx_python_wheel
    wheel=1
    # Defined only with the daemon (gRPC) and a Python that can build it (CMake says which).
    if ! grep -q "plx_python_wheel" build/build.ninja; then
      echo "build.sh: no target plx_python_wheel; see 'Python client' in CMake's output" \
           "(cmake -S . -B build)" >&2
      exit 1
    fi
  fi
  targets+=("$target")
done
if (( ${#targets[@]} > 0 )); then
  cmake --build build --target "${targets[@]}"
else
  cmake --build build
fi
if (( wheel )); then
  version=$(sed -n 's/^CMAKE_PROJECT_VERSION:STATIC=//p' build/CMakeCache.txt)
  echo "$PWD/build/clients/python/dist/plenoxd_client-$version-py3-none-any.whl"
fi
