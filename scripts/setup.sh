#!/usr/bin/env bash
# All set-up, idempotent and quick once done: the system packages (install-system-packages.sh),
# a virtual environment in .venv, requirements.txt installed into it, and the interface package
# polymatch_interfaces built into it (build-interfaces.sh); pip runs again only
# when requirements.txt, setup.py or setup.cfg changed (their hash is kept in .venv).
set -euo pipefail
cd "$(dirname "$0")/.."

bash scripts/install-system-packages.sh
if [ ! -x .venv/bin/python ]; then
    python3 -m venv .venv
fi
stamp=.venv/.polymatch-requirements.sha256
wanted=$(cat requirements.txt setup.py setup.cfg | sha256sum | cut -d' ' -f1)
if [ "$(cat "$stamp" 2>/dev/null || true)" != "$wanted" ]; then
    .venv/bin/pip install -q -r requirements.txt
    echo "$wanted" > "$stamp"
    echo "python packages: installed requirements.txt into .venv"
else
    echo "python packages: requirements.txt already installed in .venv"
fi
bash scripts/build-interfaces.sh
