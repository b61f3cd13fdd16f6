#!/usr/bin/env bash
# libFuzzer runs of every parser and decoder (issue 13; targets in fuzz/).
#
#   scripts/fuzz.sh                 build all targets, run each for FUZZ_SECONDS
#   scripts/fuzz.sh fuzz_urdf ...   only these targets
#   FUZZ_SECONDS=300 scripts/fuzz.sh   a longer budget per target (default 20)
#   FUZZ_BUILD_ONLY=1 scripts/fuzz.sh  build the targets, run nothing
#
# Clang (Debian clang-14 + libclang-rt-14-dev), ASan + UBSan, coverage over
# the project's libraries, in build-fuzz/ (FORESIGHT_FUZZ_BUILD_DIR).
# For each target: first the inputs that once crashed it
# (fuzz/regressions/<target>/*; fuzz/regressions/<target>/open/ holds found
# crashes not fixed yet and is not replayed), then a fuzzing run seeded from
# fuzz/corpus/<target>/ and the real files in config/, working in a scratch
# corpus under the build directory (the repository is never written).
# Fails (exit 1) when any target crashes, leaks, hangs beyond -timeout or
# exceeds -rss_limit_mb; the reproducer is left as <build>/fuzz/artifacts/<target>/crash-*.
# FORESIGHT_FUZZ_STRICT=1 also fails on any exception other than
# foresight::Error escaping a parser (fuzz/fuzz_support.hpp).
# FUZZ_REPLAY_ONLY="t1 t2": these targets replay their regressions but are not
# fuzzed (CI uses it for a target with an open third-party crash that the
# fuzzer finds again within seconds; the caller says why).
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
BUILD=${FORESIGHT_FUZZ_BUILD_DIR:-build-fuzz}
SECONDS_PER_TARGET=${FUZZ_SECONDS:-20}
JOBS=${FORESIGHT_JOBS:-2}

ALL_TARGETS=(fuzz_points_csv fuzz_trajectory_csv fuzz_task_script fuzz_scene_yaml fuzz_oru_yaml
  fuzz_cameras_yaml fuzz_remote_yaml fuzz_lst_yaml fuzz_sdo_list fuzz_urdf fuzz_can_frames fuzz_sdo
  fuzz_modbus_registers fuzz_dds_samples)
TARGETS=("$@")
((${#TARGETS[@]})) || TARGETS=("${ALL_TARGETS[@]}")

for p in clang libclang-rt-14-dev; do
  if ! dpkg -s "$p" >/dev/null 2>&1; then
    echo "fuzz: package $p missing: run scripts/setup.sh (it installs clang and libclang-rt-14-dev)" >&2
    exit 1
  fi
done

# Seeds from the real files, per target (besides fuzz/corpus/<target>/).
config_seeds() {
  case "$1" in
    fuzz_scene_yaml) echo config/scene.yaml ;;
    fuzz_oru_yaml) echo config/oru.yaml ;;
    fuzz_remote_yaml|fuzz_lst_yaml) echo config/remote.yaml ;;
    fuzz_urdf) echo config/robot.urdf ;;
    fuzz_sdo_list) echo config/drives/*.sdo ;;
    fuzz_task_script) echo config/scripts/*.task ;;
  esac
}
# Largest input per target: a few times the real files, small for binary records.
max_len() {
  case "$1" in
    fuzz_urdf) echo 32768 ;;
    fuzz_points_csv|fuzz_trajectory_csv|fuzz_cameras_yaml|fuzz_remote_yaml|fuzz_lst_yaml|fuzz_scene_yaml|fuzz_sdo_list) echo 16384 ;;
    fuzz_dds_samples) echo 8192 ;;
    fuzz_can_frames|fuzz_sdo) echo 2048 ;;
    fuzz_modbus_registers) echo 256 ;;
    *) echo 8192 ;;
  esac
}

LAUNCHER=()
command -v ccache >/dev/null 2>&1 && LAUNCHER=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache -DCMAKE_C_COMPILER_LAUNCHER=ccache)
t0=$(date +%s)
cmake -S . -B "$BUILD" -G Ninja -DCMAKE_BUILD_TYPE=Release -DCMAKE_C_COMPILER=clang -DCMAKE_CXX_COMPILER=clang++ \
  -DCMAKE_CXX_FLAGS_RELEASE="-O1 -DNDEBUG" -DCMAKE_C_FLAGS_RELEASE="-O1 -DNDEBUG" \
  -DFORESIGHT_FUZZ=ON -DFORESIGHT_SANITIZE=address,undefined -DPython3_EXECUTABLE=/usr/bin/python3 \
  "${LAUNCHER[@]}" >/dev/null
ninja -C "$BUILD" -j"$JOBS" "${TARGETS[@]}"
echo "fuzz: build $(( $(date +%s) - t0 )) s"
if [[ ${FUZZ_BUILD_ONLY:-0} == 1 ]]; then echo "fuzz: built (FUZZ_BUILD_ONLY=1: nothing run)"; exit 0; fi

export ASAN_OPTIONS="detect_leaks=1:halt_on_error=1:abort_on_error=0"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1"
export LSAN_OPTIONS="suppressions=$ROOT/cmake/sanitizers/lsan.supp:print_suppressions=0"

failed=()
summary=()
for t in "${TARGETS[@]}"; do
  bin="$BUILD/fuzz/$t"
  work="$BUILD/fuzz/work/$t"
  art="$BUILD/fuzz/artifacts/$t"
  rm -rf "$work"
  mkdir -p "$work" "$art"
  # Regressions: every input that once crashed must now run clean.
  regs=()
  if [[ -d fuzz/regressions/$t ]]; then
    while IFS= read -r -d '' f; do regs+=("$f"); done < <(find "fuzz/regressions/$t" -maxdepth 1 -type f -print0)
  fi
  if ((${#regs[@]})); then
    if ! "$bin" -rss_limit_mb=2048 -timeout=20 "${regs[@]}" >"$art/regressions.log" 2>&1; then
      echo "fuzz: $t: a regression input crashes again (see $art/regressions.log)" >&2
      failed+=("$t(regression)")
      continue
    fi
  fi
  if [[ " ${FUZZ_REPLAY_ONLY:-} " == *" $t "* ]]; then
    line=$(printf '%-24s %-6s regressions replayed (%s), not fuzzed (FUZZ_REPLAY_ONLY)' "$t" ok "${#regs[@]}")
    summary+=("$line")
    echo "fuzz: $line"
    continue
  fi
  # Seeds.
  [[ -d fuzz/corpus/$t ]] && cp fuzz/corpus/"$t"/* "$work"/ 2>/dev/null || true
  for f in $(config_seeds "$t"); do cp "$f" "$work/"; done
  if [[ $t == fuzz_dds_samples ]]; then FORESIGHT_FUZZ_WRITE_SEEDS="$work" "$bin"; fi
  log="$art/fuzz.log"
  s0=$(date +%s)
  if "$bin" "$work" -max_total_time="$SECONDS_PER_TARGET" -max_len="$(max_len "$t")" -timeout=10 \
      -rss_limit_mb=2048 -print_final_stats=1 -artifact_prefix="$art/" >"$log" 2>&1; then
    result=ok
  else
    result=CRASH
    failed+=("$t")
  fi
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1 || true)
  cov=$(grep -o 'cov: [0-9]*' "$log" | tail -1 | cut -d' ' -f2 || true)
  line=$(printf '%-24s %-6s %4ss  execs %-9s cov %-6s corpus %s' "$t" "$result" "$(( $(date +%s) - s0 ))" \
    "${execs:-?}" "${cov:-?}" "$(find "$work" -type f | wc -l)")
  summary+=("$line")
  echo "fuzz: $line"
  if [[ $result != ok ]]; then
    grep -m1 -E 'ERROR: |runtime error|fuzz: ' "$log" >&2 || tail -5 "$log" >&2
    ls "$art"/crash-* "$art"/leak-* "$art"/timeout-* "$art"/oom-* 2>/dev/null >&2 || true
  fi
done

echo "== fuzz summary ($SECONDS_PER_TARGET s per target)"
printf '%s\n' "${summary[@]}"
if ((${#failed[@]})); then
  echo "fuzz: FAILED: ${failed[*]}" >&2
  exit 1
fi
echo "fuzz: no crashes"
