#!/usr/bin/env bash
# Same-machine baselines: Pinocchio 4.1.0 (header-only, the seed arm) and Ruckig 0.19.4, timed in
# interleaved rounds with microrobot's own benchmarks, every process pinned to CPU 1.
#
#   tools/baselines/run.sh [rounds=3]
#
# Fetches pinned, hash-checked packages from PyPI into target/baselines/ (nothing is installed),
# builds with g++ -O3 -march=native, checks both libraries against tests/reference/ (a model that
# does not reproduce arm_reference.json to 1e-9 is not timed), then writes one log per benchmark and
# round to target/baselines/results/. Not part of CI: it is a measurement, and it needs the network.
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
here="$root/tools/baselines"
work="$root/target/baselines"
rounds="${1:-3}"
mkdir -p "$work/wheels" "$work/deps" "$work/build_ruckig" "$work/results"
cd "$work"

fetch_wheel() { # name==version sha256
    local file
    file="$(ls wheels/ 2>/dev/null | grep -i "^${1%%==*}-${1##*==}-" || true)"
    if [ -z "$file" ]; then
        pip download "$1" --no-deps --only-binary :all: -d wheels >/dev/null
        file="$(ls wheels/ | grep -i "^${1%%==*}-${1##*==}-")"
    fi
    echo "$2  wheels/$file" | sha256sum -c --quiet
    unzip -q -o "wheels/$file" -d deps
}
fetch_wheel libpinocchio==4.1.0 dbcc81e9e302ae57700775af0b86ed353effe47b5d33fa12aff9936ac33c0ae0
fetch_wheel cmeel_boost==1.90.0 14efe34db660c9aacb61247a7f9ae0ee6d7626ec9a3d89b8b27e62dba6fcaa4d
fetch_wheel cmeel_eigen==3.4.1 0ccd7b73fe8a72e2729784253c982e75d1790e0a8c71f302eb5a1fb1dd3a8a90

# Ruckig's C++ sources come in its sdist (pip would try to build it; only the tarball is wanted).
ruckig_url=https://files.pythonhosted.org/packages/4a/2a/d1c1639bf76699ab1c3c1281101372f2b749d0ad8aee4c19200947b92785/ruckig-0.19.4.tar.gz
[ -f ruckig-0.19.4.tar.gz ] || curl -sSfL -o ruckig-0.19.4.tar.gz "$ruckig_url"
echo "71d003bf0ff9aa0031d4520b0290a5ffa6458149f5afce8be3ed6d6fba49ea64  ruckig-0.19.4.tar.gz" | sha256sum -c --quiet
tar xzf ruckig-0.19.4.tar.gz

echo "== build (g++ -O3 -march=native)"
flags=(-O3 -march=native -DNDEBUG -std=c++17)
python3 "$here/gen_inputs.py"
for f in ruckig-0.19.4/src/ruckig/*.cpp; do
    b="$(basename "$f" .cpp)"
    [ "$b" = cloud_client ] && continue
    g++ "${flags[@]}" -Iruckig-0.19.4/include -c "$f" -o "build_ruckig/$b.o"
done
rm -f build_ruckig/libruckig.a && ar rcs build_ruckig/libruckig.a build_ruckig/*.o
g++ "${flags[@]}" -Iruckig-0.19.4/include "$here/bench_ruckig.cpp" build_ruckig/libruckig.a -o bench_ruckig
g++ "${flags[@]}" -Iruckig-0.19.4/include "$here/ruckig_sample.cpp" build_ruckig/libruckig.a -o ruckig_sample
# The compile definitions of Pinocchio's `pinocchio_headers` CMake target; no template
# instantiation library, no URDF, no collision.
inc=deps/cmeel.prefix/include
g++ "${flags[@]}" -I$inc -I$inc/eigen3 -DBOOST_MPL_LIMIT_LIST_SIZE=30 -DBOOST_MPL_LIMIT_VECTOR_SIZE=30 \
    -DBOOST_MPL_CFG_NO_PREPROCESSED_HEADERS -DBOOST_FUSION_INVOKE_MAX_ARITY=12 \
    "$here/bench_pin.cpp" -o bench_pin
(cd "$root" && cargo bench -q -p microrobot-model --bench model --no-run \
    && cargo bench -q -p microrobot-trajectory --bench trajectory --no-run \
    && cargo build -q --release -p microrobot-model --example hot_path_min \
    && cargo build -q --release -p microrobot-trajectory --example cpu_time)

echo "== $rounds interleaved rounds on CPU 1 (after 30 s for the build's load to settle)"
sleep 30
res="$work/results"
for r in $(seq 1 "$rounds"); do
    echo "round $r $(date +%T), load $(cut -d' ' -f1 /proc/loadavg)"
    (cd "$root" && taskset -c 1 cargo bench -q -p microrobot-model --bench model -- \
        --warm-up-time 1 --measurement-time 3) > "$res/microrobot_model_$r.txt" 2>&1
    taskset -c 1 "$root/target/release/examples/hot_path_min" > "$res/microrobot_hot_path_min_$r.txt"
    taskset -c 1 ./bench_pin 2.0 > "$res/pinocchio_$r.txt"
    (cd "$root" && taskset -c 1 cargo bench -q -p microrobot-trajectory --bench trajectory -- \
        --warm-up-time 1 --measurement-time 3) > "$res/microrobot_trajectory_$r.txt" 2>&1
    taskset -c 1 "$root/target/release/examples/cpu_time" 30000 > "$res/microrobot_cpu_time_$r.txt"
    taskset -c 1 ./bench_ruckig 2.0 30000 > "$res/ruckig_$r.txt"
done
for f in "$res"/*_1.txt; do
    echo "-- $(basename "$f")"
    # criterion prints a long name on its own line: join it to its "time:" line
    sed -e ':a' -e '/^[a-z_]*\/[a-z_0-9]*$/{N;s/\n */ /;ba' -e '}' "$f" \
        | grep -E 'time:|mean|best|p99' || true
done
echo "logs: $res"
