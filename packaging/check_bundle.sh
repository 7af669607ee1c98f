#!/bin/sh
# Checks a built bundle's command line as a user meets it (build.sh runs it after the smoke
# test; a failure stops the build). In an empty environment the bundle simulates the default
# plot (seed 1), reconstructs it and evaluates it against the simulator's truth. It fails unless
#
# * every true plant is found and paired with its reconstruction (`fieldapp evaluate traits`);
# * pykdtree's queries run on the thread count asked, set in pykdtree's own libgomp (read back
#   in the `-v` log: a bundle that lost that library would fall back to OMP_NUM_THREADS
#   silently);
# * with the build venv's Python given, plants.csv is byte-identical to the same session
#   reconstructed from source.
#
#   packaging/check_bundle.sh APP [PYTHON]
#
# APP: the bundle folder (build/bundle/dist/fieldapp, or an unpacked archive's fieldapp/).
# PYTHON: the build venv's python (fieldapp installed); without it the source comparison is
# skipped and python3 reads the truth. About 20 s (19 s CPU) on the 2-core development machine.
set -eu

[ $# -ge 1 ] || { echo "usage: packaging/check_bundle.sh APP [PYTHON]" >&2; exit 2; }
APP=$(cd "$1" && pwd)
PYTHON=${2:-}
THREADS=2

fail() { echo "bundle check: $*" >&2; exit 1; }

CHECK=$(mktemp -d "${TMPDIR:-/tmp}/fieldapp-bundle-check.XXXXXX")
trap 'rm -rf "$CHECK"' EXIT
mkdir "$CHECK/home"

# run NAME COMMAND...: COMMAND in an empty environment (a fresh HOME, no venv, no
# PYTHONPATH), its output in $CHECK/NAME.log; the log's end and a failure if it fails.
run() {
    name=$1
    shift
    env -i HOME="$CHECK/home" PATH=/usr/bin:/bin LANG=C.UTF-8 \
        FIELDAPP_RECONSTRUCTION__THREADS=$THREADS "$@" > "$CHECK/$name.log" 2>&1 || {
        status=$?
        tail -n 20 "$CHECK/$name.log" >&2
        fail "$name failed (exit $status)"
    }
}

run simulate "$APP/fieldapp" simulate --out "$CHECK/session" --seed 1
run reconstruct "$APP/fieldapp" -v reconstruct "$CHECK/session" --out "$CHECK/bundle"
run evaluate "$APP/fieldapp" evaluate traits "$CHECK/bundle" --truth "$CHECK/session/truth.json"

simulated=$("${PYTHON:-python3}" -c 'import json, sys
print(len(json.load(open(sys.argv[1]))["plants"]))' "$CHECK/session/truth.json")
found=$(($(wc -l < "$CHECK/bundle/plants.csv") - 1))  # a header, then a row per plant
paired=$(sed -n 's/^height: n = \([0-9]*\),.*/\1/p' "$CHECK/evaluate.log")
[ "$found" = "$simulated" ] && [ "$paired" = "$simulated" ] ||
    fail "$found plants found, ${paired:-no} paired with the truth, of $simulated simulated"

# pykdtree's own OpenMP: filters._openmp_threads logs each libgomp with the count read back,
# filters._pykdtree_openmp the folder it looked in when it found none. The locked wheel brings
# its libgomp; a pykdtree built against the system's OpenMP (the build venv's says) has none.
omp=$(grep "pykdtree's OpenMP" "$CHECK/reconstruct.log" | sed 's/^DEBUG [^:]*: //' | sort -u)
[ -n "$omp" ] || fail "pykdtree's OpenMP: nothing logged by the bundle's reconstruction"
if [ -n "$PYTHON" ] && ! "$PYTHON" -c 'import pathlib, pykdtree, sys
sys.exit(not any((pathlib.Path(pykdtree.__file__).parents[1] / "pykdtree.libs").glob("libgomp*")))'
then
    echo "bundle check: the build venv's pykdtree has no libgomp of its own: $omp"
elif echo "$omp" | grep -q "no libgomp"; then
    fail "$omp (inside the bundle: pykdtree's own libgomp is not where filters.py looks)"
elif echo "$omp" | grep -qv " on $THREADS threads\$"; then
    fail "pykdtree's OpenMP inside the bundle not on the $THREADS threads asked: $omp"
fi

compared=""
if [ -n "$PYTHON" ]; then
    run source "$PYTHON" -m fieldapp reconstruct "$CHECK/session" --out "$CHECK/source"
    cmp "$CHECK/bundle/plants.csv" "$CHECK/source/plants.csv" >&2 ||
        fail "plants.csv differs between the bundle and the source ($PYTHON) on the same session"
    compared=", plants.csv byte-identical to the source's"
fi
echo "bundle check: $found/$simulated plants found and paired, $omp$compared"
