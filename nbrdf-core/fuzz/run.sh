#!/usr/bin/env bash
# Seeds and runs the fuzz targets one after another, SECONDS each (default 300), and prints the
# executions per target. Exits non-zero if any target found a crash, leak, timeout or OOM; the
# input that caused it is in artifacts/TARGET/ (minimise it with
# `cargo +nightly fuzz tmin TARGET artifacts/TARGET/FILE`).
#
# Usage: nbrdf-core/fuzz/run.sh [SECONDS] [TARGET...]   (PARALLEL=1: all targets at once)
# Needs: a nightly toolchain and cargo-fuzz (`cargo install cargo-fuzz`), and for the
# merl_reader seeds the nbrdf CLI (see seed.sh). Set NICE=0 to run at normal priority.
set -uo pipefail
here=$(cd "$(dirname "$0")" && pwd)
cd "$here"
seconds=${1:-300}
shift || true
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
    targets=(merl_reader merl_structured network_json network_structured network_pruning rgl_reader rgl_structured)
fi
nice_cmd=(nice -n "${NICE:-10}")

if ! "${nice_cmd[@]}" ./seed.sh; then
    echo "run.sh: no full-size MERL seeds; merl_reader will only reach the header checks" >&2
    echo "        (rgl_reader still has its small synthetic seeds)" >&2
fi
"${nice_cmd[@]}" cargo +nightly fuzz build -O || exit 1

# Largest input per target: a full MERL table plus some trailing bytes; the structured targets
# decode their input with `arbitrary`, a few KB is plenty; JSON seeds are up to 71 KB; real RGL
# measurements about 660 KB.
max_len() {
    case $1 in
        merl_reader) echo 34992100 ;;
        merl_structured | network_structured | rgl_structured) echo 8192 ;;
        rgl_reader) echo 700000 ;;
        network_json) echo 262144 ;;
        *) echo 4096 ;;
    esac
}

run_one() {
    local target=$1
    # New inputs go to work/TARGET (git-ignored); corpus/TARGET holds the committed seeds, and
    # a target without any (rgl_structured) has no such folder in a fresh clone.
    mkdir -p "work/$target" "artifacts/$target" "corpus/$target"
    "${nice_cmd[@]}" cargo +nightly fuzz run -O "$target" "work/$target" "corpus/$target" -- \
        -max_total_time="$seconds" -rss_limit_mb=2048 -max_len="$(max_len "$target")" \
        -timeout=60 -print_final_stats=1 >"work/$target.log" 2>&1
    echo $? >"work/$target.status"
}

for target in "${targets[@]}"; do
    echo "== $target: $seconds s (log: nbrdf-core/fuzz/work/$target.log)"
    if [ "${PARALLEL:-0}" = 1 ]; then
        run_one "$target" &
    else
        run_one "$target"
    fi
done
wait

summary=()
failed=0
for target in "${targets[@]}"; do
    log=work/$target.log
    status=$(cat "work/$target.status")
    execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
    rate=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log" | tail -1)
    if [ "$status" -eq 0 ]; then
        result="no crash"
    else
        result="FAILED (exit $status): $(grep -m1 -E '^==[0-9]+== ERROR|panicked|SUMMARY' "$log")"
        failed=1
    fi
    summary+=("$(printf '%-20s %6ss %12s execs %8s exec/s  %s' "$target" "$seconds" "${execs:-?}" "${rate:-?}" "$result")")
done
echo
echo "== summary"
printf '%s\n' "${summary[@]}"
exit $failed
