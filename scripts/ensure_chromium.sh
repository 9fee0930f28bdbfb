#!/usr/bin/env bash
# The report test opens index.html in a real headless Chromium driven by Selenium: install Debian's
# chromium and chromium-driver when we can (root with apt-get). Called by `make test`, not by
# `make setup`, so that `make demo` never needs a browser. Without root/apt we say what to install
# and go on: that one test then skips with the reason.
set -u
if command -v chromium >/dev/null 2>&1 && command -v chromedriver >/dev/null 2>&1; then exit 0; fi
if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
  echo "ensure_chromium: installing chromium and chromium-driver for the report test"
  export DEBIAN_FRONTEND=noninteractive
  (apt-get install -y -qq chromium chromium-driver >/dev/null 2>&1 \
    || { apt-get update -qq && apt-get install -y -qq chromium chromium-driver >/dev/null; }) && exit 0
fi
echo "ensure_chromium: chromium/chromedriver not found and cannot be installed here" \
     "(Debian: 'apt-get install chromium chromium-driver'); the browser test of the report will skip." >&2
exit 0
