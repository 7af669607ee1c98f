#!/bin/sh
# Installs the system libraries that fieldapp's wheels load at run time (open3d: libusb, libgomp;
# Qt: EGL/GL, fontconfig, xkbcommon and the xcb libraries of its X11 platform plugin).
# Installs with apt-get when missing and we are root or have password-less sudo; otherwise it
# stops with one line saying what to install.
set -eu

# soname package
NEEDED="libusb-1.0.so.0 libusb-1.0-0
libgomp.so.1 libgomp1
libGL.so.1 libgl1
libEGL.so.1 libegl1
libfontconfig.so.1 libfontconfig1
libdbus-1.so.3 libdbus-1-3
libglib-2.0.so.0 libglib2.0-0
libxkbcommon.so.0 libxkbcommon0
libxkbcommon-x11.so.0 libxkbcommon-x11-0
libxcb-cursor.so.0 libxcb-cursor0
libxcb-icccm.so.4 libxcb-icccm4
libxcb-keysyms.so.1 libxcb-keysyms1
libxcb-image.so.0 libxcb-image0
libxcb-render-util.so.0 libxcb-render-util0
libxcb-randr.so.0 libxcb-randr0
libxcb-shape.so.0 libxcb-shape0
libxcb-xinerama.so.0 libxcb-xinerama0"

present=$( (/sbin/ldconfig -p 2>/dev/null || ldconfig -p 2>/dev/null) | awk '{print $1}')
missing=""
for pair in $(echo "$NEEDED" | tr ' ' ':'); do
    soname=${pair%%:*}
    package=${pair#*:}
    echo "$present" | grep -qx "$soname" || missing="$missing $package"
done
[ -z "$missing" ] && exit 0

if ! command -v apt-get >/dev/null 2>&1; then
    echo "fieldapp needs these system libraries (Debian names):$missing; install them with your package manager."
    exit 1
fi
if [ "$(id -u)" = 0 ]; then
    SUDO=""
elif command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null; then
    SUDO="sudo"
else
    echo "fieldapp needs system libraries: run 'sudo apt-get install$missing' and try again."
    exit 1
fi
echo "Installing system libraries:$missing"
$SUDO apt-get update -qq
DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends $missing >/dev/null
