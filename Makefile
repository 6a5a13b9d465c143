# The two commands (see README.md):
#   make demo   set up, build, run the main job (a simulated view of the default scenario)
#   make test   set up, build, run every test
# Also: make build, make bench (benchmark programs, one JSON file each under bench-results/),
# make format.

BUILD_DIR  ?= build
BUILD_TYPE ?= Release
JOBS       ?= $(shell nproc)
DEMO_OUT   ?= out/demo
CMAKE_ARGS ?=

.PHONY: all setup configure build test demo bench format check-format clean

all: build

setup:
	@./scripts/setup

configure: setup
	@if [ ! -f $(BUILD_DIR)/build.ninja ]; then \
	  cmake -S . -B $(BUILD_DIR) -G Ninja -DCMAKE_BUILD_TYPE=$(BUILD_TYPE) $(CMAKE_ARGS); \
	fi

build: configure
	@cmake --build $(BUILD_DIR) -j $(JOBS)

test: build
	@ctest --test-dir $(BUILD_DIR) --output-on-failure -j $(JOBS) --no-tests=error

demo: build
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
