#!/usr/bin/env bash
# Installs AssemblyWorld into .venv/ at the repository root, with the system libraries that
# offscreen rendering needs. Safe to re-run: it skips what is already there.
set -euo pipefail
cd "$(dirname "$0")/.."

need_pkgs=()
for lib in libEGL.so.1 libOSMesa.so.8 libGL.so.1 libgbm.so.1 libOpenGL.so.0; do
  ldconfig -p 2>/dev/null | grep -q "$lib" || need_pkgs+=("$lib")
done
if [ ${#need_pkgs[@]} -gt 0 ]; then
  debs="libegl1 libegl-mesa0 libgl1-mesa-dri libgbm1 libopengl0 libgl1 libosmesa6"
  if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null; then
    echo "[install] offscreen rendering libraries missing (${need_pkgs[*]}): apt-get install $debs"
    (apt-get install -y -q $debs >/dev/null 2>&1) || { apt-get update -q >/dev/null && apt-get install -y -q $debs >/dev/null; }
  else
    echo "[install] ERROR: offscreen rendering needs these libraries: ${need_pkgs[*]}" >&2
    echo "[install] Install them as root:  apt-get install -y $debs" >&2
    exit 1
  fi
fi

# report.html's browser tests drive Debian's Chromium through playwright (no browser download)
if ! command -v chromium >/dev/null; then
  if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null; then
    echo "[install] chromium missing (report.html's browser tests): apt-get install chromium"
    (apt-get install -y -q chromium >/dev/null 2>&1) || { apt-get update -q >/dev/null && apt-get install -y -q chromium >/dev/null; }
  else
    echo "[install] note: report.html's browser tests need Chromium; as root: apt-get install -y chromium" >&2
  fi
fi

PY=${PYTHON:-python3}
"$PY" -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else 1)' || {
  echo "[install] ERROR: Python 3.11+ is needed ($PY is $("$PY" --version 2>&1))" >&2; exit 1; }
if [ ! -x .venv/bin/python ]; then
  echo "[install] creating .venv"
  "$PY" -m venv .venv
fi
stamp=.venv/.aw-installed
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
  # pip's own output (150+ lines) goes to a log; the terminal gets a summary, or the log's tail on failure
  log=.venv/install.log
  echo "[install] installing AssemblyWorld and its dependencies into .venv (first time: a few minutes; log: $log)"
  if ! { .venv/bin/python -m pip install --upgrade pip && .venv/bin/python -m pip install -e ".[test,inspect]"; } >"$log" 2>&1; then
    tail -n 30 "$log" >&2
    echo "[install] ERROR: pip failed; the whole output is in $log" >&2
    exit 1
  fi
  warnings=$(grep -ci 'warning' "$log" || true)
  echo "[install] $(grep '^Successfully installed' "$log" | tail -n 1 | wc -w | awk '{print ($1>2)?$1-2:0}') packages installed or updated; $warnings warning line(s) in $log"
  touch "$stamp"
fi
# pip leaves a build by-product, assemblyworld.egg-info, in the repository root; wherever the root is on
# sys.path (pytest, python -c) it hides the installed dist-info, whose direct_url.json is how Inspect
# tells an installed package and names its task assemblyworld/assemblyworld
rm -rf assemblyworld.egg-info
# numba caches compiled kernels beside their modules; compile them once here, not in every process
.venv/bin/python -W ignore -c "from aw_eval.kernels import compile_kernels; compile_kernels()" >>.venv/install.log 2>&1 || {
  tail -n 30 .venv/install.log >&2
  echo "[install] ERROR: compiling the evaluator's kernels (numba) failed; see .venv/install.log" >&2; exit 1; }
echo "[install] ready: $(.venv/bin/python --version), .venv/bin/aw-*"
