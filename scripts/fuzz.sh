#!/usr/bin/env bash
# Builds the libFuzzer harnesses (fuzz/) with clang, ASan and UBSan in ./build-fuzz and runs each
# for a set time on a copy of its seed corpus.
#   scripts/fuzz.sh [SECONDS] [HARNESS...]  each harness (default: all) for SECONDS (default 60)
#   scripts/fuzz.sh --runs N [HARNESS...]   each harness for exactly N inputs from a fixed seed
#                                           (repeatable: CI's short run, .ci/run)
#   scripts/fuzz.sh --seeds                 rewrite fuzz/corpus/*/ seeds with the project's writers
# Fails (exit 1) when a harness crashes (a sanitizer report, a PLX_FUZZ_CHECK, a timeout or
# running out of memory) and prints where libFuzzer saved the input and how to replay it.
# Scratch files go to /dev/shm (else build-fuzz/tmp) and are removed after each harness.
# What a run found stays in build-fuzz/corpus/<harness>/ and is fuzzed from again next time;
# fuzz/corpus/ in the repository only changes by hand (a seed, or a fixed crash's reproducer).
# Needs clang and its runtimes (scripts/install_deps.sh --fuzz, which this script runs).
set -euo pipefail
cd "$(dirname "$0")/.."

harnesses_all=(fuzz_image fuzz_frame_proto fuzz_map_file fuzz_text_files fuzz_tum_lists
               fuzz_http_request)
seeds=0
seconds=60
runs=0
if [[ "${1:-}" == "--seeds" ]]; then
  seeds=1
  shift
elif [[ "${1:-}" == "--runs" ]]; then
  [[ "${2:-}" =~ ^[0-9]+$ ]] || { echo "fuzz: --runs needs a count" >&2; exit 2; }
  runs=$2
  shift 2
elif [[ "${1:-}" =~ ^[0-9]+$ ]]; then
  seconds=$1
  shift
fi
harnesses=("$@")
(( ${#harnesses[@]} > 0 )) || harnesses=("${harnesses_all[@]}")

bash scripts/install_deps.sh --fuzz
if [[ ! -f build-fuzz/build.ninja ]]; then
  launcher=()
  if command -v ccache > /dev/null; then
    launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
    export CCACHE_BASEDIR="${CCACHE_BASEDIR:-$PWD}"  # see scripts/build.sh
  fi
  # Only what the harnesses link is built (the plx_fuzzers target), not the tests or programs.
  cmake -S . -B build-fuzz -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DCMAKE_CXX_COMPILER=clang++ -DPLX_FUZZ=ON -DPLX_WITH_CUDA=OFF -DPLX_BUILD_TESTS=OFF \
    -DPLX_BUILD_BENCH=OFF "${launcher[@]}"
fi

if (( seeds )); then
  cmake --build build-fuzz --target plx_fuzz_seeds
  ./build-fuzz/fuzz/plx_fuzz_seeds fuzz/corpus
  echo "fuzz: seeds written to fuzz/corpus/"
  exit 0
fi
cmake --build build-fuzz --target "${harnesses[@]}"

# A UBSan report is fatal (-fno-sanitize-recover) and symbolised; leaks are reported too.
export ASAN_OPTIONS="${ASAN_OPTIONS:-abort_on_error=1:detect_leaks=1}"
export UBSAN_OPTIONS="${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}"
failed=()
for h in "${harnesses[@]}"; do
  work=build-fuzz/corpus/$h artifacts=build-fuzz/artifacts/$h/ tmp=build-fuzz/tmp/$h
  # Harnesses write their input to a file on every run, and the map harness fsyncs a save: on
  # tmpfs that is five times faster than on disk.
  if [[ -d /dev/shm && -w /dev/shm ]]; then tmp=/dev/shm/plx_fuzz_$$_$h; fi
  log=build-fuzz/logs/$h.log
  mkdir -p "$work" "$artifacts" "$tmp" "$(dirname "$log")"
  # A time limit explores more on a fast machine; a run count from a fixed seed does the same
  # work on every machine, so CI's result does not depend on its speed.
  if (( runs > 0 )); then
    budget=(-runs="$runs" -seed=1)
    echo "fuzz: $h for $runs inputs (log: $log)"
  else
    budget=(-max_total_time="$seconds")
    echo "fuzz: $h for ${seconds}s (log: $log)"
  fi
  # The first corpus folder receives new inputs; the repository's seeds are only read.
  # -timeout: one input may take 10 s; -rss_limit_mb: what a decoder may hold for one input;
  # -close_fd_mask=2: the harnesses' own stderr is dropped (libpng prints a line for every
  # corrupt image, gigabytes in ten minutes); libFuzzer's output and sanitizer reports, which
  # PLX_FUZZ_CHECK messages also use, still reach the log.
  status=0
  [[ "$tmp" == /* ]] || tmp=$PWD/$tmp
  TMPDIR=$tmp "./build-fuzz/fuzz/$h" "$work" "fuzz/corpus/$h" "${budget[@]}" \
    -timeout=10 -rss_limit_mb=2048 -close_fd_mask=2 -print_final_stats=1 \
    -artifact_prefix="$artifacts" \
    > "$log" 2>&1 || status=$?
  rm -rf "$tmp"
  # The last status line: "#N DONE cov: C ft: F corp: U/S lim: L exec/s: E rss: R".
  summary=$(grep -E '^#[0-9]+[[:space:]]+(DONE|pulse|NEW|REDUCE|INITED)' "$log" | tail -n 1 || true)
  echo "fuzz: $h: ${summary:-no status line}"
  if (( status != 0 )); then
    failed+=("$h")
    artifact=$(grep -oE "Test unit written to [^ ]+" "$log" | tail -n 1 | cut -d' ' -f5 || true)
    grep -E "ERROR: |PLX_FUZZ_CHECK|SUMMARY:|runtime error" "$log" | head -n 5 || true
    echo "fuzz: $h FAILED (exit $status); reproducer: ${artifact:-none written, see $log}"
    if [[ -n "$artifact" ]]; then echo "fuzz: replay with ./build-fuzz/fuzz/$h $artifact"; fi
  fi
done
if (( ${#failed[@]} > 0 )); then
  echo "fuzz: ${#failed[@]} harness(es) failed: ${failed[*]}"
  exit 1
fi
if (( runs > 0 )); then
  echo "fuzz: ${#harnesses[@]} harness(es) ran $runs inputs each without a crash"
else
  echo "fuzz: ${#harnesses[@]} harness(es) ran ${seconds}s each without a crash"
fi
