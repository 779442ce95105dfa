#!/usr/bin/env bash
# Installs dependencies, builds everything and runs the whole test suite (what CI runs).
#   scripts/test.sh          the suite (Release build in ./build)
#   scripts/test.sh --tsan   ThreadSanitizer build of the core tests in ./build-tsan (CPU only),
#                            then those tests: the shared map versions, mapping sessions and
#                            readers, the thread pool. The daemon's tests are not part of it:
#                            Debian's gRPC is not built with TSan, and its inlined reactor code
#                            racing with its uninstrumented library reports false positives.
#   scripts/test.sh --asan   AddressSanitizer + UndefinedBehaviorSanitizer build (gcc) of the
#                            core, app, proto and daemon tests in ./build-asan (CPU only), then
#                            those tests; the first report fails its test. ASan, unlike TSan,
#                            needs nothing from Debian's gRPC: uninstrumented libraries only go
#                            unchecked, they cause no false reports.
set -euo pipefail
cd "$(dirname "$0")/.."
if [[ "${1:-}" == "--asan" ]]; then
  bash scripts/install_deps.sh
  export CCACHE_BASEDIR="${CCACHE_BASEDIR:-$PWD}"  # see scripts/build.sh
  export CCACHE_SLOPPINESS="${CCACHE_SLOPPINESS:-pch_defines,time_macros}"
  if [[ ! -f build-asan/build.ninja ]]; then
    # -fno-sanitize-recover: a UBSan report aborts like an ASan one instead of only printing.
    flags="-fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=all"
    cmake -S . -B build-asan -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DPLX_WITH_CUDA=OFF \
      -DPLX_BUILD_BENCH=OFF -DCMAKE_CXX_FLAGS="$flags" \
      -DCMAKE_EXE_LINKER_FLAGS="-fsanitize=address,undefined" \
      $(command -v ccache > /dev/null && echo -DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
  fi
  targets=(plx_core_tests plx_app_tests)
  # The daemon's tests and the proto codec exist only in builds with gRPC.
  if grep -q "^PLX_WITH_SERVER:BOOL=ON" build-asan/CMakeCache.txt; then
    targets+=(plx_proto_tests plx_server_tests)
  fi
  cmake --build build-asan --target "${targets[@]}"
  export ASAN_OPTIONS="halt_on_error=1:abort_on_error=1:detect_leaks=1:strict_string_checks=1 ${ASAN_OPTIONS:-}"
  export UBSAN_OPTIONS="halt_on_error=1:print_stacktrace=1 ${UBSAN_OPTIONS:-}"
  pattern=$(IFS='|'; echo "${targets[*]}")
  ctest --test-dir build-asan --output-on-failure -j2 -R "^($pattern)_shard"
  exit 0
fi
if [[ "${1:-}" == "--tsan" ]]; then
  bash scripts/install_deps.sh
  export CCACHE_BASEDIR="${CCACHE_BASEDIR:-$PWD}"  # see scripts/build.sh
  export CCACHE_SLOPPINESS="${CCACHE_SLOPPINESS:-pch_defines,time_macros}"
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
