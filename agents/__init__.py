"""Taxi agents: routing policies, the policy registry and (per taxi) one-agent-at-a-time rollout."""
