#!/bin/sh
# Installs the fieldapp bundle on a Linux field laptop: the app folder, a `fieldapp` command,
# the desktop menu entry and icon, and (as root) the udev rules for the Kinect v2 and the
# table's USB-serial controller. Safe to run again (an upgrade replaces the app folder and
# keeps every setting, calibration, session and result: they live in the user's folders).
#
#   sudo ./install.sh                  everyone: /opt/fieldapp, /usr/local, /etc/udev/rules.d
#   ./install.sh                       this user: ~/.local (udev rules: says how)
#   sudo ./install.sh --add-groups     also add the user to dialout and plugdev
#   ./install.sh --dry-run             print what it would do, change nothing
#   sudo ./install.sh --uninstall      remove it again (your data stays)
#
# Run it from the unpacked bundle (fieldapp/install.sh), or from a source tree as
# packaging/install.sh (the bundle is then build/bundle/dist/fieldapp, see --bundle).
set -eu

HERE=$(cd "$(dirname "$0")" && pwd)
PROG=install.sh
APP_NAME=fieldapp

usage() {
    cat <<EOF
usage: $PROG [--user | --system] [--prefix DIR] [--root DIR] [--bundle DIR]
             [--add-groups] [--no-udev] [--uninstall] [--dry-run]

  --system       install for everyone: /opt/fieldapp, /usr/local/bin, /usr/local/share,
                 /etc/udev/rules.d (the default when run as root)
  --user         install for this user: ~/.local/lib/fieldapp, ~/.local/bin,
                 ~/.local/share (the default otherwise)
  --prefix DIR   the app folder (default /opt/fieldapp or ~/.local/lib/fieldapp)
  --root DIR     put every file under DIR instead of / (staging, tests): the udev rules
                 too, without root; this machine's udev and groups are left alone
  --bundle DIR   the built app folder to install (default: this script's folder when it
                 holds the bundle, else build/bundle/dist/fieldapp of the source tree)
  --add-groups   add the user (\$SUDO_USER when run with sudo) to dialout and plugdev
  --no-udev      do not install the udev rules
  --uninstall    remove what the install put in place (your data is kept)
  --dry-run      print what would be done and change nothing
EOF
}

say() {  # what was done (under --dry-run: what would be)
    if [ "${DRY_RUN:-0}" = 1 ]; then echo "$PROG: [dry run] $*"; else echo "$PROG: $*"; fi
}
fail() { echo "$PROG: error: $*" >&2; exit 1; }

# --- options ----------------------------------------------------------------------------------

MODE=""
PREFIX=""
ROOT=""
BUNDLE=""
ADD_GROUPS=0
UDEV=1
UNINSTALL=0
DRY_RUN=0
while [ $# -gt 0 ]; do
    case $1 in
        --system) MODE=system ;;
        --user) MODE=user ;;
        --prefix) [ $# -ge 2 ] || fail "--prefix needs a folder"; PREFIX=$2; shift ;;
        --prefix=*) PREFIX=${1#*=} ;;
        --root) [ $# -ge 2 ] || fail "--root needs a folder"; ROOT=$2; shift ;;
        --root=*) ROOT=${1#*=} ;;
        --bundle) [ $# -ge 2 ] || fail "--bundle needs a folder"; BUNDLE=$2; shift ;;
        --bundle=*) BUNDLE=${1#*=} ;;
        --add-groups) ADD_GROUPS=1 ;;
        --no-udev) UDEV=0 ;;
        --uninstall) UNINSTALL=1 ;;
        --dry-run|-n) DRY_RUN=1 ;;
        -h|--help) usage; exit 0 ;;
        *) usage >&2; fail "unknown option: $1" ;;
    esac
    shift
done

IS_ROOT=0
[ "$(id -u)" = 0 ] && IS_ROOT=1
[ -n "$MODE" ] || { [ $IS_ROOT = 1 ] && MODE=system || MODE=user; }
case $ROOT in
    "" | /) ROOT="" ;;
    /*) ROOT=${ROOT%/} ;;
    *) fail "--root must be an absolute path: $ROOT" ;;
esac
LIVE=1  # changing this machine's udev and groups
[ -n "$ROOT" ] && LIVE=0
TARGET_USER=${SUDO_USER:-$(id -un)}

if [ $MODE = system ]; then
    APP_DIR=${PREFIX:-/opt/$APP_NAME}
    BIN_DIR=/usr/local/bin
    SHARE_DIR=/usr/local/share
else
    [ -n "${HOME:-}" ] || fail "HOME is not set"
    APP_DIR=${PREFIX:-$HOME/.local/lib/$APP_NAME}
    BIN_DIR=$HOME/.local/bin
    SHARE_DIR=${XDG_DATA_HOME:-$HOME/.local/share}
fi
case $APP_DIR in
    /*) APP_DIR=${APP_DIR%/} ;;
    *) fail "--prefix must be an absolute path: $APP_DIR" ;;
esac
case $APP_DIR in
    "" | / | /usr | /usr/local | /opt | /etc | /home | "${HOME:-/}") fail "refusing to use $APP_DIR as the app folder" ;;
esac
UDEV_DIR=/etc/udev/rules.d
DESKTOP_FILE=$SHARE_DIR/applications/$APP_NAME.desktop
ICON_DIR=$SHARE_DIR/icons/hicolor
UDEV_RULES="60-fieldapp-kinect2.rules 61-fieldapp-serial.rules"
MARKER=.fieldapp-install

# --- doing, or saying what would be done ------------------------------------------------------

run() {  # run COMMAND...: print it; run it unless --dry-run
    if [ $DRY_RUN = 1 ]; then
        echo "would run: $*"
    else
        "$@"
    fi
}

dest() { echo "$ROOT$1"; }  # where a file of the installed system lands

is_bundle() { [ -x "$1/$APP_NAME" ] && [ -d "$1/_internal" ]; }

find_bundle() {
    if [ -n "$BUNDLE" ]; then
        [ -d "$BUNDLE" ] || fail "--bundle: no folder $BUNDLE"
        BUNDLE=$(cd "$BUNDLE" && pwd)
    elif is_bundle "$HERE"; then
        BUNDLE=$HERE
    else
        BUNDLE=$(cd "$HERE/.." && pwd)/build/bundle/dist/$APP_NAME
    fi
    is_bundle "$BUNDLE" || fail "no built bundle in $BUNDLE (build it with 'make bundle', or give --bundle DIR)"
    for file in fieldapp.desktop icons/fieldapp.svg udev/60-fieldapp-kinect2.rules; do
        [ -f "$HERE/$file" ] || fail "$HERE/$file is missing: run the install.sh that came with the bundle"
    done
}

owned_or_absent() {  # the folder is ours to replace or remove (never an arbitrary folder)
    [ ! -e "$1" ] || [ -f "$1/$MARKER" ] || { is_bundle "$1" && [ -f "$1/VERSION" ]; }
}

# --- install ----------------------------------------------------------------------------------

install_app() {
    app=$(dest "$APP_DIR")
    version=$(cat "$BUNDLE/VERSION" 2>/dev/null || echo unknown)
    if [ "$BUNDLE" = "$app" ]; then
        say "app: already in place in $app"
        return
    fi
    owned_or_absent "$app" || fail "$app exists and is not a fieldapp install; choose another --prefix"
    run mkdir -p "$(dirname "$app")"
    run rm -rf "$app.new" "$app.old"
    run cp -R "$BUNDLE" "$app.new"
    if [ $DRY_RUN = 0 ]; then
        echo "fieldapp $version, installed $(date +%Y-%m-%dT%H:%M:%S) from $BUNDLE" > "$app.new/$MARKER"
    fi
    [ -e "$app" ] && run mv "$app" "$app.old"
    run mv "$app.new" "$app"
    run rm -rf "$app.old"
    say "app: fieldapp $version in $app"
}

install_command() {
    bin=$(dest "$BIN_DIR")
    run mkdir -p "$bin"
    run ln -sfn "$APP_DIR/$APP_NAME" "$bin/$APP_NAME"
    say "command: $bin/$APP_NAME -> $APP_DIR/$APP_NAME"
    case ":${PATH:-}:" in
        *":$BIN_DIR:"*) ;;
        *) say "note: $BIN_DIR is not on your PATH; add it, or run $APP_DIR/$APP_NAME" ;;
    esac
}

install_desktop_entry() {
    desktop=$(dest "$DESKTOP_FILE")
    run mkdir -p "$(dirname "$desktop")"
    if [ $DRY_RUN = 1 ]; then
        echo "would write: $desktop (Exec=\"$APP_DIR/$APP_NAME\" gui)"
    else
        sed -e "s|^Exec=$APP_NAME |Exec=\"$APP_DIR/$APP_NAME\" |" \
            -e "s|^TryExec=$APP_NAME\$|TryExec=$APP_DIR/$APP_NAME|" \
            "$HERE/fieldapp.desktop" > "$desktop.part"
        chmod 644 "$desktop.part"
        mv "$desktop.part" "$desktop"
    fi
    say "menu entry: $desktop"
    icons=$(dest "$ICON_DIR")
    run mkdir -p "$icons/scalable/apps"
    run cp "$HERE/icons/fieldapp.svg" "$icons/scalable/apps/$APP_NAME.svg"
    for png in "$HERE"/icons/hicolor/*/apps/fieldapp.png; do
        [ -f "$png" ] || continue
        size=$(basename "$(dirname "$(dirname "$png")")")
        run mkdir -p "$icons/$size/apps"
        run cp "$png" "$icons/$size/apps/$APP_NAME.png"
    done
    say "icon: $icons/{scalable,48x48,128x128,256x256}/apps/"
    [ $LIVE = 1 ] || return 0
    if command -v update-desktop-database >/dev/null 2>&1; then
        run update-desktop-database -q "$(dirname "$desktop")" || true
    fi
    if command -v gtk-update-icon-cache >/dev/null 2>&1 && [ -f "$icons/index.theme" ]; then
        run gtk-update-icon-cache -q -t "$icons" || true
    fi
}

reload_udev() {
    if [ $LIVE = 0 ]; then
        say "udev: not reloaded (--root: not this machine's rules)"
    elif ! command -v udevadm >/dev/null 2>&1; then
        say "udev: udevadm not found; reboot (or replug the devices) for the rules to apply"
    elif run udevadm control --reload-rules 2>/dev/null; then
        run udevadm trigger --action=add --subsystem-match=usb --subsystem-match=tty || true
        say "udev: rules reloaded; unplug and replug the Kinect and the table controller"
    else
        say "udev: the udev daemon did not answer; the rules apply after a reboot"
    fi
}

install_udev_rules() {
    if [ $UDEV = 0 ]; then
        say "udev: skipped (--no-udev)"
        return
    fi
    if [ $IS_ROOT = 0 ] && [ $LIVE = 1 ]; then
        say "udev: rules not installed (needs root). To give this user the Kinect and the table:"
        files=""
        for rule in $UDEV_RULES; do files="$files $HERE/udev/$rule"; done
        say "  sudo install -m 644$files $UDEV_DIR/"
        say "  sudo udevadm control --reload-rules && sudo udevadm trigger"
        return
    fi
    rules=$(dest "$UDEV_DIR")
    run mkdir -p "$rules"
    for rule in $UDEV_RULES; do
        run install -m 644 "$HERE/udev/$rule" "$rules/$rule"
        say "udev: $rules/$rule"
    done
    if [ $LIVE = 1 ] && ! getent group plugdev >/dev/null 2>&1; then
        run groupadd --system plugdev
        say "group plugdev created (the Kinect rule gives it the sensor)"
    fi
    reload_udev
}

add_groups() {
    [ $ADD_GROUPS = 1 ] || return 0
    if [ $LIVE = 0 ]; then
        say "groups: left alone (--root)"
        return
    fi
    if [ $IS_ROOT = 0 ]; then
        say "groups: needs root: sudo usermod -aG dialout,plugdev $TARGET_USER"
        return
    fi
    for group in dialout plugdev; do
        getent group "$group" >/dev/null 2>&1 || run groupadd --system "$group"
        if id -nG "$TARGET_USER" 2>/dev/null | tr ' ' '\n' | grep -qx "$group"; then
            say "groups: $TARGET_USER is already in $group"
        else
            run usermod -aG "$group" "$TARGET_USER"
            say "groups: $TARGET_USER added to $group (log out and in again for it to apply)"
        fi
    done
}

# --- uninstall --------------------------------------------------------------------------------

remove() {  # remove PATH...: each that exists, saying so
    for path in "$@"; do
        if [ -e "$path" ] || [ -L "$path" ]; then
            run rm -rf "$path"
            say "removed $path"
        fi
    done
}

uninstall() {
    app=$(dest "$APP_DIR")
    owned_or_absent "$app" || fail "$app is not a fieldapp install; not removing it"
    link=$(dest "$BIN_DIR/$APP_NAME")
    if [ -L "$link" ] && [ "$(readlink "$link")" = "$APP_DIR/$APP_NAME" ]; then
        remove "$link"
    fi
    icons=$(dest "$ICON_DIR")
    remove "$app" "$(dest "$DESKTOP_FILE")" "$icons/scalable/apps/$APP_NAME.svg"
    for size in 48x48 128x128 256x256; do
        remove "$icons/$size/apps/$APP_NAME.png"
    done
    if [ $UDEV = 1 ] && { [ $IS_ROOT = 1 ] || [ $LIVE = 0 ]; }; then
        for rule in $UDEV_RULES; do
            remove "$(dest "$UDEV_DIR/$rule")"
        done
        reload_udev
    fi
    say "kept your data: settings in ~/.config/fieldapp, sessions, calibration.json and"
    say "results.sqlite in ~/.local/share/fieldapp (delete them yourself if you mean to)"
}

# --- main -------------------------------------------------------------------------------------

[ $DRY_RUN = 1 ] && echo "$PROG: dry run: nothing is changed"
say "$MODE install, app folder $ROOT$APP_DIR"
if [ $UNINSTALL = 1 ]; then
    uninstall
    exit 0
fi
find_bundle
install_app
install_command
install_desktop_entry
install_udev_rules
add_groups
say "done: start fieldapp from the menu (Science) or with '$APP_NAME'; check it with '$APP_NAME --smoke-test'"
