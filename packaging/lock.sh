#!/bin/sh
# Upgrade the lock: resolve the newest releases that pyproject.toml allows in a throw-away venv
# and write their exact versions to requirements.lock. `make run`, `make test` and `make bundle`
# install with `-c requirements.lock`, so every machine gets the versions the suite passed with.
# After this, run the whole suite on the new lock (`make clean test`) before committing it;
# docs/INSTALL.md says why and what to do when an upgrade breaks something.
set -eu
PYTHON=${PYTHON:-python3}
here=$(cd "$(dirname "$0")/.." && pwd)
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
"$PYTHON" -m venv "$tmp/venv"
"$tmp/venv/bin/python" -m pip install --quiet --upgrade pip
"$tmp/venv/bin/python" -m pip install --quiet "$here[gui,dev,bundle,realsense]"
{
  echo "# The exact versions the test suite passed with (Python $("$tmp/venv/bin/python" -c 'import sys; print(".".join(map(str, sys.version_info[:2])))'), $(uname -m) Linux)."
  echo "# Installed as constraints by make run / make test / make bundle. Regenerate with"
  echo "# 'make lock', then run 'make clean test' before committing (docs/INSTALL.md)."
  "$tmp/venv/bin/python" -m pip freeze --all --exclude-editable \
    | grep -v -i -E '^(fieldapp|setuptools|wheel)[=@ ]'
} > "$here/requirements.lock.new"
mv "$here/requirements.lock.new" "$here/requirements.lock"
echo "requirements.lock written; now run: make clean test"
