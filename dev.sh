#!/usr/bin/env bash
# One-command set-up and tasks for o3d_seqcc on a fresh Debian/Ubuntu machine.
#
#   ./dev.sh demo    install what the demo needs (once) and run the pipeline on the built-in synthetic scene
#   ./dev.sh test    install everything (once) and run the test suite
#   ./dev.sh setup   only install everything (with the MeshLab filter plugin, which test needs and demo does not)
#   ./dev.sh lint    install the Python packages (once) and run ruff (pyproject's [tool.ruff]) over the repository
#
# demo installs the system libraries Open3D needs (apt, when root or with sudo) and a virtual
# environment in .venv with the package and its core dependencies (`pip install -e .`), no more.
# setup and test add the rest: the MeshLab application, xvfb, Debian's chromium (the HTML report's
# rendering tests), nodejs/npm (apt), every extra and the test tools (`pip install -e ".[test]"`),
# the Khronos glTF validator (npm) into .cache/node and the MeshLab filter plugin of
# meshlab_filters/plugin/, built in .cache/meshlab-plugin and installed into MeshLab's plugin folder.
# Each step shows its progress, with the time since the start; re-running is cheap: each step is
# skipped when done.
set -euo pipefail
cd "$(dirname "$0")"
ROOT=$(pwd)
VENV=${VENV:-$ROOT/.venv}
# what `import open3d` needs (the demo, and every command)
APT_CORE=(libusb-1.0-0 libgomp1 libgl1 libegl1)
# the rest of the test suite's tools
APT_FULL=("${APT_CORE[@]}" xvfb xauth libgl1-mesa-dri libglx-mesa0 libqt5gui5 nodejs npm
          libvulkan1 mesa-vulkan-drivers  # Open3D's offscreen renderer (lavapipe)
          meshlab xdotool imagemagick     # MeshLab opening our output (tests/meshlab/test_meshlab_app.py)
          chromium)                       # the HTML report in a browser (tests/report/test_report*.py)

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

# ---- the MeshLab filter plugin (meshlab_filters/plugin/, GPL-3) ----------------------------------------------------
# Built against the sources of the installed MeshLab (Debian 12 / Ubuntu: 2020.09, no -dev package: `apt-get source`
# through a private source list, /etc/apt untouched) and installed where Debian's MeshLab loads plugins. Skipped when
# already built for the same sources, parameters (generated from the library) and o3d-seqcc.
PLUGIN_APT_PACKAGES=(g++ cmake make dpkg-dev xz-utils qtbase5-dev libqt5opengl5-dev libglew-dev libeigen3-dev)
PLUGIN_INSTALL_DIR=/usr/lib/x86_64-linux-gnu/meshlab/plugins  # the only folder MeshLab 2020.09 loads plugins from
PLUGIN_FILE=libfilter_o3d_seqcc.so

setup_meshlab_plugin() {
  local t0=$SECONDS cache=$ROOT/.cache/meshlab-plugin src_dir=meshlab_filters/plugin
  local version; version=$(dpkg-query -W -f='${Version}' meshlab 2>/dev/null || true)
  if [[ -z $version || ! -d $PLUGIN_INSTALL_DIR ]]; then
    log "MeshLab plugin: Debian's meshlab is not installed: skipped (its tests skip)"; return 0
  fi
  if [[ $version != 2020.09* ]]; then
    log "MeshLab plugin: MeshLab $version installed, the plugin is written for 2020.09: skipped"; return 0
  fi
  local SUDO=""
  if [[ $(id -u) -ne 0 ]]; then
    if command -v sudo >/dev/null 2>&1; then SUDO=sudo; else
      log "MeshLab plugin: installing into $PLUGIN_INSTALL_DIR needs root: skipped (run ./dev.sh setup as root)"
      return 0
    fi
  fi
  local exe=$VENV/bin/o3d-seqcc header key
  header=$("$VENV/bin/python" -m meshlab_filters.native header)
  key=$({ echo "meshlab $version, o3d-seqcc $exe"; echo "$header"; cat "$src_dir"/CMakeLists.txt "$src_dir"/*.cpp \
          "$src_dir"/*.h; } | sha256sum | cut -d' ' -f1)
  if [[ -f $cache/stamp && $(cat "$cache/stamp") == "$key" ]] && cmp -s "$cache/build/$PLUGIN_FILE" \
       "$PLUGIN_INSTALL_DIR/$PLUGIN_FILE"; then
    return 0
  fi
  log "MeshLab plugin: building $src_dir against MeshLab $version (about a minute)"
  local missing=() p
  for p in "${PLUGIN_APT_PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  if [[ ${#missing[@]} -gt 0 ]]; then
    log "MeshLab plugin: installing the build packages ${missing[*]}"
    export DEBIAN_FRONTEND=noninteractive
    $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null \
      || { $SUDO apt-get update -qq && $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null; }
  fi
  local srcroot=$cache/meshlab-$version
  if [[ ! -f $srcroot/src/common/interfaces.h ]]; then
    log "MeshLab plugin: fetching the MeshLab $version sources (apt-get source, private source list)"
    local apt=$cache/apt
    rm -rf "$apt" "$srcroot" && mkdir -p "$apt/sources" "$apt/lists/partial" "$apt/cache/archives/partial" "$cache/dl"
    # deb-src twins of the machine's own deb entries (Debian or Ubuntu), in a private list
    local f
    for f in /etc/apt/sources.list /etc/apt/sources.list.d/*.list; do
      [[ -f $f ]] && sed -n 's/^[[:space:]]*deb[[:space:]]/deb-src /p' "$f" >> "$apt/sources/src.list"
    done
    for f in /etc/apt/sources.list.d/*.sources; do
      [[ -f $f ]] && sed 's/^Types:.*/Types: deb-src/' "$f" > "$apt/sources/$(basename "$f")"
    done
    local opts=(-o Dir::Etc::sourcelist=/dev/null -o Dir::Etc::sourceparts="$apt/sources" -o Dir::State::Lists="$apt/lists"
                -o Dir::Cache="$apt/cache" -o APT::Sandbox::User="$(id -un)")
    apt-get -qq "${opts[@]}" update
    (cd "$cache/dl" && apt-get -qq "${opts[@]}" source --download-only "meshlab=$version" >/dev/null)
    dpkg-source --no-check -x "$cache/dl"/meshlab_*.dsc "$srcroot" >/dev/null
    rm -rf "$cache/dl" "$apt"
  fi
  log "MeshLab plugin: compiling (cmake, make)"
  cmake -S "$src_dir" -B "$cache/build" -DMESHLAB_SRC="$srcroot/src" -DO3D_SEQCC_PYTHON="$VENV/bin/python" \
        -DO3D_SEQCC_EXECUTABLE="$exe" > "$cache/cmake.log" 2>&1 || { cat "$cache/cmake.log" >&2; exit 1; }
  local rc=0
  cmake --build "$cache/build" -j "$(nproc)" 2>&1 | { grep -v "Built target\|Automatic MOC" || true; } >&2 || rc=$?
  [[ $rc -eq 0 ]] || { log "MeshLab plugin: build failed (see above)"; exit 1; }
  # atomic: a MeshLab starting meanwhile sees the old plugin or the new one
  $SUDO install -m 644 "$cache/build/$PLUGIN_FILE" "$PLUGIN_INSTALL_DIR/.$PLUGIN_FILE.tmp"
  $SUDO mv -f "$PLUGIN_INSTALL_DIR/.$PLUGIN_FILE.tmp" "$PLUGIN_INSTALL_DIR/$PLUGIN_FILE"
  echo "$key" > "$cache/stamp"
  log "MeshLab plugin: installed $PLUGIN_INSTALL_DIR/$PLUGIN_FILE in $((SECONDS - t0)) s (runs $exe)"
}

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
  setup) setup; setup_meshlab_plugin ;;
  demo) setup_demo; log "running o3d-seqcc demo"; "$VENV/bin/o3d-seqcc" demo --out "${OUT:-out/demo}" --overwrite "$@" ;;
  test) setup; setup_meshlab_plugin; log "running the tests"; with_display "$VENV/bin/python" -m pytest "$@" ;;
  lint) setup_python full; log "running ruff"; "$VENV/bin/python" -m ruff check "${@:-.}" ;;
  *) sed -n '2,16p' "$0"; exit 2 ;;
esac
