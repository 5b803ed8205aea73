#!/usr/bin/env bash
# Issue 48's study in rooms with priors (docs/priors.md) on a lent GPU, in about 10 minutes of
# it, 10 seeds at quick's budget. First savn: a3c (1e-3), a3c+critic and a3c+foresit (3e-4), each
# at the rate issue 44's tune validated on today's rooms (not re-validated with priors). Then
# org: a3c+org and a3c+org+foresit at quick's 1e-3 (the rate issue 44's org tune chose for both). The arms of a setup run
# as processes side by side (as docs/houses.md ran its study), then one table per setup
# (--reuse, no training) and its pairs. An arm killed at its deadline keeps its checkpoints:
# continue it with `python -m experiments.sweep --out DIR --resume`. Everything but the
# checkpoints is packed into $OUT/priors_gpu.tar.xz.
#
#   source scripts/device_env.sh && bash scripts/priors_study_gpu.sh   # on the device (it sets $OUT; carry .whl,
#                                                        # fetched here by scripts/device_wheels.sh)
#   PRESET=tiny SEEDS=2 UPDATES=4 OUT=/tmp/x bash scripts/priors_study_gpu.sh   # a dry run on a CPU
set -uo pipefail
cd "$(dirname "$0")/.."
PRESET="${PRESET:-quick}"
SEEDS="${SEEDS:-10}"
UPDATES="${UPDATES:-3000}"
SAVN_SECONDS="${SAVN_SECONDS:-330}"
ORG_SECONDS="${ORG_SECONDS:-210}"
OUT="${OUT:?set OUT to the folder the results go to}"
RUNS="${RUNS:-runs/priors_gpu}"
SAVN_ARMS=(a3c a3c+critic@learning_rate=3e-4 a3c+foresit@learning_rate=3e-4)
ORG_ARMS=(a3c+org a3c+org+foresit)
export XLA_PYTHON_CLIENT_PREALLOCATE=false   # the arms' processes share the GPU's memory
mkdir -p "$RUNS/logs" "$OUT"
python -c "import jax; print('devices:', jax.devices())" | tee "$RUNS/logs/devices.txt"

study() {  # study SETUP DEADLINE_SECONDS ARM...: the arms side by side, then their table and pairs
    local setup="$1" deadline="$2" pids=() folders=()
    shift 2
    for arm in "$@"; do
        timeout -k 20 "$deadline" python -m experiments.sweep --setup "$setup" --priors True --preset "$PRESET" \
            --seeds "$SEEDS" --num-updates "$UPDATES" --methods "$arm" --out "$RUNS/$setup/$arm" --no-progress \
            > "$RUNS/logs/${setup}_$arm.log" 2>&1 &
        pids+=($!)
        folders+=("$RUNS/$setup/$arm")
    done
    for pid in "${pids[@]}"; do wait "$pid" || echo "an arm of $setup stopped early (see $RUNS/logs)"; done
    python -m experiments.sweep --setup "$setup" --priors True --preset "$PRESET" --seeds "$SEEDS" \
        --num-updates "$UPDATES" --methods "$@" --out "$RUNS/${setup}_all" --reuse "${folders[@]}" --no-progress \
        > "$RUNS/logs/${setup}_table.log" 2>&1 || echo "the $setup table needs every arm finished (see $RUNS/logs)"
    local pairs=()
    for arm in "${@:2}"; do pairs+=("$1:$arm"); done
    [ $# -gt 2 ] && pairs+=("$2:$3")
    python -m experiments.compare --run "$RUNS/${setup}_all" --pairs "${pairs[@]}" > "$RUNS/${setup}_all/compare.md" 2>&1
}

start=$(date +%s)
study savn "$SAVN_SECONDS" "${SAVN_ARMS[@]}"
echo "savn: $(( $(date +%s) - start )) s"
study org "$ORG_SECONDS" "${ORG_ARMS[@]}"
echo "total: $(( $(date +%s) - start )) s"
tar --exclude=checkpoints -cJf "$OUT/priors_gpu.tar.xz" "$RUNS"
ls -la "$OUT"
