#!/usr/bin/env bash
# Creates .venv beside this script and installs opfmu with its test tools into it (idempotent).
#   OPFMU_TORCH        torch requirement to install first (default torch==2.13.0; on this project's
#                      machines that resolves to a local CPU build)
#   OPFMU_TORCH_INDEX  extra index for torch, e.g. https://download.pytorch.org/whl/cpu or .../cu128
#   OPFMU_PYTHON       interpreter for the venv (default python3)
set -euo pipefail
cd "$(dirname "$0")"
python=${OPFMU_PYTHON:-python3}
[ -x .venv/bin/python ] || "$python" -m venv .venv
pip=(.venv/bin/python -m pip --disable-pip-version-check -q)
if ! .venv/bin/python -c "import torch" 2>/dev/null; then
  "${pip[@]}" install "${OPFMU_TORCH:-torch==2.13.0}" ${OPFMU_TORCH_INDEX:+--extra-index-url "$OPFMU_TORCH_INDEX"}
fi
"${pip[@]}" install -e ".[test]"
