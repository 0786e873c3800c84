#!/usr/bin/env bash
# The main job at the quick preset: sets up (scripts/setup.sh), runs the five
# transfer experiments of the paper at the quick preset (one seed), draws
# the figures and the results table, and renders one clip. Rerunning resumes.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
OUT=${OUT:-runs/quick}
.venv/bin/tatl run tasks/*.toml --preset quick --out "$OUT"
# The figures and the clip are independent: drawn side by side, on the two cores.
.venv/bin/tatl plot "$OUT" &
plot=$!
.venv/bin/tatl render tasks/cartpole_to_bicycle.toml --method ta-tl-h --preset quick --seed 0 --run-dir "$OUT" \
    --seconds 4 --fps 20 --out "$OUT/cartpole_to_bicycle_ta-tl-h.mp4"
wait "$plot"
echo "done: $OUT/results.md, $OUT/figures/*.png, $OUT/cartpole_to_bicycle_ta-tl-h.mp4"
