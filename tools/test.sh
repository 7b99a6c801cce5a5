#!/usr/bin/env bash
# Set up (tools/setup.sh) and run the test suite. GL tests fail rather than skip when no context can
# be made (DIVIEWER_REQUIRE_GL=1); extra arguments go to pytest.
set -euo pipefail
. "$(dirname "${BASH_SOURCE[0]}")/setup.sh"
cd "$ROOT"
export DIVIEWER_REQUIRE_GL="${DIVIEWER_REQUIRE_GL:-1}"
python -m pytest -q -ra "$@"
