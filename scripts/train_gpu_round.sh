#!/bin/bash
# A round of the bundled model (docs/model_card.md) on one GPU machine with many CPU cores: new
# synthetic scenes made on all cores, then the variants trained side by side on the one GPU from
# INIT, each exported (float16) and packed for the trip back:
# - heads: config/train_tiny_stage1_heads_gpu.yaml (round 13's setting, 16 clips per step);
# - joint: config/train_tiny_stage2_gpu.yaml (Stage II, whole geometry branch trainable).
# The machine is lent by the minute, so both phases are timed: every core makes scenes for GEN_S
# seconds (process p takes seeds FIRST_SEED + 1000 p upwards; runs/gpu_round/seeds.txt lists what
# was made), CALIB_STEPS steps of each variant side by side give the step times, and the step
# counts are set so that both runs take about 0.9 TRAIN_S seconds at those times (a run still going
# at 1.15 TRAIN_S + 30 s is stopped and its newest checkpoint exported). Outputs: runs/gpu_round/
# and, packed for the trip back, PACK_DIR (each export a tar split into 15 MiB parts, the logs).
# Usage: scripts/train_gpu_round.sh PACK_DIR FIRST_SEED GEN_S TRAIN_S
# CALIB_STEPS (default 30) sets the calibration's length, VARIANTS (default "heads joint") which
# variants run, INIT (default models/tiny_synthetic) the model they start from; CONFIG_<variant>
# and INIT_<variant> set one variant's config and start (a variant not named joint runs heads'
# config unless its CONFIG_ says otherwise). runs/gpu_round/ may hold an earlier call's scenes
# and exports (a second call on a machine still warm): the new scenes are added, every variant
# trains on all of them, and INIT_<variant> may name an earlier export. Runs without a checkout's
# .venv: PYTHON (default python3) needs torch, numpy, scipy, opencv, safetensors, pyyaml, tqdm
# and roma, with this repository on PYTHONPATH. Round 14 ran
#   scripts/train_gpu_round.sh $OUT 40000 100 270   (14a is its joint export), then
#   CALIB_STEPS=15 INIT=<14a's export> scripts/train_gpu_round.sh $OUT 60000 45 110   (14b: heads)
# and round 15 (the second call on the same machine, still warm)
#   VARIANTS="joint jointmask" CONFIG_jointmask=config/train_tiny_stage2_gpu_mask.yaml \
#     scripts/train_gpu_round.sh PACK 80000 90 370   (15a is its joint export), then
#   VARIANTS="heads headsmask" INIT_heads=runs/gpu_round/export_joint \
#     INIT_headsmask=runs/gpu_round/export_jointmask CALIB_STEPS=10 \
#     scripts/train_gpu_round.sh PACK 100000 15 125   (15b: heads)
# with PACK a folder tarred and split into $OUT afterwards (at most 8 files come back).
set -eo pipefail
cd "$(dirname "$0")/.."
PACK_DIR=$1 FIRST_SEED=$2 GEN_S=$3 TRAIN_S=$4
PYTHON=${PYTHON:-python3}
CALIB_STEPS=${CALIB_STEPS:-30}
VARIANTS=${VARIANTS:-heads joint}
INIT=${INIT:-models/tiny_synthetic}
WORK=runs/gpu_round
DATA=$WORK/synth_train_gpu
mkdir -p "$WORK" "$PACK_DIR"
stamp() { echo "[$(date +%T)] $*" | tee -a "$WORK/round.log"; }
config_of() {  # config_of VARIANT: its CONFIG_<VARIANT>, else joint's or heads' config
  local own="CONFIG_$1"
  if [ -n "${!own}" ]; then echo "${!own}"
  elif [ "$1" = joint ]; then echo config/train_tiny_stage2_gpu.yaml
  else echo config/train_tiny_stage1_heads_gpu.yaml; fi
}
init_of() {  # init_of VARIANT: its INIT_<VARIANT>, else INIT
  local own="INIT_$1"
  echo "${!own:-$INIT}"
}
train() {  # train NAME VARIANT STEPS SECONDS SEQUENCE...: from VARIANT's start, log $WORK/NAME.log
  local name=$1 variant=$2 steps=$3 seconds=$4
  shift 4
  timeout "$seconds" "$PYTHON" -m infinihand_ros.train --config "$(config_of "$variant")" \
    --output "$WORK/$name" --steps "$steps" --init "$(init_of "$variant")" --data "$@" \
    --no-progress > "$WORK/$name.log" 2>&1
}

stamp "generate for $GEN_S s on $(nproc) processes from seed $FIRST_SEED"
for p in $(seq 0 $(($(nproc) - 1))); do
  first=$((FIRST_SEED + 1000 * p))
  OMP_NUM_THREADS=1 timeout "$GEN_S" "$PYTHON" -m infinihand_ros.synth.batch --out "$DATA" \
    --seeds "$first" $((first + 999)) --frames 24 --fps 10 --width 224 --height 168 \
    > /dev/null 2>&1 &
done
generators=$(jobs -p)
# While the scenes are made: 2 steps of each variant on the first 8 finished ones, so that a run
# that cannot train on this machine stops here, not after the generation.
until [ "$(ls "$DATA"/seed_*/samples/meta.json 2>/dev/null | wc -l)" -ge 8 ]; do sleep 1; done
first_sequences=$(ls -d "$DATA"/seed_*/samples | sed -n 1,8p | xargs -n1 dirname)
for name in $VARIANTS; do
  # shellcheck disable=SC2086
  if ! train "sanity_$name" "$name" 2 3600 $first_sequences; then
    stamp "sanity run of $name failed: $WORK/sanity_$name.log"
    kill $generators 2>/dev/null || true
    cp "$WORK/sanity_$name.log" "$WORK/round.log" "$PACK_DIR/"
    exit 1
  fi
  stamp "sanity run of $name: $(tail -1 "$WORK/sanity_$name.log")"
done
wait $generators || true
find "$DATA" -mindepth 2 -maxdepth 2 -name '.*' -exec rm -rf {} +  # interrupted sequences
find "$DATA" -mindepth 1 -maxdepth 1 -type d -empty -delete
ls "$DATA" | sort -t_ -k2 -n > "$WORK/seeds.txt"
stamp "generated $(wc -l < "$WORK/seeds.txt") sequences"

stopped() {  # stopped NAME STATUS: note in NAME's log that its run ended early
  echo "$1: training stopped with status $2" >> "$WORK/$1.log"
}
steps_for() {  # steps_for VARIANT: steps of about 0.9 TRAIN_S s at the calibration's logged steps
  "$PYTHON" -c "import json, sys, yaml; \
records = [json.loads(line) for line in open(sys.argv[1])]; \
rates = [record['clips_per_s'] for record in records if record['step'] > 1]; \
clips = yaml.safe_load(open(sys.argv[2]))['train']['batch_size']; \
print(max(1, int(0.9 * float(sys.argv[3]) * sum(rates) / len(rates) / clips)))" \
    "$WORK/calib_$1/loss_log.jsonl" "$(config_of "$1")" "$TRAIN_S"
}
stamp "calibrate: $CALIB_STEPS steps of each of $VARIANTS side by side"
for name in $VARIANTS; do
  { train "calib_$name" "$name" "$CALIB_STEPS" 3600 "$DATA" || stopped "calib_$name" $?; } &
done
wait
limit=$((TRAIN_S * 115 / 100 + 30))
for name in $VARIANTS; do
  steps=$(steps_for "$name" || echo 300)  # 300: the calibration failed
  stamp "train $name ($steps steps)"
  { train "$name" "$name" "$steps" "$limit" "$DATA" || stopped "$name" $?; } &
done
wait
stamp "trained"
cp "$WORK/round.log" "$WORK/seeds.txt" "$PACK_DIR/"

for name in $VARIANTS; do
  checkpoint=$WORK/$name/checkpoints/final/model
  if [ ! -f "$checkpoint/model.safetensors" ]; then
    newest=$(ls -d "$WORK/$name"/checkpoints/step_* 2>/dev/null | tail -1)
    checkpoint=${newest:+$newest/model}
  fi
  if [ -n "$checkpoint" ]; then
    echo "$name: exporting $checkpoint" >> "$WORK/$name.log"
    "$PYTHON" -m infinihand_ros.model.io.export --checkpoint "$checkpoint" \
      --out "$WORK/export_$name" --train-sequences "$DATA" --overwrite >> "$WORK/$name.log" 2>&1 \
      && tar -C "$WORK" -cf - "export_$name" | split -b 15M - "$PACK_DIR/export_$name.tar.part-"
  fi
  cat "$WORK/calib_$name.log" "$WORK/$name.log" "$WORK/$name/loss_log.jsonl" \
    > "$PACK_DIR/$name.log" 2>/dev/null || true
done
stamp "packed into $PACK_DIR"
cp "$WORK/round.log" "$PACK_DIR/"
