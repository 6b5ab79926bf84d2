#!/usr/bin/env bash
# Regenerates the committed example report in reports/example/ from a fresh clone:
#   python3 -m venv .venv && .venv/bin/pip install -e '.[test]' && PATH=.venv/bin:$PATH bash reports/example/regenerate.sh
# Takes about 2 minutes on 2 cores. Problems: the bundled ones plus 2 small problems of each
# scene (seed 1); every method at 1e-8, 1e-9, 1e-10; trajectories at 1e-14; the 10-digit path
# and its certified reference for every problem (all have ≤ 60 contacts).
set -euo pipefail
cd "$(dirname "$0")"
rm -rf problems run
for spec in SpheresPile:16 Chute:30 PrimitiveSoup:24 MassRatio:12 RollingExtremes:12 Frictionless:12 \
            Lattice:12 AllOpen:12 AllSticking:12 Millimetre:12; do
    rfverify generate "${spec%%:*}" --count 2 --seed 1 --size "${spec##*:}" --out problems/scenes --quiet
done
rfverify bench bundled problems/scenes --out run --jobs 2 --quiet
rfverify report run --quiet
