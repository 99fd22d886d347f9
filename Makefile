# demcal: the two commands that do everything on a fresh Debian machine.
#   make demo   install missing packages, build, run the main job on the bundled default data
#   make test   the same set-up, then every test
BUILD ?= build
JOBS ?= 2
BUILD_TYPE ?= Release

.PHONY: all deps configure build demo test bench soak clean

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

bench: build
	bash scripts/bench.sh $(BUILD)

# Crash safety: 20 kills -9 of a campaign, each resumed; result and archive checked (docs/pipelines.md).
soak: build
	$(BUILD)/bench/bench_soak --kills 20 --seed 1 --out $(BUILD)/soak

clean:
	rm -rf $(BUILD)
