#!/usr/bin/env bash
# Issue #22's comparison v2-hrl (docs/results/README.md, "comparison-v2-hrl"): HRL-SAC re-tuned on val (a joint phase
# of 80,000 steps) against comparison-v2's flat SAC (n-step 3), the scripted searchers and every constant goal under
# the new low level. From the project root, with the venv's hrlsac on PATH. V2 holds comparison-v2's flat SAC run
# folders (docs/results/comparison-v2.sh), V2HRL gets the new HRL-SAC ones.
set -euo pipefail
V2=${V2:-runs/comparison-v2}
V2HRL=${V2HRL:-runs/comparison-v2-hrl}
# Seeds 0-2 are probes k2, k2s1 and k2s2 (the same settings and seeds), copied in before the sweep.
hrlsac sweep docs/results/comparison-v2-hrl.sweep.yaml --out "$V2HRL"
HRL=("$V2HRL"/hrl-sac-default-seed{0,1,2,3,4})
SAC=("$V2"/sac-default-seed{0,1,2,3,4})   # evaluated on test by comparison-v2.sh
LARGE=docs/results/large-area.yaml
for run in "${HRL[@]}"; do
    for scenarios in "" "--generator $LARGE"; do
        hrlsac evaluate "$run" --split test --episodes 1000 $scenarios                  # the environment's rules
        hrlsac evaluate "$run" --split test --episodes 1000 $scenarios --flight-rules   # the mission runner's rules
    done
    for goal in ExploreArea SearchSpecificLocation TrackObject ReturnToBase; do   # constant goals, 1 km
        hrlsac evaluate "$run" --split test --episodes 1000 --constant-goal $goal
        hrlsac evaluate "$run" --split test --episodes 1000 --constant-goal $goal --flight-rules
    done
done
OUT=docs/results/comparison-v2-hrl
hrlsac compare "${HRL[@]}" "${SAC[@]}" --out $OUT --episodes 1000
hrlsac compare "${HRL[@]}" "${SAC[@]}" --out $OUT-flight --episodes 1000 --flight-rules
hrlsac compare "${HRL[@]}" "${SAC[@]}" --out $OUT-large --episodes 1000 --generator $LARGE
hrlsac compare "${HRL[@]}" "${SAC[@]}" --out $OUT-large-flight --episodes 1000 --generator $LARGE --flight-rules
