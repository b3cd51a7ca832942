#!/usr/bin/env bash
# Run the test suite in the project's venv, offline, with Hugging Face caches in a temp folder, on every core:
# pytest with one xdist worker per core, whole test files per worker (module fixtures run once); beside it,
# the shared tiny releases are built once (tests/tiny_releases.py), while the test files that need none run
# first. pytest runs niced, so the release builds (LIBERO's is the longest single task) get the cores first.
# The slowest tests are listed at the end. Arguments go to pytest (e.g. one test file); then nothing is
# pre-built and the fixtures build what those tests use.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
export HF_HUB_OFFLINE=1 HF_DATASETS_OFFLINE=1
WORKERS="${WSP_TEST_WORKERS:-$(nproc)}"
TMP="$(mktemp -d -t wsp-test-XXXXXX)"
PREBUILD=""
stop_prebuild() { [ -z "$PREBUILD" ] || kill -- "-$PREBUILD" 2>/dev/null || true; }
cleanup() { stop_prebuild; rm -rf "$TMP"; }
trap cleanup EXIT
if [ $# -eq 0 ]; then
  export WSP_TEST_RELEASES="$TMP/releases"
  setsid .venv/bin/python tests/tiny_releases.py "$WSP_TEST_RELEASES" > "$TMP/tiny-releases.log" 2>&1 &
  PREBUILD=$!
fi
rc=0
nice -n 10 .venv/bin/python -m pytest -q -n "$WORKERS" --dist loadfile --durations=15 --durations-min=1 "$@" || rc=$?
if [ -n "$PREBUILD" ]; then  # done by now when every test ran
  if kill -0 "$PREBUILD" 2>/dev/null; then echo "[tiny releases] still building when the tests ended: stopped"; fi
  stop_prebuild; wait "$PREBUILD" 2>/dev/null || true; PREBUILD=""
  grep '^\[tiny releases\]' "$TMP/tiny-releases.log" || true
  grep -q '^\[tiny releases\] done' "$TMP/tiny-releases.log" || tail -5 "$TMP/tiny-releases.log"
fi
exit "$rc"
