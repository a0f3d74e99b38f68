#!/usr/bin/env bash
# Issue #22's comparison v2 (docs/results/README.md, "comparison-v2"): the flat SAC re-tuned with n-step returns,
# beside comparison-v1's HRL-SAC runs and scripted searchers (unchanged). From the project root, with the venv's
# hrlsac on PATH. V1 holds comparison-v1's run folders (docs/results/comparison-v1.sh), V2 gets the new ones.
set -euo pipefail
V1=${V1:-runs/comparison-v1}
V2=${V2:-runs/comparison-v2}
# Seed 0 is probe fC (the same settings and seed), copied in before the sweep; without it the sweep trains it.
hrlsac sweep docs/results/comparison-v2-sac.sweep.yaml --out "$V2"
LARGE=docs/results/large-area.yaml
for run in "$V2"/sac-default-seed{0,1,2,3,4}; do
    for scenarios in "" "--generator $LARGE"; do
        hrlsac evaluate "$run" --split test --episodes 1000 $scenarios
        hrlsac evaluate "$run" --split test --episodes 1000 $scenarios --flight-rules
    done
done
python docs/results/comparison_v2.py "$V1" "$V2"
