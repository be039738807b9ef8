#!/usr/bin/env bash
# The README's commands. Each sets the machine up first (scripts/bootstrap.sh).
#   bash run.sh demo [--out DIR]   the main job
#   bash run.sh test [pytest args] the test suite
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
bash "$root/scripts/bootstrap.sh"
cmd=${1:-}; shift || true
case "$cmd" in
    demo) exec "$root/.venv/bin/mi-dsbrdf" demo "$@" ;;
    test) cd "$root" && exec .venv/bin/python -m pytest -q "$@" ;;
    *) echo "usage: bash run.sh demo|test [args]" >&2; exit 2 ;;
esac
