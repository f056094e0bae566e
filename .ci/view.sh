#!/usr/bin/env bash
# The viewer in a real browser (issue 29): Debian's headless Chromium loads the page with the
# token, drags on the view with pointer events, waits for the final frame, saves the scene and
# the screenshot with the page's buttons, and compares them with `volsplat render --scene`
# (crates/cli/tests/browser.rs). Needs root or sudo for apt-get when chromium is missing.
set -euo pipefail
cd "$(dirname "$0")/.."
export CARGO_TERM_COLOR=never
export CARGO_INCREMENTAL=0

step() { echo; echo "=== $* ==="; }

step "view: chromium"
if ! command -v "${VOLSPLAT_CHROMIUM:-chromium}" >/dev/null 2>&1; then
  sudo_="$(command -v sudo || true)"
  $sudo_ apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo_ apt-get install -y -qq chromium
fi
"${VOLSPLAT_CHROMIUM:-chromium}" --version

step "view: the page in headless chromium against volsplat render"
# The release profile, as the README's test command: reuses its build (decision 0032).
VOLSPLAT_BROWSER_TEST=1 cargo test --release -p volsplat-cli --test browser -- --nocapture
