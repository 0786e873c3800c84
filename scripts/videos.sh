#!/usr/bin/env bash
# Regenerates the sample clips in videos/: the TA-TL policy of each experiment on
# its target, with the source system beside it driven from the mapped state.
# Reuses a finished run (default runs/quick, made by scripts/quick.sh) and trains
# what it lacks at the smoke preset.
set -euo pipefail
cd "$(dirname "$0")/.."
RUN=${RUN:-runs/quick}
for spec in tasks/*.toml; do
  name=$(basename "$spec" .toml)
  .venv/bin/tatl render "$spec" --method ta-tl --seed 0 --run-dir "$RUN" --with-source \
      --seconds "${SECONDS_PER_CLIP:-6}" --width 480 --height 360 --fps 25 --out "videos/${name}_ta-tl.mp4"
done
ls -la videos/
