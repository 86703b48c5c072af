# clothfit: the two front-door commands.
#   make demo   install dependencies, build, run the main job
#   make test   install dependencies (incl. web/ and chromium), fetch the HDRIs, build, run the tests
# Everything else (bench, lut, stress, format) is a convenience on top of the same build.

BUILD_DIR ?= build
BUILD_TYPE ?= Release
JOBS ?= $(shell nproc 2>/dev/null || echo 2)
CLOTHFIT := $(BUILD_DIR)/bin/clothfit
GENERATOR := $(shell command -v ninja >/dev/null 2>&1 && echo "-G Ninja")

.PHONY: all deps data configure build test demo bench stress lut format clean san-build san-fuzzers sanitize fuzz fuzz-replay regressions regressions-san

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

# Hostile inputs (docs/reliability.md). One clang build in $(SAN_DIR) serves both: every project
# object has ASan+UBSan and libFuzzer coverage, so it holds the test suite, the executable and
# the harnesses.
#   make sanitize                the whole ctest suite under ASan+UBSan (no report allowed)
#   make fuzz FUZZ_SECONDS=N     every harness for N seconds (FUZZ=name or FUZZ=a,b for some;
#                                FUZZ_JOBS=2 runs two at a time; FUZZ_LOG_DIR=dir keeps the logs)
#   make fuzz-replay             each corpus file and reproducer once per harness (CI, seconds)
#   make regressions             the issue-14 reproducers through the Release executable
#   make regressions-san         the same through the ASan+UBSan executable in $(SAN_DIR) (CI)
SAN_DIR ?= build-san
FUZZ_SECONDS ?= 60
FUZZ ?= all
FUZZ_JOBS ?= 1
FUZZ_LOG_DIR ?=
SAN_ENV := ASAN_OPTIONS=detect_leaks=1:abort_on_error=1:detect_stack_use_after_return=0 \
           UBSAN_OPTIONS=halt_on_error=1:print_stacktrace=1 \
           LSAN_OPTIONS=suppressions=$(CURDIR)/tests/fuzz/lsan.supp:print_suppressions=1 \
           CLOTHFIT_REGRESSION_TIMEOUT=120

$(SAN_DIR)/CMakeCache.txt:
	@echo "[make] configuring $(SAN_DIR) (clang, ASan+UBSan, libFuzzer)"
	@cmake -S . -B $(SAN_DIR) $(GENERATOR) -DCMAKE_BUILD_TYPE=RelWithDebInfo \
	  -DCMAKE_CXX_COMPILER=clang++ -DCLOTHFIT_FUZZ=ON

# Builds in $(SAN_DIR) hold a lock, so a fuzz campaign started in the background and a build
# of the test suite never run ninja in the same directory at once.
SAN_LOCK := $(shell command -v flock >/dev/null 2>&1 && echo "flock $(SAN_DIR)/.build.lock")

san-build: $(SAN_DIR)/CMakeCache.txt
	@$(SAN_LOCK) cmake --build $(SAN_DIR) -j $(JOBS)

comma := ,
# The harnesses named by FUZZ (all of them by default), without the test suite.
FUZZ_TARGETS := $(if $(filter all,$(FUZZ)),clothfit_fuzzers,$(addprefix fuzz_,$(subst $(comma), ,$(FUZZ))))
san-fuzzers: $(SAN_DIR)/CMakeCache.txt
	@$(SAN_LOCK) cmake --build $(SAN_DIR) -j $(JOBS) --target $(FUZZ_TARGETS)

sanitize: san-build
	@echo "[make] running the test suite under ASan+UBSan"
	@start=$$(date +%s); cd $(SAN_DIR) && $(SAN_ENV) ctest --output-on-failure -j $(JOBS) \
	  --output-log sanitize.log; \
	  rc=$$?; echo "[make] sanitize: ctest exit $$rc in $$(( $$(date +%s) - start )) s"; exit $$rc

fuzz: san-fuzzers
	@FUZZ_JOBS=$(FUZZ_JOBS) FUZZ_LOG_DIR=$(FUZZ_LOG_DIR) \
	  tests/fuzz/fuzz.sh run $(SAN_DIR)/fuzz $(FUZZ) $(FUZZ_SECONDS)

fuzz-replay: san-fuzzers
	@tests/fuzz/fuzz.sh replay $(SAN_DIR)/fuzz $(FUZZ)

regressions: build
	@tests/fuzz/run_regressions.sh $(CLOTHFIT)

regressions-san: $(SAN_DIR)/CMakeCache.txt
	@$(SAN_LOCK) cmake --build $(SAN_DIR) -j $(JOBS) --target clothfit
	@$(SAN_ENV) tests/fuzz/run_regressions.sh $(SAN_DIR)/bin/clothfit

format:
	@clang-format -i $$(git ls-files '*.h' '*.cpp')

clean:
	@rm -rf $(BUILD_DIR) $(SAN_DIR)
