#!/usr/bin/env bash
# Network "hosts" on one Linux machine: network namespaces on one virtual switch (a bridge in a
# namespace of its own), to try a run across hosts without more machines. Needs root (or CAP_NET_ADMIN).
#
#   deploy/netns.sh up [PREFIX] [N]     create PREFIX-h1 (10.77.0.1) … PREFIX-hN (10.77.0.N); N is 3 by default
#   deploy/netns.sh down [PREFIX] [N]   remove them and the switch
#
# Then run a command on a "host" with: ip netns exec PREFIX-h1 <command>
set -euo pipefail
cmd=${1:-}
p=${2:-surge}
n=${3:-3}
case "$n" in ''|*[!0-9]*) echo "$0: N must be a number of hosts, 2 to 9" >&2; exit 2 ;; esac
if [ "$n" -lt 2 ] || [ "$n" -gt 9 ]; then echo "$0: N must be a number of hosts, 2 to 9" >&2; exit 2; fi
case "$cmd" in
  up)
    ip netns add "$p-sw"
    ip -n "$p-sw" link add "$p-br" type bridge
    ip -n "$p-sw" link set "$p-br" up
    for i in $(seq 1 "$n"); do
      ip netns add "$p-h$i"
      ip link add "$p-v$i" type veth peer name "$p-s$i"
      ip link set "$p-v$i" netns "$p-h$i"
      ip link set "$p-s$i" netns "$p-sw"
      ip -n "$p-sw" link set "$p-s$i" master "$p-br"
      ip -n "$p-sw" link set "$p-s$i" up
      ip -n "$p-h$i" addr add "10.77.0.$i/24" dev "$p-v$i"
      ip -n "$p-h$i" link set lo up
      ip -n "$p-h$i" link set "$p-v$i" up
    done
    ;;
  down)
    for i in $(seq 1 "$n"); do ip netns del "$p-h$i" 2>/dev/null || true; done
    ip netns del "$p-sw" 2>/dev/null || true
    ;;
  *)
    echo "usage: $0 up|down [PREFIX] [N]" >&2
    exit 2
    ;;
esac
