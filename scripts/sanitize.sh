#!/usr/bin/env bash
# Sanitizer runs (issue 13), each in a build directory of its own:
#
#   scripts/sanitize.sh asan   ASan + UBSan (+ float-cast-overflow) over the whole
#                              test suite, minus the long timing-sensitive HIL runs
#                              listed in ASAN_EXCLUDE below       -> build-asan/
#   scripts/sanitize.sh asan-ci  the same over the CI scope (.ci/run): the tests of
#                              common/, common/protocol and remote_site/ only (the
#                              ground station and hil_tests are left out for CI's
#                              time budget, each binary named in the log; see
#                              ASAN_CI_SKIP_DIRS below)          -> build-asan/
#   scripts/sanitize.sh tsan   TSan over the tests with threads: the control loop,
#                              the DDS link both sides, the journal writer -> build-tsan/
#   scripts/sanitize.sh        both (asan, then tsan)
#   FORESIGHT_SANITIZE_BUILD_ONLY=1 scripts/sanitize.sh MODE   only build MODE's targets
#
# GCC (the project's compiler) with cmake/Sanitizers.cmake (FORESIGHT_SANITIZE).
# Builds only the targets the selected tests need, -j${FORESIGHT_JOBS:-2}.
# Warnings are not errors here (FORESIGHT_WERROR=OFF): the main build checks
# them, and the sanitizers make GCC emit different -Wmaybe-uninitialized /
# -Wstringop-* diagnostics that say nothing about our code.
#
# Runtime options: any ASan/UBSan/TSan report fails the test that caused it
# (UBSan halts on the first error; leaks are reported). Third-party leaks are
# suppressed by name in cmake/sanitizers/lsan.supp (Mesa's OSMesa), never by
# turning leak detection off. Exits non-zero when a build or a test fails;
# each step prints its wall time.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
MODE=${1:-all}
JOBS=${FORESIGHT_JOBS:-2}
# FORESIGHT_SANITIZE_BUILD_ONLY=1: configure and build, run nothing (.ci/run
# builds ahead in the background while the main test run leaves the CPU idle).
BUILD_ONLY=${FORESIGHT_SANITIZE_BUILD_ONLY:-0}

case "$MODE" in asan|asan-ci|tsan|all) ;; *)
  echo "usage: scripts/sanitize.sh [asan|asan-ci|tsan|all]" >&2; exit 2 ;;
esac

# Packages: GCC's sanitizer runtimes come with build-essential (libasan8,
# libubsan1, libtsan2 through gcc-12); the rest is scripts/setup.sh's list.
for lib in libasan8 libubsan1 libtsan2; do
  if ! dpkg -s "$lib" >/dev/null 2>&1; then
    echo "sanitize: $lib missing: run scripts/setup.sh first (build-essential brings it)" >&2
    exit 1
  fi
done

LAUNCHER=()
command -v ccache >/dev/null 2>&1 && LAUNCHER=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache)

# The control loop mlockall()s; under a sanitizer it skips that (see
# control_loop.cpp), and `foresight-remote check` returns before trying when
# the limit is unlimited: locking ASan's terabytes of shadow would exhaust memory.
ulimit -l unlimited 2>/dev/null || true

export ASAN_OPTIONS="detect_leaks=1:check_initialization_order=1:strict_init_order=1:detect_stack_use_after_return=0:abort_on_error=0:halt_on_error=1:print_summary=1"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1:print_summary=1"
export LSAN_OPTIONS="suppressions=$ROOT/cmake/sanitizers/lsan.supp:print_suppressions=0"
export TSAN_OPTIONS="halt_on_error=1:second_deadlock_stack=1:suppressions=$ROOT/cmake/sanitizers/tsan.supp"

step_start=0
step() { step_start=$(date +%s); echo "== sanitize: $* ($(date -u +%H:%M:%S) UTC)"; }
step_done() { echo "== sanitize: done in $(( $(date +%s) - step_start )) s"; }

configure() {  # dir sanitizers
  # -O1 (the sanitizers' recommendation): a third less compile time than -O3.
  cmake -S . -B "$1" -G Ninja -DCMAKE_BUILD_TYPE=Release -DFORESIGHT_WERROR=OFF \
    -DCMAKE_CXX_FLAGS_RELEASE="-O1 -DNDEBUG" -DCMAKE_C_FLAGS_RELEASE="-O1 -DNDEBUG" \
    -DFORESIGHT_SANITIZE="$2" -DPython3_EXECUTABLE=/usr/bin/python3 "${LAUNCHER[@]}" >/dev/null
}

# Every executable target in bin/ (tests, the programs they start; the
# benchmarks are in bench/), minus the binaries excluded below. Only
# executables: ninja builds the libraries they link, and no other (listing
# every target with object files had put the ground station's libraries, which
# no test in the CI scope links, into the asan-ci build).
exe_targets() {  # dir exclude-regex
  ninja -C "$1" -t targets all |
    sed -n 's/^bin\/\([^:]*\): CXX_EXECUTABLE_LINKER__.*/\1/p' |
    grep -Ev "^($2)\$" || true
}

# ---- ASan + UBSan -------------------------------------------------------------
# Left out of the ASan run, and why (each runs in the normal build's ctest):
#  * test_changeout_hil   the whole contact sequence against the real daemon,
#                         ~2 min normally; its timeouts are tuned to real-time
#                         cycles that ASan slows 2-3x (the same daemon paths run
#                         in test_remote_commands, which stays in).
#  * test_demo_cli        `foresight demo --fast`: the changeout again end to end.
#  * emulated_link_4s_upload_and_run  4 s round trip through the link emulator.
#  * LinkEmu RTT/rate measurements   they assert round trips within 5% of 400 ms
#                         and forwarding rates: timing, not memory.
#  * PointsCsvHardening.MoreRowsThanAPointsFileMayHaveAreRefused,
#    CalibrateHardening.OutlierFlaggingRefitsABoundedNumberOfTimes  they bound
#                         the wall time of 1e6-row inputs (10 s, 30 s): under
#                         ASan on a loaded machine they took 10.03 s and 104 s
#                         with no sanitizer report (timing, not memory).
#  * RtAlloc.CounterWorks  the allocation counter's self-test asserts an exact
#                         count (3: a vector's operator new twice, one malloc);
#                         under ASan's allocator hook it sees 2 (first CI run,
#                         2026-12-02). The no-allocation proofs assert a count
#                         of 0, which the hook still sees; the exact count is
#                         checked in the normal build.
#  * Plant.LatchAndLoosenThroughTheLstFreeTheOru  asserts that every plant cycle
#                         met its period (cycles_ok) while the LST runs over
#                         Modbus: ASan's 2-3x slow-down missed it (timing, not
#                         memory; first CI run, 2026-12-02).
#  * link_outage_mid_trajectory  the script times a link outage against the
#                         trajectory's upload; under ASan beside other tests the
#                         upload took longer and the outage came first ("the link
#                         was lost before the trajectory ran", 2026-12-02; passed
#                         alone under ASan): timing, not memory.
ASAN_EXCLUDE_BINARIES='test_changeout_hil|test_demo_cli'
ASAN_EXCLUDE_TESTS='_NOT_BUILT$|^PointsCsvHardening\.MoreRowsThanAPointsFileMayHaveAreRefused$|^CalibrateHardening\.OutlierFlaggingRefitsABoundedNumberOfTimes$|^Changeout\.|^DemoCli\.|^emulated_link_4s_upload_and_run$|^link_outage_mid_trajectory$|^RtAlloc\.CounterWorks$|^Plant\.LatchAndLoosenThroughTheLstFreeTheOru$|^LinkEmu\.(UdpEchoRoundTripWithinFivePercentOf400ms|DdsPingPongRoundTripWithinFivePercentOf400ms|ForwardingCapacityMeasured|BandwidthCapRespectedAndQueueBounded|LossRateWithinStatisticalBounds|DdsTrajectoryUploadArrivesWholeThroughLossAndJitter)$'

# The CI scope (asan-ci): CI (.ci/run) has 90 min on 2 cores and the normal
# build + test run takes ~31 min of it; everything CI adds must fit in ~40 min
# (ASan, TSan and the fuzzers). ASan over the whole suite does not fit: the
# ground station's binaries (OpenCV, Ceres, OSMesa, CLI11: the heaviest
# translation units of the project, and GL rendering that ASan slows most) and
# hil_tests (the real daemon driven by the ground CLI, which needs the ground
# station built) are left out of the CI run. They are not skipped silently: every
# binary left out is printed with this reason, and `scripts/sanitize.sh asan`
# runs them (the whole suite). What CI runs under ASan: every test of common/
# (models, kinematics, planner, input hardening), common/protocol (every DDS
# sample's validation, loopback, Fast DDS interop), remote_site/ (CAN, CiA 402,
# F/T, LST over Modbus, simulator, the RT controller and its no-allocation
# proofs, journal, the remote link, the daemon); the ground's parsers run under
# ASan+UBSan in the fuzzers (scripts/fuzz.sh, also in CI).
ASAN_CI_SKIP_DIRS=(ground_station hil_tests)
# hil_tests' shell tests are not binaries of their own: left out of the CI
# scope by name (they need the ground CLI and the link emulator, not built there).
ASAN_CI_EXCLUDE_TESTS='^link_outage_mid_trajectory$'

# Executable targets defined in the CMakeLists.txt under the given folders.
targets_in_dirs() {
  local d
  for d in "$@"; do
    find "$d" -name CMakeLists.txt -print0 | xargs -0 grep -hoE '^\s*(foresight_add_test|add_executable)\(\s*[A-Za-z0-9_-]+' |
      sed -E 's/.*\(\s*//'
  done | sort -u
}

run_asan() {  # all|ci
  local dir=${FORESIGHT_ASAN_DIR:-build-asan} exclude=$ASAN_EXCLUDE_BINARIES exclude_tests=$ASAN_EXCLUDE_TESTS
  step "ASan+UBSan configure + build ($dir, scope $1)"
  configure "$dir" "address,undefined"
  if [[ $1 == ci ]]; then
    mapfile -t skipped < <(targets_in_dirs "${ASAN_CI_SKIP_DIRS[@]}")
    echo "sanitize: asan-ci leaves out (CI time budget; run by 'scripts/sanitize.sh asan'): ${skipped[*]}"
    exclude="$exclude|$(IFS='|'; echo "${skipped[*]}")"
    exclude_tests="$exclude_tests|$ASAN_CI_EXCLUDE_TESTS"
  fi
  mapfile -t targets < <(exe_targets "$dir" "$exclude")
  ninja -C "$dir" -j"$JOBS" "${targets[@]}"
  step_done
  [[ $BUILD_ONLY == 1 ]] && return 0
  step "ASan+UBSan ctest (scope $1)"
  # Tests of binaries not built here are "<binary>_NOT_BUILT": excluded by name.
  ctest --test-dir "$dir" --output-on-failure -j"$JOBS" --timeout 900 -E "$exclude_tests"
  step_done
}

# ---- TSan ---------------------------------------------------------------------
# The tests whose code runs threads of ours: the RT control loop (its thread,
# the lock-free hand-off, the simulator thread), the DDS link both sides
# (listeners -> queues -> the daemon/ground threads), the journal writer thread
# and its SPSC ring, the daemon (supervisor + loop + link).
TSAN_BINARIES=(test_control_loop test_control test_journal test_spsc_ring test_link_loopback test_protocol_loopback test_daemon)
TSAN_TESTS='^(ControlLoop|Journal|JournalCommand|SpscRing|LinkLoopback|LinkLoopbackRos2|LinkLoopbackTwoKept|ProtocolLoopback|Daemon|Inbox)[A-Za-z]*\.'
# Left out of the TSan run, and why (it runs in the normal build's ctest):
#  * ControlLoop.InsertsThroughTheSimulatedDrivesAndSensor  the insertion's peak
#    force depends on the loop thread keeping its 2 ms cycle against the
#    simulated contact; under TSan (5-15x slower) on a loaded machine it
#    overshot the 80 N limit (86.2 N) with no TSan report: timing, not a race
#    (the loop's threading is exercised by the other ControlLoop tests).
#  * LinkLoopback.DelayStatisticsAndTelemetryAgesAreSane  asserts a loopback
#    round-trip median below 50 ms; under TSan on a loaded machine it measured
#    147 ms with no TSan report: a latency bound, not a race.
TSAN_EXCLUDE_TESTS='^ControlLoop\.InsertsThroughTheSimulatedDrivesAndSensor$|^LinkLoopback\.DelayStatisticsAndTelemetryAgesAreSane$'


run_tsan() {
  local dir=${FORESIGHT_TSAN_DIR:-build-tsan}
  step "TSan configure + build ($dir)"
  configure "$dir" "thread"
  ninja -C "$dir" -j"$JOBS" "${TSAN_BINARIES[@]}"
  step_done
  [[ $BUILD_ONLY == 1 ]] && return 0
  step "TSan ctest"
  # Discovered tests of binaries not built here are "not run": select by name.
  ctest --test-dir "$dir" --output-on-failure -j"$JOBS" --timeout 900 -R "$TSAN_TESTS" -E "$TSAN_EXCLUDE_TESTS"
  step_done
}

case "$MODE" in
  asan) run_asan all ;;
  asan-ci) run_asan ci ;;
  tsan) run_tsan ;;
  all) run_asan all; run_tsan ;;
esac
if [[ $BUILD_ONLY == 1 ]]; then echo "sanitize: $MODE built"; else echo "sanitize: $MODE clean"; fi
