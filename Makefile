# hush — top-level wrapper around CMake. On a fresh Debian 12 machine:
#   make demo   installs what is missing, builds, runs the demo
#   make test   installs what is missing, builds, runs every test
# (Release, then a Release build of the vector loops the native one did not
# compile (x86-64-v3's AVX2 loops on an AVX-512 CPU, elsewhere the AVX-512
# loops with SIMDe emulating them), then AddressSanitizer + UBSan, then the tests under
# ThreadSanitizer (clang, libomp and Archer), then 60 s of EXR fuzzing,
# 30 s of scene and sequence-file fuzzing, 45 s of filter-API fuzzing and
# 20 s of path-space-filter API fuzzing).

JOBS      ?= $(shell nproc 2>/dev/null || echo 2)
BUILD     ?= build
ASAN      ?= build-asan
TSAN      ?= build-tsan-omp
FUZZ      ?= build-fuzz
V3        ?= build-v3
EMU       ?= build-avx512-emu
FUZZ_SECS ?= 60
FUZZ_SCENE_SECS ?= 30
FUZZ_FILTER_SECS ?= 45
FUZZ_PSF_SECS ?= 20
DEMO_OUT  ?= out/demo
CMAKE_FLAGS ?=

# Debian packages the build, the tests and the demo need.
PACKAGES = cmake make gcc g++ pkg-config clang libclang-rt-14-dev libomp-dev \
           libembree-dev libopenexr-dev libpng-dev libjpeg-dev libassimp-dev libcjson-dev \
           libsimde-dev

SUDO := $(shell [ "$$(id -u)" = 0 ] || echo sudo)

.PHONY: all deps build test test-release test-isa test-v3 test-avx512-emu test-asan test-tsan test-fuzz demo install clean

all: build

deps:
	@missing=""; for p in $(PACKAGES); do \
	  dpkg-query -W -f='$${Status}' $$p 2>/dev/null | grep -q "install ok installed" || missing="$$missing $$p"; \
	done; \
	if [ -n "$$missing" ]; then \
	  echo "make deps: installing$$missing"; \
	  $(SUDO) apt-get update -qq && \
	  DEBIAN_FRONTEND=noninteractive $(SUDO) apt-get install -y -qq --no-install-recommends $$missing; \
	else echo "make deps: all packages present"; fi

$(BUILD)/CMakeCache.txt:
	cmake -S . -B $(BUILD) -DCMAKE_BUILD_TYPE=Release -DHUSH_WERROR=ON $(CMAKE_FLAGS)

build: $(BUILD)/CMakeCache.txt
	cmake --build $(BUILD) -j $(JOBS)

test: deps
	$(MAKE) test-release
	$(MAKE) test-isa
	$(MAKE) test-asan
	$(MAKE) test-tsan
	$(MAKE) test-fuzz
	@echo "make test: all test stages passed"

test-release: build
	ctest --test-dir $(BUILD) --output-on-failure -j $(JOBS)

# The hand-written vector loops come as AVX-512, AVX2 and portable code; a
# native build compiles one of the first two, the ASan build the portable
# one. test-isa builds and tests the other: x86-64-v3's AVX2 loops on an
# AVX-512 CPU, and on any other the AVX-512 loops (test-avx512-emu), so that
# a loop written on one of CI's two host CPUs is run on the other's too.
test-isa:
	@if grep -qw avx512f /proc/cpuinfo; then $(MAKE) test-v3; else $(MAKE) test-avx512-emu; fi

# The x86-64-v3 build (AVX2 + FMA) compiles hand-written AVX2 loops that a
# native build on an AVX-512 CPU never builds (svgf's a-trous and spatial
# variance): built with -Werror and tested wherever the CPU can run them.
test-v3:
	@if grep -qw avx2 /proc/cpuinfo && grep -qw fma /proc/cpuinfo; then \
	  cmake -S . -B $(V3) -DCMAKE_BUILD_TYPE=Release -DHUSH_ARCH=x86-64-v3 -DHUSH_WERROR=ON $(CMAKE_FLAGS) && \
	  cmake --build $(V3) -j $(JOBS) && \
	  ctest --test-dir $(V3) --output-on-failure -j $(JOBS); \
	else echo "test-v3: skipped, this CPU has no AVX2 + FMA"; fi

# The AVX-512 loops on a CPU without AVX-512: their intrinsics implemented by
# SIMDe (libsimde-dev) through tests/avx512_emulation.h, force-included.
# Checks their logic, not their speed.
test-avx512-emu:
	cmake -S . -B $(EMU) -DCMAKE_BUILD_TYPE=Release -DHUSH_WERROR=ON \
	  -DCMAKE_C_FLAGS="-include $(CURDIR)/tests/avx512_emulation.h" $(CMAKE_FLAGS)
	cmake --build $(EMU) -j $(JOBS)
	ctest --test-dir $(EMU) --output-on-failure -j $(JOBS)

test-asan:
	cmake -S . -B $(ASAN) -DCMAKE_BUILD_TYPE=Debug -DHUSH_SANITIZE=ON -DHUSH_WERROR=ON -DHUSH_NATIVE=OFF $(CMAKE_FLAGS)
	cmake --build $(ASAN) -j $(JOBS)
	ASAN_OPTIONS=detect_leaks=1:abort_on_error=1 UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1 \
	  ctest --test-dir $(ASAN) --output-on-failure -j $(JOBS)

# ThreadSanitizer over the tests, built by clang with LLVM's OpenMP runtime
# and its Archer tool, which tells TSan about OpenMP's barriers (gcc's
# libgomp is not instrumented: every parallel loop would be a false report).
# tests/tsan.supp: the uninstrumented libraries' own threads (Embree, TBB,
# libomp).
TSAN_TESTS = test_accumulate test_api test_asvgf test_bmfr test_cli test_core test_eval_cli \
             test_export_bmfr test_gradients test_io test_lag test_metrics test_nca \
             test_progressive test_psf test_render test_render_cli test_report test_scene \
             test_ssim test_svgf test_synthetic test_taa
ARCHER = $(dir $(shell readlink -f "$$(command -v clang)"))../lib/libarcher.so
test-tsan:
	@test -f $(ARCHER) || { echo "make test-tsan: $(ARCHER) is missing (libomp-dev)"; exit 1; }
	cmake -S . -B $(TSAN) -DCMAKE_C_COMPILER=clang -DCMAKE_CXX_COMPILER=clang++ \
	  -DCMAKE_BUILD_TYPE=Debug -DHUSH_WERROR=ON -DHUSH_NATIVE=OFF \
	  -DCMAKE_C_FLAGS="-fsanitize=thread -g -O1 -ffp-contract=off -Wno-pass-failed" \
	  -DCMAKE_EXE_LINKER_FLAGS=-fsanitize=thread $(CMAKE_FLAGS)
	cmake --build $(TSAN) -j $(JOBS) --target hush_cli $(TSAN_TESTS)
	cd $(TSAN) && OMP_TOOL_LIBRARIES=$(ARCHER) \
	  TSAN_OPTIONS="halt_on_error=1 ignore_noninstrumented_modules=1 suppressions=$(CURDIR)/tests/tsan.supp" \
	  ctest -j $(JOBS) --output-on-failure -R '^test_'

test-fuzz:
	cmake -S . -B $(FUZZ) -DCMAKE_C_COMPILER=clang -DCMAKE_BUILD_TYPE=RelWithDebInfo -DHUSH_FUZZ=ON -DHUSH_BUILD_TESTS=OFF -DHUSH_NATIVE=OFF $(CMAKE_FLAGS)
	cmake --build $(FUZZ) -j $(JOBS) --target fuzz_exr fuzz_exr_corpus
	mkdir -p $(FUZZ)/fuzz/corpus-run && cp -n $(FUZZ)/fuzz/corpus/* $(FUZZ)/fuzz/corpus-run/ 2>/dev/null || true
	ASAN_OPTIONS=detect_leaks=1 $(FUZZ)/fuzz/fuzz_exr -max_total_time=$(FUZZ_SECS) -timeout=10 -rss_limit_mb=2048 \
	  -print_final_stats=1 $(FUZZ)/fuzz/corpus-run
	@echo "fuzz_exr: $(FUZZ_SECS) s without a crash or leak"
	cmake --build $(FUZZ) -j $(JOBS) --target fuzz_scene
	mkdir -p $(FUZZ)/fuzz/scene-run && cp -n fuzz/scene_seeds/* $(FUZZ)/fuzz/scene-run/ 2>/dev/null || true
	ASAN_OPTIONS=detect_leaks=1:fast_unwind_on_malloc=0 LSAN_OPTIONS=suppressions=$(CURDIR)/fuzz/lsan-assimp.supp \
	  $(FUZZ)/fuzz/fuzz_scene -max_total_time=$(FUZZ_SCENE_SECS) -timeout=10 -rss_limit_mb=2048 -keep_seed=1 \
	  -print_final_stats=1 $(FUZZ)/fuzz/scene-run
	@echo "fuzz_scene: $(FUZZ_SCENE_SECS) s without a crash or leak"
	cmake --build $(FUZZ) -j $(JOBS) --target fuzz_filter
	mkdir -p $(FUZZ)/fuzz/filter-run && cp -n fuzz/filter_seeds/* $(FUZZ)/fuzz/filter-run/ 2>/dev/null || true
	ASAN_OPTIONS=detect_leaks=1 $(FUZZ)/fuzz/fuzz_filter -max_total_time=$(FUZZ_FILTER_SECS) -timeout=60 \
	  -rss_limit_mb=2048 -keep_seed=1 -print_final_stats=1 $(FUZZ)/fuzz/filter-run
	@echo "fuzz_filter: $(FUZZ_FILTER_SECS) s without a crash, leak, NaN output or thread-count difference"
	cmake --build $(FUZZ) -j $(JOBS) --target fuzz_psf
	mkdir -p $(FUZZ)/fuzz/psf-run && cp -n fuzz/psf_seeds/* $(FUZZ)/fuzz/psf-run/ 2>/dev/null || true
	ASAN_OPTIONS=detect_leaks=1 $(FUZZ)/fuzz/fuzz_psf -max_total_time=$(FUZZ_PSF_SECS) -timeout=30 \
	  -rss_limit_mb=2048 -keep_seed=1 -print_final_stats=1 $(FUZZ)/fuzz/psf-run
	@echo "fuzz_psf: $(FUZZ_PSF_SECS) s without a crash, leak, NaN lookup or thread-count difference"

demo: deps build
	./tools/demo.sh $(BUILD)/hush $(DEMO_OUT)

install: build
	cmake --install $(BUILD)

clean:
	rm -rf $(BUILD) $(ASAN) $(TSAN) $(FUZZ) $(V3) $(EMU) out
