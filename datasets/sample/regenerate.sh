#!/usr/bin/env bash
# Regenerates the sample dataset byte for byte from the simulator: bash datasets/sample/regenerate.sh
# (run from anywhere, with doorbatch installed). Seeds and scenarios are fixed here.
set -euo pipefail
cd "$(dirname "$0")"
rm -rf logs worlds
mkdir -p logs worlds
cp ../../configs/worlds/office_corridor.yaml worlds/office_corridor.yaml

# Mapping run: one simulated log of three passes, cut into one log per pass (doorbatch map takes one log
# per pass); the whole log is dropped, its truth file (world, doors, angles over time) stays.
doorbatch simulate worlds/office_corridor.yaml -o logs/map.mcap --scenario scenarios/mapping.yaml --seed 1 \
  --split-passes -q
rm logs/map.mcap

seed=11
for doors in closed open partial; do
  doorbatch simulate worlds/office_corridor.yaml -o "logs/loc_${doors}.mcap" --scenario "scenarios/loc_${doors}.yaml" \
    --seed "$seed" -q
  seed=$((seed + 1))
done
