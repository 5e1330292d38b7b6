#!/usr/bin/env bash
# Gradescope runs this once, as root, from /autograder/source, while it builds the
# autograder image (Ubuntu with Python 3). It installs the grading package bundled
# beside this file (pyproject.toml and autograder/, then reference/) and its dependencies
# into a virtual environment, $AUTOGRADER_ROOT/venv (default /autograder/venv),
# with a Python of at least 3.11 (installed from Ubuntu, or the deadsnakes PPA on
# older releases, when the image's python3 is older).
set -euo pipefail
SOURCE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
ROOT="${AUTOGRADER_ROOT:-/autograder}"
export DEBIAN_FRONTEND=noninteractive

recent() { "$1" -c 'import sys; sys.exit(sys.version_info < (3, 11))' >/dev/null 2>&1; }

PYTHON=""
for candidate in python3 python3.13 python3.12 python3.11; do
    if command -v "$candidate" >/dev/null 2>&1 && recent "$candidate"; then
        PYTHON="$candidate"
        break
    fi
done
if [ -z "$PYTHON" ]; then
    apt-get update
    if ! apt-get install -y python3.11 python3.11-venv; then
        apt-get install -y software-properties-common
        add-apt-repository -y ppa:deadsnakes/ppa
        apt-get update
        apt-get install -y python3.11 python3.11-venv
    fi
    PYTHON=python3.11
fi
if ! "$PYTHON" -c 'import ensurepip, venv' >/dev/null 2>&1; then
    apt-get update
    apt-get install -y "$(basename "$PYTHON")-venv"
fi

"$PYTHON" -m venv "$ROOT/venv"
"$ROOT/venv/bin/python" -m pip install --upgrade pip
# The grading engine, then the model solutions the hidden checks compare with (their
# own distribution, so that a student's install of the engine never holds them).
"$ROOT/venv/bin/python" -m pip install "$SOURCE" "$SOURCE/reference"
"$ROOT/venv/bin/python" -c 'import autograder, reference; print("installed autograder", autograder.__version__)'
