#!/usr/bin/env bash
# Install the Debian packages listed in tools/system-packages.txt that are missing.
# Needs root (as in CI); otherwise it only names what is missing.
set -euo pipefail
cd "$(dirname "$0")/.."
missing=()
while read -r pkg _; do
  [[ -z "$pkg" || "$pkg" == \#* ]] && continue
  dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing+=("$pkg")
done < tools/system-packages.txt
if (( ${#missing[@]} == 0 )); then exit 0; fi
if [[ "$(id -u)" -ne 0 ]] || ! command -v apt-get >/dev/null 2>&1; then
  echo "note: Debian packages missing (tests that need them will fail): ${missing[*]}" >&2
  exit 0
fi
echo "installing Debian packages: ${missing[*]} (log: /tmp/suspid-apt.log) ..." >&2
{ apt-get update -q && DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends "${missing[@]}"; } \
  >/tmp/suspid-apt.log 2>&1 || { cat /tmp/suspid-apt.log >&2; exit 1; }
