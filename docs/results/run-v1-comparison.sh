#!/usr/bin/env bash
# The SarSearch-v1 comparison of docs/results.md: HRL-SAC's five runs against the flat SAC's five runs, the scripted
# searchers and every constant goal under HRL-SAC's low level, on the 1,000 test scenarios, at 1 km (the task) and
# on the 2 km square (large-area.yaml), under the environment's rules and the mission runner's.
# From the project root, with the venv's hrlsac on PATH, after training the two sweeps:
#   hrlsac sweep docs/results/hrl-sac.sweep.yaml     # HRL-SAC, seeds 0-4 -> runs/hrl-sac
#   hrlsac sweep docs/results/sac.sweep.yaml         # flat SAC, seeds 0-4 -> runs/sac
# HRLDIR and SACDIR hold the run folders; OUT is the prefix of the four report folders.
set -euo pipefail
HRLDIR=${HRLDIR:-runs/hrl-sac}
SACDIR=${SACDIR:-runs/sac}
OUT=${OUT:-reports/v1}
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
    # TrackObject at every decision on the 2 km square
    hrlsac evaluate "$run" --split test --episodes 1000 --workers 2 --generator $LARGE --constant-goal TrackObject
    hrlsac evaluate "$run" --split test --episodes 1000 --workers 2 --generator $LARGE --constant-goal TrackObject \
        --flight-rules
done
hrlsac compare "${HRL[@]}" "${SAC[@]}" --out "$OUT-1km" --episodes 1000
hrlsac compare "${HRL[@]}" "${SAC[@]}" --out "$OUT-1km-runner-rules" --episodes 1000 --flight-rules
hrlsac compare "${HRL[@]}" "${SAC[@]}" --out "$OUT-2km" --episodes 1000 --generator $LARGE
hrlsac compare "${HRL[@]}" "${SAC[@]}" --out "$OUT-2km-runner-rules" --episodes 1000 --generator $LARGE --flight-rules
# per-seed figures and TrackObject at every decision, paired with the learned meta-controller
python docs/results/val_summary.py --split test "$SACDIR" "$HRLDIR" --out "$OUT-seeds-1km.json"
python docs/results/val_summary.py --split test --scenarios generator-large-area "$SACDIR" "$HRLDIR" \
    --out "$OUT-seeds-2km.json"
