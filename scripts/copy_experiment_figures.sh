#!/usr/bin/env bash
# Copy the results of `activebonds reproduce NAME --scale paper --out OUT` into docs/figures/DEST
# (summary, per-series results, best models, convergence and weight figures, one animation).
# usage: scripts/copy_experiment_figures.sh OUT/NAME docs/figures/DEST [CONFIG whose animation to keep]
set -euo pipefail
src="$1"; dest="$2"; anim="${3:-}"
rm -rf "$dest"; mkdir -p "$dest"
cp "$src/summary.json" "$dest/"
for cfg in "$src"/*/; do
  name="$(basename "$cfg")"
  mkdir -p "$dest/$name"
  cp "$cfg"/standard.json "$cfg"/neural.json "$cfg"/best_standard.toml "$cfg"/best_neural.toml "$dest/$name/"
  cp "$cfg/figures/convergence.png" "$dest/$name-convergence.png"
  cp "$cfg/figures/neural_weights.png" "$dest/$name-neural-weights.png"
  if [ "$name" = "$anim" ]; then cp "$cfg/figures/animation.gif" "$dest/$name-animation.gif"; fi
done
