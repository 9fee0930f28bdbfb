#!/usr/bin/env bash
# Dr.Jit's LLVM backend needs libLLVM >= 16 (15 aborts with "Cannot select ... fminimum", 14 is
# refused). Install Debian's libllvm19 when we can; otherwise say what to install and go on:
# the package falls back to the scalar_rgb variant with a warning.
set -u
have_llvm() {
  for f in /usr/lib/x86_64-linux-gnu/libLLVM-{16,17,18,19,20,21}.so* /usr/lib/x86_64-linux-gnu/libLLVM.so.{16,17,18,19,20,21}* \
           /usr/lib/llvm-{16,17,18,19,20,21}/lib/libLLVM*.so* /usr/local/lib/libLLVM*.so*; do
    [ -e "$f" ] && return 0
  done
  return 1
}
if have_llvm; then exit 0; fi
if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
  echo "ensure_llvm: installing libllvm19 for Dr.Jit's LLVM backend"
  (apt-get install -y -qq libllvm19 >/dev/null 2>&1 || { apt-get update -qq && apt-get install -y -qq libllvm19; }) \
    && exit 0
fi
echo "ensure_llvm: no libLLVM >= 16 found. Install one (Debian: 'apt-get install libllvm19') or set" \
     "DRJIT_LIBLLVM_PATH; until then rendering falls back to the slow scalar_rgb variant." >&2
exit 0
