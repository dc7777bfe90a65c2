#!/usr/bin/env bash
# Two network "hosts" on one Linux machine (network namespaces joined by a veth pair),
# to try a run across hosts without a second machine. Needs root (or CAP_NET_ADMIN).
#
#   deploy/netns.sh up [PREFIX]     create PREFIX-h1 (10.77.0.1) and PREFIX-h2 (10.77.0.2)
#   deploy/netns.sh down [PREFIX]   remove them
#
# Then run a command on a "host" with: ip netns exec PREFIX-h1 <command>
set -euo pipefail
cmd=${1:-}
p=${2:-surge}
case "$cmd" in
  up)
    ip netns add "$p-h1"
    ip netns add "$p-h2"
    ip link add "$p-v1" type veth peer name "$p-v2"
    ip link set "$p-v1" netns "$p-h1"
    ip link set "$p-v2" netns "$p-h2"
    ip -n "$p-h1" addr add 10.77.0.1/24 dev "$p-v1"
    ip -n "$p-h2" addr add 10.77.0.2/24 dev "$p-v2"
    for h in h1 h2; do ip -n "$p-$h" link set lo up; done
    ip -n "$p-h1" link set "$p-v1" up
    ip -n "$p-h2" link set "$p-v2" up
    ;;
  down)
    ip netns del "$p-h1" 2>/dev/null || true
    ip netns del "$p-h2" 2>/dev/null || true
    ;;
  *)
    echo "usage: $0 up|down [PREFIX]" >&2
    exit 2
    ;;
esac
