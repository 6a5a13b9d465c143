#!/usr/bin/env bash
# Runs libFuzzer targets for a bounded time each, from copies of their committed seed corpora
# (fuzz/corpus/<target>, fuzz/regressions/<target>), so the repository is never modified. Fails
# (exit 1) when any target reports a crash, a sanitizer error (ASan, UBSan, LeakSanitizer), a
# timeout, an out-of-memory or a failed property; the input that did it is kept under
# <build>/fuzz-artifacts/<target>/ and the log's tail is printed.
#
#   fuzz/run_fuzzers.sh BUILD_DIR SECONDS [TARGET...]
#
# BUILD_DIR: a build configured with cmake/AvpSanitizeBuild.cmake (its fuzz/avp_fuzz_<target>).
# SECONDS: fuzzing time per target. TARGET: map_file octomap_import scene_file image_codec
# tensor_codec infer_request bag (default: all). FUZZ_JOBS targets run at once (default 2);
# FUZZ_TIMEOUT (s per input, default 10), FUZZ_RSS_MB (default 2048) and FUZZ_ARGS (more
# libFuzzer flags) tune the run. Used by `make test` (briefly) and `make fuzz` (longer).
set -euo pipefail

if [ $# -lt 2 ]; then
  sed -n '2,15p' "$0" | sed 's/^# \{0,1\}//'
  exit 2
fi
build="$(cd "$1" && pwd)"
seconds="$2"
shift 2
fuzz_dir="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
  targets=(map_file octomap_import scene_file image_codec tensor_codec infer_request bag)
fi
jobs="${FUZZ_JOBS:-2}"
timeout_s="${FUZZ_TIMEOUT:-10}"
rss_mb="${FUZZ_RSS_MB:-2048}"

for t in "${targets[@]}"; do
  if [ ! -x "$build/fuzz/avp_fuzz_$t" ]; then
    echo "run_fuzzers: $build/fuzz/avp_fuzz_$t is missing (build the target avp_fuzzers)" >&2
    exit 2
  fi
done

work="$(mktemp -d "${TMPDIR:-/tmp}/avp-fuzz.XXXXXX")"
trap 'rm -rf "$work"' EXIT
artifacts="$build/fuzz-artifacts"
mkdir -p "$artifacts"

# Sanitizers: stop at the first report, with a stack; leaks are reported at exit.
export ASAN_OPTIONS="${ASAN_OPTIONS:-detect_leaks=1:abort_on_error=0:symbolize=1:detect_stack_use_after_return=1}"
# Stacks with function names and lines (llvm-14's symbolizer; Debian does not put it on PATH).
if [ -z "${ASAN_SYMBOLIZER_PATH:-}" ] && [ -x /usr/lib/llvm-14/bin/llvm-symbolizer ]; then
  export ASAN_SYMBOLIZER_PATH=/usr/lib/llvm-14/bin/llvm-symbolizer
fi
# Leaks inside third-party libraries that avp cannot free (each explained in fuzz/lsan.supp).
export LSAN_OPTIONS="${LSAN_OPTIONS:-suppressions=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)/lsan.supp:print_suppressions=0}"
export UBSAN_OPTIONS="${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1:silence_unsigned_overflow=1}"
export AVP_FUZZ_SECONDS="$seconds" AVP_FUZZ_BUILD="$build" AVP_FUZZ_SRC="$fuzz_dir" AVP_FUZZ_WORK="$work"
export AVP_FUZZ_ARTIFACTS="$artifacts" AVP_FUZZ_TIMEOUT="$timeout_s" AVP_FUZZ_RSS_MB="$rss_mb"
export AVP_FUZZ_ARGS="${FUZZ_ARGS:-}"

run_one() {
  local t="$1"
  local corpus="$AVP_FUZZ_WORK/corpus-$t" log="$AVP_FUZZ_WORK/$t.log"
  mkdir -p "$corpus" "$AVP_FUZZ_ARTIFACTS/$t" "$AVP_FUZZ_WORK/tmp-$t"
  # Seeds and past crashes, flattened (file names are unique per folder; regressions prefixed).
  find "$AVP_FUZZ_SRC/corpus/$t" -maxdepth 1 -type f ! -name '.*' -exec cp {} "$corpus/" \; 2>/dev/null || true
  if [ -d "$AVP_FUZZ_SRC/regressions/$t" ]; then
    for f in "$AVP_FUZZ_SRC/regressions/$t"/*; do
      [ -f "$f" ] && cp "$f" "$corpus/regression-$(basename "$f")"
    done
  fi
  local dict=()
  [ -f "$AVP_FUZZ_SRC/dict/$t.dict" ] && dict=("-dict=$AVP_FUZZ_SRC/dict/$t.dict")
  local start=$SECONDS rc=0
  # shellcheck disable=SC2086
  TMPDIR="$AVP_FUZZ_WORK/tmp-$t" "$AVP_FUZZ_BUILD/fuzz/avp_fuzz_$t" \
    -max_total_time="$AVP_FUZZ_SECONDS" -timeout="$AVP_FUZZ_TIMEOUT" \
    -rss_limit_mb="$AVP_FUZZ_RSS_MB" -max_len=65536 -print_final_stats=1 \
    -artifact_prefix="$AVP_FUZZ_ARTIFACTS/$t/" "${dict[@]}" $AVP_FUZZ_ARGS \
    "$corpus" >"$log" 2>&1 || rc=$?
  local runs
  runs="$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$' || echo '?')"
  if [ "$rc" -eq 0 ]; then
    echo "fuzz $t: ok, $runs inputs in $((SECONDS - start)) s, corpus $(ls "$corpus" | wc -l) files"
  else
    echo "fuzz $t: FAILED (exit $rc) after $((SECONDS - start)) s; the log's end:"
    grep -v '^#[0-9]' "$log" | tail -n 60 | sed "s|^|  [$t] |"
    echo "fuzz $t: the input is under $AVP_FUZZ_ARTIFACTS/$t/ (replay: $AVP_FUZZ_BUILD/fuzz/avp_fuzz_$t FILE);"
    echo "fuzz $t: once fixed, keep it as fuzz/regressions/$t/<what-it-is> (docs/limits.md)"
    return 1
  fi
}
export -f run_one

echo "run_fuzzers: ${#targets[@]} targets, ${seconds} s each, ${jobs} at a time (artifacts: $artifacts)"
if printf '%s\n' "${targets[@]}" | xargs -P "$jobs" -I{} bash -c 'run_one "$@"' _ {}; then
  echo "run_fuzzers: all ${#targets[@]} targets ran ${seconds} s without a finding"
else
  echo "run_fuzzers: a fuzz target failed (above)" >&2
  exit 1
fi
