#!/usr/bin/env bash
# Set PyGran up on Debian 12 (as root) and run the main job or the whole test suite.
#   bash scripts/bootstrap.sh main   # apt packages, venv, core + every plugin; then the main job:
#                                    # the hopper discharge study (pygran demo) into ./demo-output
#   bash scripts/bootstrap.sh test   # the same set-up; then the complete test suite
# Idempotent: packages already present are not reinstalled; pip reinstalls only when a
# package definition or compiled source (pyproject.toml, setup.py, .pyx, .pxi, .pxd, .h)
# changed since the last run.
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
VENV=${PYGRAN_VENV:-$ROOT/.venv}
APT_PACKAGES=(python3 python3-venv python3-dev build-essential
    liggghts libliggghts-dev openmpi-bin libopenmpi-dev yade)
PLUGINS=(pygran-readers pygran-native pygran-liggghts pygran-yade)

log() { printf '\033[1m[pygran setup]\033[0m %s\n' "$*" >&2; }

install_apt_packages() {
    local missing=()
    for pkg in "${APT_PACKAGES[@]}"; do
        dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing+=("$pkg")
    done
    if ((${#missing[@]})); then
        log "installing Debian packages: ${missing[*]}"
        apt-get update -q
        DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends "${missing[@]}"
    fi
}

install_python_packages() {
    if [[ ! -x $VENV/bin/python ]]; then
        log "creating virtual environment $VENV"
        /usr/bin/python3 -m venv "$VENV"
    fi
    local stamp=$VENV/.pygran-install-stamp digest
    digest=$(cd "$ROOT" && shopt -s nullglob && cat pyproject.toml setup.py pygran_core/*.pyx plugins/*/pyproject.toml \
        plugins/*/setup.py plugins/*/src/*/*.{pyx,pxi,pxd,h} plugins/*/src/*/*/*.{cpp,h} | sha256sum | cut -d' ' -f1)
    if [[ -f $stamp && $(cat "$stamp") == "$digest" ]]; then
        return
    fi
    log "installing pygran-core and plugins (${PLUGINS[*]}) into $VENV"
    "$VENV/bin/python" -m pip install -q --upgrade pip "setuptools>=77" wheel
    local args=(-e "$ROOT[test,plot,docs]")
    for plugin in "${PLUGINS[@]}"; do args+=(-e "$ROOT/plugins/$plugin[test]"); done
    "$VENV/bin/python" -m pip install -q "${args[@]}"
    echo "$digest" >"$stamp"
}

run_main() {
    "$VENV/bin/pygran" plugins
    "$VENV/bin/pygran" demo --output "${PYGRAN_DEMO_OUTPUT:-$ROOT/demo-output}"
}

run_tests() {
    local status=0
    # the slowest tests listed at the end: the suite is kept under 20 minutes
    PYGRAN_STRICT_PLUGINS=1 "$VENV/bin/python" -m pytest -p no:cacheprovider --durations=20 "$@" || status=$?
    if ((status == 5)); then
        echo "pytest collected no tests: failing" >&2
        return 1
    fi
    return "$status"
}

case "${1:-}" in
    main) install_apt_packages; install_python_packages; run_main ;;
    test) install_apt_packages; install_python_packages; shift; cd "$ROOT"; run_tests "$@" ;;
    *) echo "usage: bash scripts/bootstrap.sh main|test [pytest arguments]" >&2; exit 2 ;;
esac
