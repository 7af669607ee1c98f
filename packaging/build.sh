#!/bin/sh
# Builds the fieldapp bundle (``make bundle``): PyInstaller one-folder app in
# build/bundle/dist/fieldapp/ with the install files beside it, smoke-tests it, and packs it
# as build/bundle/fieldapp-<version>-linux-<arch>.tar.gz.
#
#   packaging/build.sh [PYTHON]      PYTHON: the venv's python with PyInstaller (.venv/bin/python)
#
# FIELDAPP_BUNDLE_TRIM=0 keeps open3d's plotly viewer stack (see fieldapp.spec).
# FIELDAPP_BUNDLE_SMOKE=0 skips the checks of the built bundle (smoke test, check_bundle.sh).
set -eu

PYTHON=${1:-.venv/bin/python}
ROOT=$(cd "$(dirname "$0")/.." && pwd)
OUT="$ROOT/build/bundle"
APP="$OUT/dist/fieldapp"
cd "$ROOT"

fail() { echo "bundle: $*" >&2; exit 1; }
now() { date +%s; }

[ -x "$PYTHON" ] || fail "no Python at $PYTHON (run 'make bundle', which creates the venv)"
"$PYTHON" -c 'import PyInstaller' 2>/dev/null ||
    fail "PyInstaller is missing: $PYTHON -m pip install -c requirements.lock -e '.[gui,bundle]'"
VERSION=$("$PYTHON" -c 'from importlib.metadata import version; print(version("fieldapp"))')
ARCH=$(uname -m)
ARCHIVE="$OUT/fieldapp-$VERSION-linux-$ARCH.tar.gz"

started=$(now)
echo "bundle: PyInstaller (a few minutes)..."
"$PYTHON" -m PyInstaller --noconfirm --log-level WARN \
    --distpath "$OUT/dist" --workpath "$OUT/work" packaging/fieldapp.spec
built=$(now)

# What install.sh needs, at the same relative paths as in packaging/.
cp packaging/install.sh packaging/README.md packaging/fieldapp.desktop "$APP/"
rm -rf "$APP/icons" "$APP/udev"
cp -R packaging/icons packaging/udev "$APP/"
echo "$VERSION" > "$APP/VERSION"
{
    echo "fieldapp $VERSION, built $(date -u +%Y-%m-%dT%H:%M:%SZ) on $(uname -sm)"
    # read back by fieldapp/provenance.py: each result's provenance names the bundle's commit
    echo "commit $(git rev-parse --short=12 HEAD 2>/dev/null || echo unknown)$(
        git status --porcelain --untracked-files=no 2>/dev/null | grep -q . && echo ' modified')"
    "$PYTHON" -c 'from importlib.util import find_spec as f; print("camera backends: sim, replay" + "".join(", " + b for m, b in (("pylibfreenect2", "kinect2"), ("pyrealsense2", "realsense")) if f(m)))'
} > "$APP/BUILD-INFO"
chmod 755 "$APP/install.sh" "$APP/fieldapp"

if [ "${FIELDAPP_BUNDLE_SMOKE:-1}" != 0 ]; then
    echo "bundle: smoke test of the built bundle..."
    smoke_started=$(now)
    env -u DISPLAY -u WAYLAND_DISPLAY QT_QPA_PLATFORM=offscreen "$APP/fieldapp" --smoke-test ||
        fail "the built bundle failed its smoke test (see above)"
    echo "bundle: smoke test passed in $(( $(now) - smoke_started )) s (start-up included)"
    echo "bundle: the command line of the built bundle: simulate, reconstruct, evaluate..."
    check_started=$(now)
    sh packaging/check_bundle.sh "$APP" "$PYTHON" ||
        fail "the built bundle failed its command-line check (see above)"
    echo "bundle: command-line check passed in $(( $(now) - check_started )) s"
fi

echo "bundle: packing $(basename "$ARCHIVE")..."
rm -f "$ARCHIVE"
tar -C "$OUT/dist" -czf "$ARCHIVE.part" fieldapp
mv "$ARCHIVE.part" "$ARCHIVE"

echo "bundle: $APP ($(du -sh "$APP" | cut -f1)), $ARCHIVE ($(du -sh "$ARCHIVE" | cut -f1))"
echo "bundle: PyInstaller $(( built - started )) s, everything $(( $(now) - started )) s"
echo "bundle: install with: tar -xzf $(basename "$ARCHIVE") && sudo fieldapp/install.sh"
