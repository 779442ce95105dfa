#!/usr/bin/env bash
# Installs dependencies, builds everything and runs the whole test suite (what CI runs).
#   scripts/test.sh          the suite (Release build in ./build)
#   scripts/test.sh --tsan   ThreadSanitizer build of the core tests in ./build-tsan (CPU only),
#                            then those tests: the shared map versions, mapping sessions and
#                            readers, the thread pool. The daemon's tests are not part of it:
#                            Debian's gRPC is not built with TSan, and its inlined reactor code
#                            racing with its uninstrumented library reports false positives.
set -euo pipefail
cd "$(dirname "$0")/.."
if [[ "${1:-}" == "--tsan" ]]; then
  bash scripts/install_deps.sh
  export CCACHE_BASEDIR="${CCACHE_BASEDIR:-$PWD}"  # see scripts/build.sh
  if [[ ! -f build-tsan/build.ninja ]]; then
    cmake -S . -B build-tsan -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DPLX_WITH_CUDA=OFF \
      -DPLX_BUILD_BENCH=OFF -DCMAKE_CXX_FLAGS="-fsanitize=thread" \
      -DCMAKE_EXE_LINKER_FLAGS="-fsanitize=thread" \
      $(command -v ccache > /dev/null && echo -DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
  fi
  cmake --build build-tsan --target plx_core_tests
  # halt_on_error: a report fails the test; second_deadlock_stack: readable lock reports.
  export TSAN_OPTIONS="halt_on_error=1 second_deadlock_stack=1 suppressions=$PWD/tests/tsan.supp ${TSAN_OPTIONS:-}"
  ctest --test-dir build-tsan --output-on-failure -j2 -R "plx_core_tests"
  exit 0
fi
bash scripts/install_deps.sh
# One CUDA architecture keeps CI's nvcc time small (the CMake default builds five); the kernels
# only need to compile here, no machine in CI has a GPU.
if [[ "${PLX_CMAKE_ARGS:-}" != *PLX_CUDA_ARCHITECTURES* ]]; then
  export PLX_CMAKE_ARGS="${PLX_CMAKE_ARGS:-} -DPLX_CUDA_ARCHITECTURES=86"
fi
bash scripts/build.sh
ctest --test-dir build --output-on-failure -j2
