#!/usr/bin/env bash
# System tools a command needs, by what it runs:
#   demo (the default)  cmake and g++: they build the interface package (build-interfaces.sh)
#   test                the same, and iproute2 (network namespaces), nftables (packet loss),
#                       tcpdump (proof that no DDS packet leaves the namespaces) for the
#                       multi-host tests
# Idempotent: installs with apt-get only what is missing, only as root; prints one line saying
# what it did.
set -euo pipefail

purpose=${1:-demo}
case "$purpose" in
    demo) wanted=(cmake g++) ;;
    test) wanted=(cmake g++ iproute2 nftables tcpdump) ;;
    *) echo "install-system-packages.sh: unknown purpose '$purpose' (demo or test)" >&2
       exit 2 ;;
esac
missing=()
for pkg in "${wanted[@]}"; do
    if ! dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed"; then
        missing+=("$pkg")
    fi
done

if [ ${#missing[@]} -eq 0 ]; then
    echo "system packages: ${wanted[*]} already installed"
    exit 0
fi
if [ "$(id -u)" -ne 0 ] || ! command -v apt-get >/dev/null 2>&1; then
    echo "system packages: missing ${missing[*]} (not installed: needs root and apt-get;" \
         "the interface package needs cmake and g++, the multi-host tests skip without the rest)"
    exit 0
fi
log=$(mktemp)
if timeout 600 apt-get update -qq >"$log" 2>&1 \
   && DEBIAN_FRONTEND=noninteractive timeout 600 \
      apt-get install -y -qq --no-install-recommends "${missing[@]}" >>"$log" 2>&1; then
    echo "system packages: installed ${missing[*]}"
    rm -f "$log"
else
    echo "system packages: apt-get failed to install ${missing[*]} (log: $log)" >&2
    exit 1
fi
