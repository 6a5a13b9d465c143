# The two commands (see README.md):
#   make demo   set up, build the avp program, run the main job (a simulated episode of the
#               default scenario)
#   make test   set up, build, run every test
# Also: make python (the Python package: `.venv/bin/python -c "import avp"`, docs/python.md),
# make build (everything, tests included), make build-avp (the program only),
# make bench (benchmark programs, one JSON file each under bench-results/),
# make format, make fuzz, make sanitize (docs/limits.md, "Fuzzing and sanitizers").

BUILD_DIR  ?= build
BUILD_TYPE ?= Release
JOBS       ?= $(shell nproc)
DEMO_OUT   ?= out/demo
CMAKE_ARGS ?=
# The clang build of the fuzzers and the ASan + UBSan suites (cmake/AvpSanitizeBuild.cmake).
SAN_DIR    ?= $(BUILD_DIR)/sanitize
SAN_CMAKE_ARGS ?=
# make test fuzzes every target FUZZ_TEST_SECONDS; make fuzz FUZZ_SECONDS (FUZZ_TARGETS: some).
FUZZ_TEST_SECONDS ?= 15
FUZZ_SECONDS ?= 600
FUZZ_TARGETS ?=
# The suites make test runs under ASan + UBSan: the modules that read untrusted input. Less the
# integrator's four long scene comparisons (thread counts, carving against ray casting: 250 s
# under the sanitizers, most of the pass; they run in the normal build and in make sanitize).
SAN_TESTS  ?= avp_core_test avp_io_test avp_ros_msg_test avp_mapping_test avp_segmentation_service_test
SAN_TEST_FILTER ?= -IntegratorSceneTest.ThreadCountDoesNotChangeTheMap*:IntegratorSceneTest.ProjectiveCarvingEqualsRayCasting*
# make sanitize: every suite of the sanitizer build.
SAN_ALL_TESTS ?= avp_core_test avp_io_test avp_ros_msg_test avp_robot_test avp_sim_scene_test \
  avp_sim_render_test avp_mapping_test avp_segmentation_test avp_planning_test avp_pipeline_test \
  avp_eval_test avp_report_test avp_experiment_test avp_segmentation_service_test avp_zsl_text_test \
  avp_zsl_geometry_test avp_architecture_test avp_run_command_test avp_planner_contract_test \
  avp_episode_end_to_end_test avp_remote_segmenter_e2e_test avp_extending_examples_test \
  avp_scenario_start_pose_test

.PHONY: all setup configure build build-avp python test demo bench format check-format clean \
        sanitize-configure fuzz-build fuzz-test sanitize-test fuzz sanitize

all: build

setup:
	@./scripts/setup

configure: setup
	@if [ ! -f $(BUILD_DIR)/build.ninja ]; then \
	  cmake -S . -B $(BUILD_DIR) -G Ninja -DCMAKE_BUILD_TYPE=$(BUILD_TYPE) $(CMAKE_ARGS); \
	fi

build: configure
	@cmake --build $(BUILD_DIR) -j $(JOBS)

# Only the avp program and the libraries it links: what the demo runs (no test or benchmark
# program), so that a newcomer's first result does not wait for the ~150 test objects.
build-avp: configure
	@cmake --build $(BUILD_DIR) -j $(JOBS) --target avp

# Every test of the normal build (with the replay tests of the fuzz corpora), then each fuzzer
# briefly, then the suites of SAN_TESTS under ASan + UBSan.
test: build
	@ctest --test-dir $(BUILD_DIR) --output-on-failure -j $(JOBS) --no-tests=error
	@$(MAKE) --no-print-directory fuzz-test sanitize-test

sanitize-configure: setup
	@if [ ! -f $(SAN_DIR)/build.ninja ]; then \
	  cmake -C cmake/AvpSanitizeBuild.cmake -S . -B $(SAN_DIR) -G Ninja $(SAN_CMAKE_ARGS); \
	fi

fuzz-build: sanitize-configure
	@cmake --build $(SAN_DIR) -j $(JOBS) --target avp_fuzzers

fuzz-test: fuzz-build
	@FUZZ_JOBS=$(JOBS) ./fuzz/run_fuzzers.sh $(SAN_DIR) $(FUZZ_TEST_SECONDS)

# (make test SAN_TESTS= skips them.)
sanitize-test: sanitize-configure
	@if [ -n "$(strip $(SAN_TESTS))" ]; then \
	  cmake --build $(SAN_DIR) -j $(JOBS) --target $(SAN_TESTS) && \
	  FUZZ_JOBS=$(JOBS) SANITIZE_GTEST_FILTER='$(SAN_TEST_FILTER)' \
	    ./fuzz/run_sanitized_tests.sh $(SAN_DIR) $(SAN_TESTS); \
	fi

# Longer fuzzing (FUZZ_SECONDS per target, e.g. make fuzz FUZZ_SECONDS=3600 FUZZ_TARGETS=map_file).
fuzz: fuzz-build
	@FUZZ_JOBS=$(JOBS) ./fuzz/run_fuzzers.sh $(SAN_DIR) $(FUZZ_SECONDS) $(FUZZ_TARGETS)

# The nightly check: every suite under ASan + UBSan, and every fuzzer briefly.
sanitize: sanitize-configure
	@cmake --build $(SAN_DIR) -j $(JOBS) --target avp_fuzzers $(SAN_ALL_TESTS)
	@FUZZ_JOBS=$(JOBS) ./fuzz/run_sanitized_tests.sh $(SAN_DIR) $(SAN_ALL_TESTS)
	@FUZZ_JOBS=$(JOBS) ./fuzz/run_fuzzers.sh $(SAN_DIR) $(FUZZ_TEST_SECONDS)

# The Python package (python/, docs/python.md): built into $(BUILD_DIR)/python and put on the path
# of the virtual environment $(PYTHON_VENV) (Debian's python3, its numpy and matplotlib visible:
# --system-site-packages), so that `$(PYTHON_VENV)/bin/python -c "import avp"` works, offline.
PYTHON_VENV ?= .venv
python: configure
	@cmake --build $(BUILD_DIR) -j $(JOBS) --target avp_python
	@./scripts/python-venv $(PYTHON_VENV) $(BUILD_DIR)/python

demo: build-avp
	@./scripts/demo $(BUILD_DIR) $(DEMO_OUT)

# One JSON file of records per program under bench-results/ (docs/benchmarks.md). Pass options to
# the OctoMap comparison with BENCH_MAP_ARGS, e.g. make bench BENCH_MAP_ARGS=--quick
bench: build
	@BENCH_MAP_ARGS="$(BENCH_MAP_ARGS)" ./scripts/bench $(BUILD_DIR) bench-results

format:
	@git ls-files '*.h' '*.cpp' | xargs clang-format -i

check-format:
	@git ls-files '*.h' '*.cpp' | xargs clang-format --dry-run --Werror

clean:
	rm -rf $(BUILD_DIR)
