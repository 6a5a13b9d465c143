# Initial cache for the clang build of the fuzz targets and the ASan + UBSan unit tests
# (docs/limits.md, "Fuzzing and sanitizers"): cmake -C cmake/AvpSanitizeBuild.cmake -S . -B <dir>.
# `make test`, `make fuzz` and `make sanitize` configure $(BUILD_DIR)/sanitize with it.
#
# Every avp target gets -fsanitize=address,undefined (AVP_SANITIZE, cmake/AvpHelpers.cmake) and
# every translation unit gets libFuzzer's coverage instrumentation (fuzzer-no-link), so the
# libraries link into both the fuzzers (-fsanitize=fuzzer) and the GoogleTest suites. UB stops the
# program (-fno-sanitize-recover) so that a report fails the test. -O1 with line tables: quick to
# compile, stacks with file:line, asserts kept (no NDEBUG).
set(CMAKE_C_COMPILER clang CACHE STRING "")
set(CMAKE_CXX_COMPILER clang++ CACHE STRING "")
set(CMAKE_BUILD_TYPE Sanitize CACHE STRING "")
set(CMAKE_CXX_FLAGS_SANITIZE "-O1 -gline-tables-only" CACHE STRING "")
set(CMAKE_C_FLAGS_SANITIZE "-O1 -gline-tables-only" CACHE STRING "")
# clang warns about unused constants and unused private fields where GCC does not: kept as
# warnings, not errors, here (the GCC build, with -Werror, is the one that gates warnings).
set(CMAKE_CXX_FLAGS "-fsanitize=fuzzer-no-link -fno-sanitize-recover=undefined -fno-omit-frame-pointer -Wno-error=unused-const-variable -Wno-error=unused-private-field"
    CACHE STRING "")
set(AVP_SANITIZE "address,undefined" CACHE STRING "")
set(AVP_BUILD_FUZZERS ON CACHE BOOL "")
# Only what the fuzzers and the sanitized suites need.
set(AVP_BUILD_BENCHMARKS OFF CACHE BOOL "")
set(AVP_BUILD_APPS OFF CACHE BOOL "")
set(AVP_WITH_ONNX OFF CACHE BOOL "")
set(AVP_WITH_ROS2 OFF CACHE BOOL "")
