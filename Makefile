# demcal: the two commands that do everything on a fresh Debian machine.
#   make demo   install missing packages, build, run the main job on the bundled default data
#   make test   the same set-up, then every test
#   make test-sanitize   every test in a separate AddressSanitizer + UBSan build (build-sanitize/)
#   make fuzz    build the libFuzzer targets with clang (build-fuzz/) and run each FUZZ_MINUTES
BUILD ?= build
JOBS ?= 2
BUILD_TYPE ?= Release

.PHONY: all deps configure build demo test test-sanitize fuzz bench clean

all: build

deps:
	@bash scripts/install-deps.sh

$(BUILD)/CMakeCache.txt:
	cmake -S . -B $(BUILD) -DCMAKE_BUILD_TYPE=$(BUILD_TYPE)

configure: deps $(BUILD)/CMakeCache.txt

build: configure
	cmake --build $(BUILD) -j$(JOBS)

demo: build
	bash scripts/demo.sh $(BUILD)

test: build
	cd $(BUILD) && ctest --output-on-failure -j$(JOBS) --timeout 600

# Sanitized build: RelWithDebInfo for readable reports, no benchmarks. SANITIZE_TESTS is a ctest -R
# pattern (default: every test); ASan's leak checker is off (LibTorch's static caches are reported).
SANITIZE_BUILD ?= build-sanitize
SANITIZE_TESTS ?= .
test-sanitize: deps
	cmake -S . -B $(SANITIZE_BUILD) -DCMAKE_BUILD_TYPE=RelWithDebInfo -DDEMCAL_SANITIZE=ON -DDEMCAL_BUILD_BENCHMARKS=OFF
	cmake --build $(SANITIZE_BUILD) -j$(JOBS)
	cd $(SANITIZE_BUILD) && ASAN_OPTIONS=detect_leaks=0:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1 \
	  ctest --output-on-failure -j$(JOBS) --timeout 1800 -R '$(SANITIZE_TESTS)'

# libFuzzer: clang build of the three fuzz targets, each run FUZZ_MINUTES (scripts/fuzz.sh).
FUZZ_BUILD ?= build-fuzz
FUZZ_MINUTES ?= 10
fuzz: deps
	bash scripts/fuzz.sh $(FUZZ_BUILD) $(FUZZ_MINUTES)

bench: build
	bash scripts/bench.sh $(BUILD)

clean:
	rm -rf $(BUILD)
