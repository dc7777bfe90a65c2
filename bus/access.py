"""The router's access control, written from the key scheme (:data:`bus.keys.SCHEME`).

Default deny.  Each session is known by its certificate's common name
(``coordinator``, ``predictor``, ``taxi-<i>``; see :mod:`bus.certs`), and is
allowed exactly what its role does with each key, in each direction through
the router:

===============  ===================================================  ==========================
use of the key   the writer may                                       a reader may
===============  ===================================================  ==========================
published        ``put`` (in); learn of subscribers (out)             declare a subscriber (in),
                                                                      receive ``put`` (out)
queryable        declare the queryable, ``reply`` (in); receive       ``query`` (in), learn of the
                 ``query`` (out)                                      queryable, receive ``reply`` (out)
liveliness       declare the token (in)                               declare a liveliness subscriber
                                                                      or query (in), receive tokens (out)
===============  ===================================================  ==========================

("in" is ingress to the router, from the session; "out" is egress, to it.)
A writer must learn of the subscribers: zenoh filters on the writer's
side, and a publisher that knows of none sends nothing.

A taxi writes only its own per-agent keys (``control/<i>``, ``alive/<i>``)
and reads only its own ``turn/<i>``.  So one key has one writer: nobody but
the coordinator can publish a state, a turn, a committed control or stop, or
answer ``spec``; nobody but taxi *i* can propose taxi *i*'s control.  The
forecast keys are the exception the scheme names: the predictor service or
the coordinator may publish them (``also_written_by``).
"""

from __future__ import annotations

from collections import defaultdict

from bus.certs import taxi_name
from bus.keys import (
    COORDINATOR,
    PREDICTOR,
    PUB,
    QUERYABLE,
    SCHEME,
    TAXI,
    TOKEN,
    Channel,
    key,
    root,
)

INGRESS, EGRESS = "ingress", "egress"
#: (use, writing?) -> [(flow, messages)]
_MESSAGES: dict[tuple[str, bool], list[tuple[str, tuple[str, ...]]]] = {
    (PUB, True): [(INGRESS, ("put",)), (EGRESS, ("declare_subscriber",))],
    (PUB, False): [(INGRESS, ("declare_subscriber",)), (EGRESS, ("put",))],
    (QUERYABLE, True): [(INGRESS, ("declare_queryable", "reply")), (EGRESS, ("query",))],
    (QUERYABLE, False): [(INGRESS, ("query",)), (EGRESS, ("reply", "declare_queryable"))],
    (TOKEN, True): [(INGRESS, ("liveliness_token",))],
    (TOKEN, False): [(INGRESS, ("declare_liveliness_subscriber", "liveliness_query")), (EGRESS, ("liveliness_token",))],
}


#: Declarations a writer (or querier) is told of, so that it sends at all: zenoh filters on the writer's side.
_DECLARATIONS = {"declare_subscriber", "declare_queryable"}


def _key_for(channel: Channel, run_root: str, role: str, index: int | None, writing: bool, flow: str,
             messages: tuple[str, ...]) -> str:
    """A taxi's own per-agent key, or every agent's; a writer learns of subscriptions to every agent's."""
    if channel.per_sector:
        return key(run_root, channel.name, "*")
    if not channel.per_agent:
        return key(run_root, channel.name)
    learning = flow == EGRESS and _DECLARATIONS.issuperset(messages)
    own = role == TAXI and (writing or channel.own_only) and not learning
    return key(run_root, channel.name, index if own else "*")


def grants(role: str, index: int | None = None, run: str | None = None) -> list[tuple[str, tuple[str, ...], str]]:
    """What identity (``role``, ``index``) may do: ``(flow, messages, key expression)`` triples."""
    run_root = root(run)
    out = []
    for channel in SCHEME:
        uses = [(channel.use, True, role in channel.writers), (channel.use, False, role in channel.readers)]
        if channel.answered_by is not None:
            uses += [(QUERYABLE, True, role == channel.answered_by), (QUERYABLE, False, role in channel.readers)]
        for use, writing, applies in uses:
            if applies:
                out += [(flow, msgs, _key_for(channel, run_root, role, index, writing, flow, msgs))
                        for flow, msgs in _MESSAGES[(use, writing)]]
    return out


def identities(taxis: int) -> list[tuple[str, str, int | None]]:
    """Every identity of a fleet of ``taxis``: ``(common name, role, taxi index)``."""
    return [(COORDINATOR, COORDINATOR, None), (PREDICTOR, PREDICTOR, None),
            *((taxi_name(i), TAXI, i) for i in range(taxis))]


def access_control(taxis: int, run: str | None = None) -> dict:
    """The ``access_control`` block of the router's zenoh config for a fleet of ``taxis`` (``run=None``: any run).

    A grant shared by several identities (every taxi reads ``state``) is one
    rule; rules granted to the same identities form one policy.
    """
    holders: dict[tuple[str, tuple[str, ...], str], list[str]] = defaultdict(list)
    for name, role, index in identities(taxis):
        for grant in grants(role, index, run):
            holders[grant].append(name)
    rules, by_subjects = [], defaultdict(list)
    for (flow, msgs, k), names in holders.items():
        rule_id = f"{flow} {'+'.join(msgs)} {k}"
        rules.append({"id": rule_id, "permission": "allow", "flows": [flow], "messages": list(msgs), "key_exprs": [k]})
        by_subjects[tuple(names)].append(rule_id)
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": [{"id": name, "cert_common_names": [name]} for name, _, _ in identities(taxis)],
        "policies": [{"rules": ids, "subjects": list(names)} for names, ids in by_subjects.items()],
    }
