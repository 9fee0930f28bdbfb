#!/usr/bin/env bash
# Plugins run in a bubblewrap sandbox (denoisebench/sandbox.py): install Debian's
# bubblewrap when we can (root with apt-get). Called by `make setup`. Without root/apt we say what
# to install and go on: run-benchmark then refuses untrusted plugins unless given
# `--isolation process`, and the sandbox tests skip with the reason.
set -u
if ! command -v bwrap >/dev/null 2>&1; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    echo "ensure_sandbox: installing bubblewrap for the plugin sandbox"
    export DEBIAN_FRONTEND=noninteractive
    apt-get install -y -qq bubblewrap >/dev/null 2>&1 \
      || { apt-get update -qq && apt-get install -y -qq bubblewrap >/dev/null; }
  fi
fi
if ! command -v bwrap >/dev/null 2>&1; then
  echo "ensure_sandbox: bwrap not found and cannot be installed here (Debian: 'apt-get install bubblewrap');" \
       "plugins then need --isolation process, and the sandbox tests skip." >&2
  exit 0
fi
# the namespaces the sandbox needs: a kernel or container may refuse them
if ! bwrap --unshare-all --unshare-user --ro-bind / / true 2>/dev/null; then
  echo "ensure_sandbox: bwrap is installed but cannot create namespaces here (user namespaces disabled?" \
       "see sysctl kernel.unprivileged_userns_clone / user.max_user_namespaces); plugins need --isolation process." >&2
fi
exit 0
