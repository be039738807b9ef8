#!/usr/bin/env bash
# Idempotent set-up for a fresh machine: a libLLVM >= 16 for Dr.Jit's LLVM
# backend (Debian's libllvm19 when none is present; LLVM 14/15 abort inside
# Dr.Jit with "Cannot select ... fmaximum"), a virtual environment in .venv
# and an editable install of the package with its test extras.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
cd "$root"

have_llvm16() {
    local f v
    for f in /usr/lib/*/libLLVM-[0-9]*.so /usr/lib/*/libLLVM.so.[0-9]* /usr/lib/llvm-*/lib/libLLVM*.so*; do
        [ -e "$f" ] || continue
        v=$(basename "$f" | sed -E 's/^libLLVM[-.]?(so\.)?([0-9]+).*/\2/')
        [[ "$v" =~ ^[0-9]+$ ]] && [ "$v" -ge 16 ] && return 0
    done
    return 1
}

if [ -z "${DRJIT_LIBLLVM_PATH:-}" ] && ! have_llvm16; then
    echo "bootstrap: no libLLVM >= 16 found; installing Debian's libllvm19" >&2
    if [ "$(id -u)" -eq 0 ]; then sudo=""; else sudo="sudo"; fi
    $sudo apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq libllvm19 >/dev/null
fi

if [ ! -x .venv/bin/python ]; then
    python3 -m venv .venv
fi
# Reinstall only when pyproject.toml changed since the last install.
stamp=.venv/.mi-dsbrdf-installed
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
    .venv/bin/python -m pip install -q --disable-pip-version-check -e '.[test]'
    touch "$stamp"
fi
