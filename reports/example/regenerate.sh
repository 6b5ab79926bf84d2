#!/usr/bin/env bash
# Regenerates the committed example report in reports/example/ from a fresh clone:
#   python3 -m venv .venv && .venv/bin/pip install -e '.[test]' && PATH=.venv/bin:$PATH bash reports/example/regenerate.sh
# Takes about 2 minutes on 2 cores. Problems: the bundled ones plus 2 small problems of each
# scene (seed 1); every method at 1e-8, 1e-9, 1e-10; trajectories at 1e-14; the 10-digit path
# and its certified reference for every problem (all have ≤ 60 contacts).
#
#   bash reports/example/regenerate.sh --scenes   regenerates only the scene files (seconds)
#
# The scene files are bit-for-bit reproducible (`rfverify generate --help`, "Reproducibility"):
# with the rfverify that wrote them, they come out identical and `git status` stays clean.
# A change to the solver that changes any of its results changes them (the scenes are
# simulated with rfverify.solve); the script then says so, and the new files belong in the same
# commit as that solver change (with a regenerated report, whose records are keyed on them).
set -euo pipefail
cd "$(dirname "$0")"
if ! command -v rfverify >/dev/null; then
    echo "regenerate.sh: rfverify is not on PATH (nothing changed); fix: PATH=\$PWD/.venv/bin:\$PATH bash $0" >&2
    exit 2
fi
rm -rf problems
for spec in SpheresPile:16 Chute:30 PrimitiveSoup:24 MassRatio:12 RollingExtremes:12 Frictionless:12 \
            Lattice:12 AllOpen:12 AllSticking:12 Millimetre:12; do
    rfverify generate "${spec%%:*}" --count 2 --seed 1 --size "${spec##*:}" --out problems/scenes --quiet
done
if git rev-parse --is-inside-work-tree >/dev/null 2>&1; then
    changed=$(git status --porcelain -- problems | wc -l)
    if [ "$changed" -eq 0 ]; then
        echo "regenerate.sh: the scene files are identical to the committed ones" >&2
    else
        echo "regenerate.sh: $changed scene file(s) differ from the committed ones: this rfverify" \
             "(its solver) or its numpy/scipy/QDLDL differs from the one that wrote them (see" \
             "'rfverify generate --help', Reproducibility); commit them with the report" >&2
    fi
fi
if [ "${1:-}" = "--scenes" ]; then
    exit 0
fi
rm -rf run
# In a fresh clone the first k-digit path in each back end compiles its double-double kernels
# (numba, minutes, cached beside the sources); compile them all once here, so that no path time
# in the report includes the compilation.
py="$(dirname "$(command -v rfverify)")/python"
[ -x "$py" ] || py=python3
"$py" -c 'import rfverify
p = rfverify.load("bundled:chute")  # a global problem: every back end applies (a local one has no dofs)
for backend in ("dof", "contact", "hybrid"):
    rfverify.solve_to_digits(p, digits=10, backend=backend)'
rfverify bench bundled problems/scenes --out run --jobs 2 --quiet
rfverify report run --quiet
