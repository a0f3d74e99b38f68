#!/usr/bin/env bash
# Issue #22's comparison on SarSearch-v1, end to end (from the project root, with the venv's hrlsac on PATH).
# Training: about 20 minutes (HRL-SAC) and 45 minutes (flat SAC) on 2 cores; the evaluations and the four reports
# about an hour (each report flies the scripted searchers again).
# RUNS is where the run folders go (outside the checkout here: /work/runs/comparison-v1).
set -euo pipefail
RUNS=${RUNS:-runs/comparison-v1}
hrlsac sweep docs/results/comparison-v1-hrl.sweep.yaml --out "$RUNS"
hrlsac sweep docs/results/comparison-v1-sac.sweep.yaml --out "$RUNS"
HRL=("$RUNS"/hrl-sac-default-seed{0,1,2,3,4})
SAC=("$RUNS"/sac-default-seed{0,1,2,3,4})
LARGE=docs/results/large-area.yaml
for run in "${HRL[@]}" "${SAC[@]}"; do
    for scenarios in "" "--generator $LARGE"; do
        hrlsac evaluate "$run" --split test --episodes 1000 $scenarios                  # the environment's rules
        hrlsac evaluate "$run" --split test --episodes 1000 $scenarios --flight-rules   # the mission runner's rules
    done
done
for run in "${HRL[@]}"; do  # every constant goal under each run's learned low level (the test split only)
    for goal in ExploreArea SearchSpecificLocation TrackObject ReturnToBase; do
        hrlsac evaluate "$run" --split test --episodes 1000 --constant-goal $goal
        hrlsac evaluate "$run" --split test --episodes 1000 --constant-goal $goal --flight-rules
    done
done
hrlsac compare "${HRL[@]}" "${SAC[@]}" --out docs/results/comparison-v1 --episodes 1000
hrlsac compare "${HRL[@]}" "${SAC[@]}" --out docs/results/comparison-v1-flight --episodes 1000 --flight-rules
hrlsac compare "${HRL[@]}" "${SAC[@]}" --out docs/results/comparison-v1-large --episodes 1000 --generator $LARGE
hrlsac compare "${HRL[@]}" "${SAC[@]}" --out docs/results/comparison-v1-large-flight --episodes 1000 \
    --generator $LARGE --flight-rules
