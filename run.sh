#!/usr/bin/env bash
# The README's commands. Each sets the machine up first (scripts/bootstrap.sh).
#   bash run.sh demo [--out DIR]          the main job
#   bash run.sh test [pytest args]        the fast tests (those not marked slow)
#   bash run.sh test --all [pytest args]  every test (CI runs this through .ci/run)
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
bash "$root/scripts/bootstrap.sh"
cmd=${1:-}; shift || true
case "$cmd" in
    demo) exec "$root/.venv/bin/mi-dsbrdf" demo "$@" ;;
    test)
        cd "$root"
        if [ "${1:-}" = "--all" ]; then shift; exec .venv/bin/python -m pytest -q "$@"; fi
        exec .venv/bin/python -m pytest -q -m "not slow" "$@" ;;
    *) echo "usage: bash run.sh demo|test [--all] [args]" >&2; exit 2 ;;
esac
