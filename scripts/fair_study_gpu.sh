#!/usr/bin/env bash
# Issue 44's study on a lent GPU, in about 10 minutes of it: a3c, a3c+critic and a3c+foresit at
# Adam 3e-4 for 3x quick's budget (9000 updates) over 10 seeds, the three arms as three processes
# side by side (as docs/houses.md ran its study); then the three at the paper preset's learning
# rate 1e-4 (quick otherwise), for whatever time is left (each killed at its deadline keeps its
# checkpoints: continue with `python -m experiments.sweep --out DIR --resume`). Everything but the
# checkpoints is packed into $OUT/fair_gpu.tar.xz.
#
#   source scripts/device_env.sh && bash scripts/fair_study_gpu.sh   # on the device (it sets $OUT; carry .whl,
#                                                        # fetched here by scripts/device_wheels.sh)
#   PRESET=tiny SEEDS=2 UPDATES=4 LOW_LR_SECONDS=60 OUT=/tmp/x bash scripts/fair_study_gpu.sh   # a dry run on a CPU
set -uo pipefail
cd "$(dirname "$0")/.."
PRESET="${PRESET:-quick}"
SEEDS="${SEEDS:-10}"
UPDATES="${UPDATES:-9000}"
HIGH_LR_SECONDS="${HIGH_LR_SECONDS:-600}"  # the 3e-4 arms' deadline
LOW_LR_SECONDS="${LOW_LR_SECONDS:-180}"   # the 1e-4 arms' time: what is left of the 10 minutes (0: not run)
OUT="${OUT:?set OUT to the folder the results go to}"
RUNS="${RUNS:-runs/fair_gpu}"
ARMS=(a3c a3c+critic a3c+foresit)
export XLA_PYTHON_CLIENT_PREALLOCATE=false   # three processes share the GPU's memory
mkdir -p "$RUNS/logs" "$OUT"
python -c "import jax; print('devices:', jax.devices())" | tee "$RUNS/logs/devices.txt"

side_by_side() {  # side_by_side LR UPDATES_FLAG DEADLINE_SECONDS: the three arms at LR as three processes
    local lr="$1" updates="$2" deadline="$3" pids=()
    for arm in "${ARMS[@]}"; do
        timeout -k 20 "$deadline" python -m experiments.sweep --preset "$PRESET" --seeds "$SEEDS" $updates \
            --methods "$arm@learning_rate=$lr" --out "$RUNS/lr$lr/$arm" --no-progress \
            > "$RUNS/logs/lr${lr}_$arm.log" 2>&1 &
        pids+=($!)
    done
    for pid in "${pids[@]}"; do wait "$pid" || echo "an arm at $lr stopped early (see $RUNS/logs)"; done
}

start=$(date +%s)
side_by_side 3e-4 "--num-updates $UPDATES" "$HIGH_LR_SECONDS"
echo "3e-4 at 3x the budget: $(( $(date +%s) - start )) s"
# One table of the three (no training: --reuse combines the three sweeps), then the pairs.
python -m experiments.sweep --preset "$PRESET" --seeds "$SEEDS" --num-updates "$UPDATES" --no-progress \
    --methods "${ARMS[@]/%/@learning_rate=3e-4}" --out "$RUNS/lr3e-4_3x" \
    --reuse "$RUNS/lr3e-4/a3c" "$RUNS/lr3e-4/a3c+critic" "$RUNS/lr3e-4/a3c+foresit" > "$RUNS/logs/table_3x.log" 2>&1
python -m experiments.compare --run "$RUNS/lr3e-4_3x" --pairs "a3c@learning_rate=3e-4:a3c+foresit@learning_rate=3e-4" \
    "a3c@learning_rate=3e-4:a3c+critic@learning_rate=3e-4" "a3c+critic@learning_rate=3e-4:a3c+foresit@learning_rate=3e-4" \
    > "$RUNS/lr3e-4_3x/compare.md" 2>&1
[ "$LOW_LR_SECONDS" -gt 0 ] && side_by_side 1e-4 "" "$LOW_LR_SECONDS"
echo "total: $(( $(date +%s) - start )) s"
tar --exclude=checkpoints -cJf "$OUT/fair_gpu.tar.xz" "$RUNS"
ls -la "$OUT"
