#!/usr/bin/env bash
# Runs GoogleTest programs of a sanitizer build (cmake/AvpSanitizeBuild.cmake: clang,
# AddressSanitizer + UndefinedBehaviorSanitizer, LeakSanitizer at exit) and fails when any test
# fails or any sanitizer reports. Each program runs from its own build folder, as ctest would run
# it, FUZZ_JOBS (default 2) at a time; the log of a failed one is printed.
#
#   fuzz/run_sanitized_tests.sh BUILD_DIR TEST_PROGRAM...   (e.g. avp_core_test avp_io_test)
#
# Used by `make test` (the suites of the modules that read untrusted input) and
# `make sanitize` (every suite). ctest is not used: the sanitizer build has only some programs
# built, and ctest would list the others as failures. SANITIZE_GTEST_FILTER, when set, is passed
# to every program as --gtest_filter (make test leaves out a few long scene runs with it).
set -euo pipefail

if [ $# -lt 2 ]; then
  sed -n '2,12p' "$0" | sed 's/^# \{0,1\}//'
  exit 2
fi
build="$(cd "$1" && pwd)"
shift
src="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
work="$(mktemp -d "${TMPDIR:-/tmp}/avp-sanitize.XXXXXX")"
trap 'rm -rf "$work"' EXIT

export ASAN_OPTIONS="${ASAN_OPTIONS:-detect_leaks=1:symbolize=1:detect_stack_use_after_return=1:strict_string_checks=1}"
# Stacks with function names and lines (llvm-14's symbolizer; Debian does not put it on PATH).
if [ -z "${ASAN_SYMBOLIZER_PATH:-}" ] && [ -x /usr/lib/llvm-14/bin/llvm-symbolizer ]; then
  export ASAN_SYMBOLIZER_PATH=/usr/lib/llvm-14/bin/llvm-symbolizer
fi
# Leaks inside third-party libraries that avp cannot free (each explained in fuzz/lsan.supp).
export LSAN_OPTIONS="${LSAN_OPTIONS:-suppressions=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)/lsan.supp:print_suppressions=0}"
export UBSAN_OPTIONS="${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}"
export AVP_CONFIG_DIR="${AVP_CONFIG_DIR:-$src/configs}"
export AVP_SAN_BUILD="$build" AVP_SAN_WORK="$work" AVP_SAN_TIMEOUT="${SANITIZE_TIMEOUT:-1200}"
export AVP_SAN_FILTER="${SANITIZE_GTEST_FILTER:-}"

run_one() {
  local name="$1" exe
  exe="$(find "$AVP_SAN_BUILD" -path "$AVP_SAN_BUILD/_deps" -prune -o -type f -name "$name" -perm -u+x -print | head -n 1)"
  if [ -z "$exe" ]; then
    echo "sanitize $name: MISSING (not built in $AVP_SAN_BUILD)"
    return 1
  fi
  local log="$AVP_SAN_WORK/$name.log" start=$SECONDS rc=0
  local filter=()
  if [ -n "$AVP_SAN_FILTER" ]; then filter=("--gtest_filter=$AVP_SAN_FILTER"); fi
  (cd "$(dirname "$exe")" && timeout "$AVP_SAN_TIMEOUT" "$exe" --gtest_brief=1 "${filter[@]}") >"$log" 2>&1 || rc=$?
  if [ "$rc" -eq 0 ]; then
    echo "sanitize $name: ok ($(grep -o '[0-9]* tests\? from [0-9]* test suites\? ran' "$log" | head -n 1), $((SECONDS - start)) s)"
  else
    echo "sanitize $name: FAILED (exit $rc, $((SECONDS - start)) s); the log's end:"
    tail -n 80 "$log" | sed "s|^|  [$name] |"
    return 1
  fi
}
export -f run_one

echo "run_sanitized_tests: $# programs of $build"
if printf '%s\n' "$@" | xargs -P "${FUZZ_JOBS:-2}" -I{} bash -c 'run_one "$@"' _ {}; then
  echo "run_sanitized_tests: all $# programs passed under ASan + UBSan"
else
  echo "run_sanitized_tests: a program failed or a sanitizer reported (above)" >&2
  exit 1
fi
