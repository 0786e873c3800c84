#!/usr/bin/env bash
# Regenerates the sample clips in videos/ from a finished run (default
# runs/paper, made by the README's paper-preset command; what a run lacks is
# trained at the smoke preset): for each experiment, the paper's TA-TL and the
# extension that works there, on the target with the source beside it driven
# from the mapped state.
set -euo pipefail
cd "$(dirname "$0")/.."
RUN=${RUN:-runs/paper}
PRESET=${PRESET:-paper}
clip() {  # spec method seconds
  local name; name=$(basename "$1" .toml)
  .venv/bin/tatl render "$1" --method "$2" --seed 0 --run-dir "$RUN" --preset "$PRESET" --with-source \
      --seconds "$3" --width 480 --height 360 --fps 25 --out "videos/${name}_$2.mp4"
}
for spec in tasks/*.toml; do clip "$spec" ta-tl "${SECONDS_PER_CLIP:-6}"; done
clip tasks/grid_to_windy.toml ta-tl-replan "${SECONDS_PER_CLIP:-6}"
clip tasks/variants/cartpole_to_bicycle_affine.toml ta-tl-h 25
clip tasks/variants/mc_to_ip_energy.toml ta-tl "${SECONDS_PER_CLIP:-6}"
ls -la videos/
