#!/bin/bash
# Reproduce the bundled model models/tiny_synthetic on a CPU from its recipe
# (models/tiny_synthetic/recipe.yaml: training sets and their seeds, the training stages in order
# with their settings, steps and starting checkpoints, the export and the evaluations).
# Every step resumes: run it again after an interruption and it continues where it stopped.
# Outputs go to runs/ (ignored by git); the export is runs/tiny_synthetic, the evaluation
# reports runs/eval_*.md.
# Usage: scripts/train_embedded_model.sh [--dry-run] [--jobs N] [--runs DIR] [RECIPE]
set -eo pipefail
cd "$(dirname "$0")/.."
source scripts/env.sh
recipe=models/tiny_synthetic/recipe.yaml
args=()
for arg in "$@"; do
  case "$arg" in
    *.yaml) recipe=$arg ;;
    *) args+=("$arg") ;;
  esac
done
exec python -m infinihand_ros.train.recipe_runner "$recipe" "${args[@]}"
