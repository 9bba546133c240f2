#!/usr/bin/env bash
# One-command set-up and tasks for o3d_seqcc on a fresh Debian/Ubuntu machine.
#
#   ./dev.sh demo    install what the demo needs (once) and run the pipeline on the built-in synthetic scene
#   ./dev.sh test    install everything (once) and run the test suite
#   ./dev.sh setup   only install everything
#
# demo installs the system libraries Open3D needs (apt, when root or with sudo) and a virtual
# environment in .venv with the package and its core dependencies (`pip install -e .`), no more.
# setup and test add the rest: the MeshLab application, xvfb, Debian's chromium (the HTML report's
# rendering tests), nodejs/npm (apt), every extra and the test tools (`pip install -e ".[test]"`)
# and the Khronos glTF validator (npm) into .cache/node. Each step shows its progress, with the
# time since the start; re-running is cheap: each step is skipped when done.
set -euo pipefail
cd "$(dirname "$0")"
ROOT=$(pwd)
VENV=${VENV:-$ROOT/.venv}
# what `import open3d` needs (the demo, and every command)
APT_CORE=(libusb-1.0-0 libgomp1 libgl1 libegl1)
# the rest of the test suite's tools
APT_FULL=("${APT_CORE[@]}" xvfb xauth libgl1-mesa-dri libglx-mesa0 libqt5gui5 nodejs npm
          libvulkan1 mesa-vulkan-drivers  # Open3D's offscreen renderer (lavapipe)
          meshlab xdotool imagemagick     # MeshLab opening our output (tests/test_meshlab_app.py)
          chromium)                       # the HTML report in a browser (tests/test_report*.py)

START=$SECONDS
log() { printf '\033[1m[dev.sh %d:%02d]\033[0m %s\n' $(((SECONDS - START) / 60)) $(((SECONDS - START) % 60)) "$*" >&2; }

# with_ticker CMD...: run CMD; every 20 s meanwhile say how far the venv has grown (pip prints nothing while it
# unpacks and byte-compiles, about a minute for Open3D alone)
with_ticker() {
  "$@" &
  local pid=$! n=0
  while kill -0 "$pid" 2>/dev/null; do
    sleep 1
    n=$((n + 1))
    if ((n % 20 == 0)) && kill -0 "$pid" 2>/dev/null; then
      log "... pip still working: $(du -sm "$VENV" 2>/dev/null | cut -f1) MB in $VENV"
    fi
  done
  wait "$pid"
}

# setup_system core|full: the apt packages of that level that are missing
setup_system() {
  local missing=() wanted=()
  if [[ ${1:-full} == core ]]; then wanted=("${APT_CORE[@]}"); else wanted=("${APT_FULL[@]}"); fi
  if command -v dpkg-query >/dev/null 2>&1; then
    for p in "${wanted[@]}"; do
      # node/npm may come from elsewhere (nvm, the image): only install when absent
      if [[ $p == nodejs && -n $(command -v node || true) ]]; then continue; fi
      if [[ $p == npm && -n $(command -v npm || true) ]]; then continue; fi
      dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
    done
  fi
  [[ ${#missing[@]} -eq 0 ]] && return 0
  local SUDO=""
  if [[ $(id -u) -ne 0 ]]; then
    if command -v sudo >/dev/null 2>&1; then SUDO=sudo; else
      log "missing system packages: ${missing[*]}; install them as root: apt-get install -y ${missing[*]}"
      return 0
    fi
  fi
  log "installing system packages: ${missing[*]}"
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -q
  $SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
  log "system packages installed"
}

find_python() {
  for py in "${PYTHON:-}" python3.13 python3.12 python3.11 python3.10 python3; do
    [[ -z $py ]] && continue
    if command -v "$py" >/dev/null 2>&1 && "$py" -c 'import sys; sys.exit(sys.version_info < (3, 10))' 2>/dev/null; then
      echo "$py"; return 0
    fi
  done
  log "Python >= 3.10 not found"; exit 1
}

# setup_python core|full: the package into $VENV with its core dependencies, or with every extra and the test tools
setup_python() {
  local level=${1:-full}
  local stamp="$VENV/.o3d_seqcc-installed"
  local hash
  hash=$(sha256sum pyproject.toml | cut -d' ' -f1)
  # a full install serves the demo too; a core one is completed by setup / test
  if [[ -f $stamp ]] && { [[ $(cat "$stamp") == "$hash full" ]] || [[ $level == core && $(cat "$stamp") == "$hash core" ]]; }; then
    return 0
  fi
  if [[ ! -x $VENV/bin/python ]]; then
    local py; py=$(find_python)
    log "creating $VENV with $py"
    if ! "$py" -m venv "$VENV" 2>/dev/null; then
      # Debian's python3 ships venv/ensurepip separately
      local ver; ver=$("$py" -c 'import sys; print(f"{sys.version_info[0]}.{sys.version_info[1]}")')
      log "python venv module missing: installing python3-venv python${ver}-venv"
      rm -rf "$VENV"
      local SUDO=""; [[ $(id -u) -ne 0 ]] && SUDO=sudo
      $SUDO apt-get update -qq && $SUDO apt-get install -y -qq "python${ver}-venv" python3-venv >/dev/null
      "$py" -m venv "$VENV"
    fi
  fi
  local spec=. mods="o3d_seqcc open3d cv2 sklearn xatlas matplotlib"
  if [[ $level == full ]]; then spec=".[test]"; mods="$mods pymeshlab distributed pytest"; fi
  log "installing o3d_seqcc (pip install -e \"$spec\") into $VENV"
  # pip's own output is the progress (downloads, then the install); it stops the script when it fails
  with_ticker "$VENV/bin/python" -m pip install -e "$spec"
  # present, without paying for importing them (open3d alone takes seconds; the command imports what it needs)
  "$VENV/bin/python" -c "import importlib.util as u, sys; m = [n for n in sys.argv[1:] if u.find_spec(n) is None]; \
sys.exit(f'missing after the install: {m}' if m else 0)" $mods || { log "install failed"; exit 1; }
  echo "$hash $level" > "$stamp"
  log "python packages installed"
}

setup_node() {
  local dir="$ROOT/.cache/node"
  [[ -f $dir/node_modules/gltf-validator/package.json ]] && return 0
  if command -v npm >/dev/null 2>&1; then
    log "installing the Khronos glTF validator (npm gltf-validator) into $dir"
    mkdir -p "$dir"
    npm install --no-audit --no-fund --prefix "$dir" gltf-validator \
      || log "npm install gltf-validator failed: the GLB validation test will be skipped"
  else
    log "npm not found: the GLB validation test will be skipped"
  fi
}

setup() { setup_system full; setup_python full; setup_node; }
setup_demo() { setup_system core; setup_python core; }

# pymeshlab's raster filters need an OpenGL context and a Qt platform plugin
export QT_QPA_PLATFORM=${QT_QPA_PLATFORM:-xcb}
[[ -d /usr/lib/x86_64-linux-gnu/qt5/plugins ]] && export QT_PLUGIN_PATH=${QT_PLUGIN_PATH:-/usr/lib/x86_64-linux-gnu/qt5/plugins}
export GLTF_VALIDATOR_DIR=${GLTF_VALIDATOR_DIR:-$ROOT/.cache/node}
export MPLBACKEND=Agg

with_display() {
  if [[ -z ${DISPLAY:-} ]] && command -v xvfb-run >/dev/null 2>&1; then
    xvfb-run -a -s "-screen 0 1280x1024x24 +extension GLX" "$@"
  else
    "$@"
  fi
}

cmd=${1:-help}; shift || true
case $cmd in
  setup) setup ;;
  demo) setup_demo; log "running o3d-seqcc demo"; "$VENV/bin/o3d-seqcc" demo --out "${OUT:-out/demo}" --overwrite "$@" ;;
  test) setup; log "running the tests"; with_display "$VENV/bin/python" -m pytest "$@" ;;
  *) sed -n '2,15p' "$0"; exit 2 ;;
esac
