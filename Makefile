# clothfit: the two front-door commands.
#   make demo   install dependencies, build, run the main job
#   make test   install dependencies (incl. web/ and chromium), fetch the HDRIs, build, run the tests
# Everything else (bench, lut, stress, format) is a convenience on top of the same build.

BUILD_DIR ?= build
BUILD_TYPE ?= Release
JOBS ?= $(shell nproc 2>/dev/null || echo 2)
CLOTHFIT := $(BUILD_DIR)/bin/clothfit
GENERATOR := $(shell command -v ninja >/dev/null 2>&1 && echo "-G Ninja")

.PHONY: all deps data configure build test demo bench stress lut format clean

all: build

deps:
	@scripts/install-deps

# Real HDR environments into the data cache ($$CLOTHFIT_DATA or ~/.cache/clothfit), fetched
# only when the cache is missing or does not match its manifest.
data:
	@scripts/fetch-data --check --quiet || scripts/fetch-data

# Re-configure when the build directory is missing; CMake re-runs itself on CMakeLists changes.
$(BUILD_DIR)/CMakeCache.txt:
	@echo "[make] configuring $(BUILD_DIR) ($(BUILD_TYPE))"
	@generator="$$(command -v ninja >/dev/null 2>&1 && echo '-G Ninja')"; \
	cmake -S . -B $(BUILD_DIR) $$generator -DCMAKE_BUILD_TYPE=$(BUILD_TYPE)

configure: deps $(BUILD_DIR)/CMakeCache.txt

build: configure
	@echo "[make] building with $(JOBS) jobs"
	@cmake --build $(BUILD_DIR) -j $(JOBS)

test: build data
	@echo "[make] running the test suite"
	@cd $(BUILD_DIR) && ctest --output-on-failure -j $(JOBS)

demo: build data
	@scripts/demo $(CLOTHFIT)

bench: build
	@$(CLOTHFIT) bench brdf

stress: build
	@$(CLOTHFIT) stress --evals 10000000

lut: build
	@mkdir -p out
	@$(CLOTHFIT) lut --size 128 --out out/dfg.exr --sheen-out out/sheen_albedo.exr

format:
	@clang-format -i $$(git ls-files '*.h' '*.cpp')

clean:
	@rm -rf $(BUILD_DIR)
