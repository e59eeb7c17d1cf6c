#!/bin/sh
# `make setup`'s Debian packages: apt-get update and install PACKAGE..., waiting up to APT_LOCK_WAIT seconds
# (default 600) for another apt or dpkg (unattended upgrades, a second `make setup`) instead of failing at
# once.  DPkg::Lock::Timeout makes install wait for the dpkg lock; update takes the package lists' lock, which
# that option does not cover (measured, apt 2.6), so update is retried for as long as that lock is the failure.
set -eu
wait_s=${APT_LOCK_WAIT:-600}
apt="apt-get -q -o DPkg::Lock::Timeout=$wait_s"
log=$(mktemp)
trap 'rm -f "$log"' EXIT
start=$(date +%s)
echo "make setup: apt-get update and install $* (waits up to $wait_s s for another apt or dpkg)"
until $apt update 2>"$log"; do
    if ! grep -q "Could not get lock" "$log" || [ $(($(date +%s) - start)) -ge "$wait_s" ]; then
        cat "$log" >&2
        exit 1
    fi
    echo "apt-get update: $(grep -m1 'Could not get lock' "$log" | sed 's/^E: //'); waiting"
    sleep 5
done
cat "$log" >&2                   # update's warnings, if any
DEBIAN_FRONTEND=noninteractive $apt install -y "$@"
