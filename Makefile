# cellsight: the two commands of the README, plus bench.
#   make demo   install what is missing, build, run the simulated cell cycle headless → out/demo/
#   make test   install what is missing, build, run every test (ctest); non-zero on any failure
#   make bench  build and run the benchmarks (figures in docs/)
#   make train  retrain the shipped learned-descriptor models (config/descriptors/, under 2 h on 2 cores)
#   make sanitize   clang ASan + UBSan build (_build_san), the core and scanner gtests under it
#   make fuzz       every libFuzzer target for FUZZ_SECONDS each (default 60) from test/fuzz/corpus
#   make soak       SOAK_CYCLES (default 1000) cell cycles against one set of nodes → out/soak/
SHELL := /bin/bash
export PATH := /usr/bin:/bin:/usr/sbin:/sbin:$(PATH)
BUILD ?= _build
JOBS ?= 2
SAN_BUILD ?= _build_san
FUZZ_SECONDS ?= 60
SOAK_CYCLES ?= 1000
SOAK_TRAJECTORY ?= quick_sweep

.PHONY: all deps configure build test demo bench train sanitize fuzz soak clean format

all: build

deps:
	@bash scripts/install-deps.sh

$(BUILD)/CMakeCache.txt:
	@mkdir -p $(BUILD)/devel/lib/python3/dist-packages
	cmake -S . -B $(BUILD) -DCMAKE_BUILD_TYPE=Release -DCATKIN_ENABLE_TESTING=ON

configure: deps $(BUILD)/CMakeCache.txt

build: configure
	cmake --build $(BUILD) -j$(JOBS)
	cmake --build $(BUILD) -j$(JOBS) --target tests

test: build
	@bash scripts/run-tests.sh $(BUILD)

demo:
	@bash scripts/demo.sh $(BUILD) out/demo

train: build
	@bash scripts/train.sh $(BUILD) all

bench: build
	@bash scripts/bench.sh $(BUILD)

sanitize: deps
	@bash scripts/sanitize.sh $(SAN_BUILD)

fuzz: deps
	@bash scripts/fuzz.sh $(FUZZ_SECONDS) $(SAN_BUILD)

soak: build
	@SOAK_MAX_CYCLE_RATIO=$${SOAK_MAX_CYCLE_RATIO:-1.5} bash scripts/soak.sh $(SOAK_CYCLES) $(SOAK_TRAJECTORY) $(BUILD) out/soak

format:
	clang-format -i $$(git ls-files '*.cpp' '*.hpp')

clean:
	rm -rf $(BUILD) $(SAN_BUILD)
