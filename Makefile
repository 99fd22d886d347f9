# demcal: the two commands that do everything on a fresh Debian machine.
#   make demo   install missing packages, build, run the main job on the bundled default data
#   make test   the same set-up, then every test
#   make test-sanitize   every test in a separate AddressSanitizer + UBSan build (clang, build-sanitize/)
#   make fuzz    build the libFuzzer targets with clang (build-fuzz/) and run each FUZZ_MINUTES
BUILD ?= build
JOBS ?= 2
BUILD_TYPE ?= Release
# Ninja schedules every translation unit as soon as its inputs exist, where CMake's Makefiles wait
# for each library's link before compiling the targets that use it (docs/benchmarks.md, "Build
# time"). Read by CMake for a new build folder only: one keeps the generator it was configured with.
GENERATOR ?= Ninja

.PHONY: all deps configure build demo test test-sanitize test-sanitize-reduced fuzz bench soak clean

all: build

deps:
	@bash scripts/install-deps.sh

$(BUILD)/CMakeCache.txt:
	CMAKE_GENERATOR="$(GENERATOR)" cmake -S . -B $(BUILD) -DCMAKE_BUILD_TYPE=$(BUILD_TYPE)

configure: deps $(BUILD)/CMakeCache.txt

build: configure
	cmake --build $(BUILD) -j$(JOBS)

demo: build
	bash scripts/demo.sh $(BUILD)

test: build
	cd $(BUILD) && ctest --output-on-failure -j$(JOBS) --timeout 600

# Sanitized build: RelWithDebInfo with line tables only (-g1: file and line in every report, a
# smaller and faster build than -g), no benchmarks. SANITIZE_TARGETS: the test programs to build
# (default all); SANITIZE_TESTS: a ctest -R pattern, SANITIZE_EXCLUDE a ctest -E pattern
# (docs/hardening.md gives the times). Tests of programs not built are skipped.
# LeakSanitizer stays on. Compiled by clang (SANITIZE_CC, SANITIZE_CXX): its AddressSanitizer +
# UBSan build takes a third of g++'s time (docs/hardening.md, "In CI"); the Release build stays g++.
SANITIZE_BUILD ?= build-sanitize
SANITIZE_CC ?= clang
SANITIZE_CXX ?= clang++
SANITIZE_TARGETS ?= all
SANITIZE_TESTS ?= .
SANITIZE_EXCLUDE ?= _NOT_BUILT
# SANITIZE_EXCLUDE_FILE: a file of further ctest -E patterns, one a line (# comments).
SANITIZE_EXCLUDE_FILE ?=
sanitize_exclude_listed = $(if $(SANITIZE_EXCLUDE_FILE),|$(shell grep -v -e '^\#' -e '^$$' $(SANITIZE_EXCLUDE_FILE) | paste -sd'|'))
# A folder configured with another compiler is configured afresh: on a compiler change CMake
# resets its cache, the sanitizer option and flags with it.
test-sanitize:
	@bash scripts/install-deps.sh $(if $(filter clang%,$(SANITIZE_CC)),clang libclang-rt-dev)
	@if [ -f $(SANITIZE_BUILD)/CMakeCache.txt ] && ! grep -qx "CMAKE_CXX_COMPILER:[A-Z]*=$$(command -v $(SANITIZE_CXX))" $(SANITIZE_BUILD)/CMakeCache.txt; then \
	  echo "test-sanitize: $(SANITIZE_BUILD) was configured with another compiler; configuring it afresh"; rm -rf $(SANITIZE_BUILD); fi
	CMAKE_GENERATOR="$(GENERATOR)" cmake -S . -B $(SANITIZE_BUILD) -DCMAKE_BUILD_TYPE=RelWithDebInfo -DDEMCAL_SANITIZE=ON -DDEMCAL_BUILD_BENCHMARKS=OFF \
	  -DCMAKE_C_COMPILER=$(SANITIZE_CC) -DCMAKE_CXX_COMPILER=$(SANITIZE_CXX) "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O2 -g1 -DNDEBUG"
	cmake --build $(SANITIZE_BUILD) -j$(JOBS) --target $(SANITIZE_TARGETS)
	cd $(SANITIZE_BUILD) && ASAN_OPTIONS=abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1 \
	  ctest --output-on-failure -j$(JOBS) --timeout 3600 -R '$(SANITIZE_TESTS)' -E '_NOT_BUILT|$(SANITIZE_EXCLUDE)$(sanitize_exclude_listed)'

# Every test program sanitized, less the long loop tests of tests/sanitize/long-tests.txt (their
# reduced forms run; docs/hardening.md).
test-sanitize-reduced:
	$(MAKE) test-sanitize SANITIZE_EXCLUDE_FILE=tests/sanitize/long-tests.txt

# libFuzzer: clang build of the three fuzz targets, each run FUZZ_MINUTES (scripts/fuzz.sh).
FUZZ_BUILD ?= build-fuzz
FUZZ_MINUTES ?= 10
fuzz: deps
	bash scripts/fuzz.sh $(FUZZ_BUILD) $(FUZZ_MINUTES)

bench: build
	bash scripts/bench.sh $(BUILD)

# Crash safety: 20 kills -9 of a campaign, each resumed; result and archive checked (docs/pipelines.md).
# `make test` runs a short one (5 kills, surrogate on).
soak: build
	$(BUILD)/tests/crash_soak --kills 20 --seed 1 --out $(BUILD)/soak

clean:
	rm -rf $(BUILD)
