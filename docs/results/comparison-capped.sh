#!/usr/bin/env bash
# Issue #22's comparison in the capped environment (docs/results/README.md, "comparison-capped"): HRL-SAC
# (comparison-v2-hrl-capped's five runs) against the flat SAC chosen on val (SAC below), the scripted searchers and
# every constant goal under HRL-SAC's low level, on the 1,000 test scenarios, once. From the project root, with the
# venv's hrlsac on PATH; HRLDIR and SACDIR hold the run folders of the two sweeps
# (docs/results/comparison-v2-hrl-capped.sweep.yaml, and the flat SAC sweep the README section chose).
set -euo pipefail
HRLDIR=${HRLDIR:-runs/comparison-v2-hrl-capped}
SACDIR=${SACDIR:-runs/comparison-capped-sac}
HRL=("$HRLDIR"/hrl-sac-default-seed{0,1,2,3,4})
SAC=("$SACDIR"/sac-default-seed{0,1,2,3,4})
LARGE=docs/results/large-area.yaml
for run in "${HRL[@]}" "${SAC[@]}"; do
    for scenarios in "" "--generator $LARGE"; do
        hrlsac evaluate "$run" --split test --episodes 1000 --workers 2 $scenarios                 # environment's rules
        hrlsac evaluate "$run" --split test --episodes 1000 --workers 2 $scenarios --flight-rules  # the runner's rules
    done
done
for run in "${HRL[@]}"; do
    for goal in ExploreArea SearchSpecificLocation TrackObject ReturnToBase; do   # constant goals, 1 km
        hrlsac evaluate "$run" --split test --episodes 1000 --workers 2 --constant-goal $goal
        hrlsac evaluate "$run" --split test --episodes 1000 --workers 2 --constant-goal $goal --flight-rules
    done
done
OUT=${OUT:-docs/results/comparison-capped}  # comparison-avx2 sets its own (docs/results/README.md)
hrlsac compare "${HRL[@]}" "${SAC[@]}" --out $OUT --episodes 1000
hrlsac compare "${HRL[@]}" "${SAC[@]}" --out $OUT-flight --episodes 1000 --flight-rules
hrlsac compare "${HRL[@]}" "${SAC[@]}" --out $OUT-large --episodes 1000 --generator $LARGE
hrlsac compare "${HRL[@]}" "${SAC[@]}" --out $OUT-large-flight --episodes 1000 --generator $LARGE --flight-rules
