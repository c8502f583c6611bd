#!/usr/bin/env bash
# One-shot check of warpspec on a CUDA machine, run from the repository root:
#
#   bash benchmarks/gpu_check.sh                 # sizes 128 256 512, about 9 minutes on one GPU
#   bash benchmarks/gpu_check.sh --sizes "16"    # tiny: checks the script itself (CPU fallback)
#   options: --python PY (use this interpreter, no venv), --tests "PATHS" (default: tests)
#
# It makes a venv (.venv-gpu-check), installs '.[dev]' (with --python PY it uses that
# interpreter as is instead: needed where pip cannot reach an index), runs the test suite (the
# device-parametrised tests run on cuda:0 when Warp sees a GPU), the CPU/CUDA agreement test,
# then the benchmarks at each size: one iteration, redistance (full and capped as the solver
# caps it), and the octant end to end with default options (the scheduled iterations) through
# the API, per stage (set-up, iterations, meshing, peak memory), and the command line, with
# its accuracy against the true sphere. Every step has its own time limit and a failure does
# not stop the others; the end prints one markdown table of all steps. Without a GPU
# everything runs on the CPU (say so in the table).
set -u

SIZES="128 256 512"
TESTS="tests"
PY=""
VENV=".venv-gpu-check"
while [ $# -gt 0 ]; do
    case "$1" in
        --sizes) SIZES="$2"; shift 2 ;;
        --python) PY="$2"; shift 2 ;;
        --tests) TESTS="$2"; shift 2 ;;
        -h|--help) sed -n '2,17p' "$0"; exit 0 ;;
        *) echo "gpu_check: unknown argument $1 (use --sizes \"N ...\", --python PY, --tests PATHS)"
           exit 2 ;;
    esac
done
if [ ! -f pyproject.toml ] || [ ! -d warpspec ]; then
    echo "gpu_check: run it from the repository root (pyproject.toml and warpspec/ not found)"
    exit 2
fi

LOG_DIR=$(mktemp -d -t warpspec-gpu-check-XXXXXX)
DEADLINE=$((SECONDS + 530))   # every step fits in the 9 minutes: later ones are cut short
ROWS=()
FAILED=0
export WARP_CACHE_PATH="$PWD/build/warp-cache"

# step NAME LIMIT_S CMD...: run CMD with a time limit, log it, keep one table row.
step() {
    local name="$1" limit="$2"; shift 2
    local log="$LOG_DIR/$(echo "$name" | tr -c 'A-Za-z0-9' '_').log"
    local left=$((DEADLINE - SECONDS))
    if [ "$left" -lt 10 ]; then
        echo "=== $name: skipped, out of time"
        ROWS+=("| $name | SKIPPED (out of time) | 0 | |"); FAILED=1; return
    fi
    [ "$limit" -gt "$left" ] && limit=$left
    echo
    echo "=== $name (limit ${limit} s): $*"
    local t0=$SECONDS
    timeout --kill-after=10 "$limit" "$@" >"$log" 2>&1
    local rc=$?
    local took=$((SECONDS - t0))
    cat "$log"
    local status="ok"
    if [ $rc -eq 124 ] || [ $rc -eq 137 ]; then status="TIMEOUT"; FAILED=1
    elif [ $rc -ne 0 ]; then status="FAILED (rc $rc)"; FAILED=1; fi
    # the result: pytest's summary line, else the last row of the last markdown table
    local result
    result=$(grep -E "^=+ .*(passed|failed|error|skipped).* =+$" "$log" | tail -1 | tr -d '=' \
             | sed 's/^ *//; s/ *$//')
    if [ -z "$result" ]; then
        result=$(grep -E '^\|' "$log" | grep -v -- '---' | tail -1 | tr '|' '/' \
                 | sed 's/^ *\/ *//; s/ *\/ *$//')
    fi
    [ -z "$result" ] && result=$(tail -1 "$log" | cut -c1-160 | tr '|' '/')
    ROWS+=("| $name | $status | $took | ${result:-} |")
}

if [ -z "$PY" ]; then
    step "venv and install .[dev]" 150 bash -c \
        "python3 -m venv $VENV && $VENV/bin/python -m pip install -q --upgrade pip \
         && $VENV/bin/python -m pip install -q -e '.[dev]'"
    PY="$VENV/bin/python"
fi
if ! "$PY" -c "import warp" >/dev/null 2>&1; then
    echo "gpu_check: $PY cannot import warp; nothing else can run"
    printf '%s\n' "| step | status | s | result |" "|---|---|---|---|" "${ROWS[@]}"
    exit 1
fi

DEVICE=$("$PY" -c "import warp as wp; wp.config.quiet = True; wp.init(); \
print('cuda:0' if wp.is_cuda_available() else 'cpu')" 2>/dev/null | tail -1)
GPU=$("$PY" -c "import warp as wp; wp.config.quiet = True; wp.init(); \
print(wp.get_device('cuda:0').name if wp.is_cuda_available() else 'none (CPU fallback)')" \
    2>/dev/null | tail -1)
echo "gpu_check: device $DEVICE, GPU: $GPU, sizes: $SIZES"

step "tests (not slow), $DEVICE" 150 "$PY" -m pytest -q -x -m "not slow" -p no:cacheprovider $TESTS
if [ "$DEVICE" = "cpu" ]; then
    ROWS+=("| CPU/CUDA agreement test | skipped: no GPU | 0 | |")
else
    step "CPU/CUDA agreement test" 60 "$PY" -m pytest -q -p no:cacheprovider \
        "tests/test_solver.py::test_cpu_and_cuda_agree_near_the_surface"
fi
for n in $SIZES; do
    step "one iteration at ${n}^3" 60 "$PY" benchmarks/bench_iteration.py --sizes "$n" \
        --repeats 1 --iterations 20 --numpy-repeats 1 --no-breakdown --device "$DEVICE"
    peers=""
    [ "$n" -gt 128 ] && peers="--no-peers"   # scikit-fmm: 80 s at 256^3, minutes at 512^3
    step "redistance at ${n}^3" 60 "$PY" benchmarks/bench_redistance.py --sizes "$n" \
        --repeats 1 --device "$DEVICE" $peers
    # the last row printed is the API run's stages: set-up, iterations, meshing, memory
    step "octant end to end (cli, api) at ${n}^3" 120 "$PY" benchmarks/bench_octant.py \
        --resolutions "$n" --repeats 1 --modes warm --runners cli api --device "$DEVICE"
done

echo
echo "## warpspec GPU check: device $DEVICE ($GPU), $(date -u '+%Y-%m-%d %H:%M UTC'), logs in $LOG_DIR"
echo
printf '%s\n' "| step | status | s | result |" "|---|---|---|---|" "${ROWS[@]}"
exit $FAILED
