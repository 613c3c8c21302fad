"""Roles as Zenoh access control: the ``access_control`` section for one session, by its role.

Zenoh enforces it where the traffic passes (the router, and each session's own links), deny by
default. Its subjects are peers' certificate common names (known only over mutual TLS); rules
allow message kinds on key expressions, per direction (``ingress``: from that peer,
``egress``: to it). A rule allows a message when one of its key expressions *includes* the
message's, so a monitor's subscription to ``rover/*/state`` needs ``rover/**``, not each rover's
key. Measured with eclipse-zenoh 1.10 (tests/bus/test_zenoh_tls.py):

- at the router: a rover may put only under ``rover/<its name>/**``, declare and answer only its
  own ``rover/<its name>/control``, and is sent only queries for that; an operator may
  subscribe to ``rover/**`` and query ``rover/*/control``; a monitor may only subscribe;
  routers relay everything for each other. Anything else (a rover's query, a monitor's, a
  rover publishing another's state, any other key) is dropped.
- in a rover's own session: it sends only its own state / status and control replies, takes
  only queries for its own control (from routers and operators) and subscriptions (from
  routers, operators, monitors): the rover keeps its promise even to a peer connected straight
  to it, and a bug in it cannot publish under another name.
- in a monitor's or operator's session: only what the role needs, from routers and rovers.

Peers also learn the other side's declarations (a peer-mode rover publishes only to those it
knows subscribe), so the router also lets subscriptions out to rovers and queryables out to
operators.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

from .roles import MONITOR, OPERATOR, ROUTER, ROVER

ALL_MESSAGES = ["put", "delete", "declare_subscriber", "query", "reply", "declare_queryable",
                "liveliness_token", "liveliness_query", "declare_liveliness_subscriber"]
FLEET = "rover/**"
CONTROLS = "rover/*/control"


def own_keys(name: str) -> str:
    return f"rover/{name}/**"


def own_control(name: str) -> str:
    return f"rover/{name}/control"


class _Builder:
    """Rules, subjects and policies, each with a unique id, in Zenoh's schema."""

    def __init__(self) -> None:
        self.rules: list[dict[str, Any]] = []
        self.subjects: list[dict[str, Any]] = []
        self.policies: list[dict[str, Any]] = []

    def rule(self, rid: str, flow: str, messages: list[str], key_exprs: list[str]) -> str:
        # One flow per rule: Zenoh allows every (flow, message, key) combination of a rule.
        self.rules.append({"id": rid, "permission": "allow", "flows": [flow],
                           "messages": messages, "key_exprs": key_exprs})
        return rid

    def subject(self, sid: str, names: Iterable[str]) -> str | None:
        names = sorted(set(names))
        if not names:
            return None       # Zenoh refuses an empty list (and an absent one means anyone)
        self.subjects.append({"id": sid, "cert_common_names": names})
        return sid

    def policy(self, rules: list[str], subjects: list[str | None]) -> None:
        subjects = [s for s in subjects if s is not None]
        if subjects:
            self.policies.append({"rules": rules, "subjects": subjects})

    def config(self) -> dict[str, Any]:
        return {"enabled": True, "default_permission": "deny", "rules": self.rules,
                "subjects": self.subjects, "policies": self.policies}


def access_control(role: str, name: str, roster: Mapping[str, Iterable[str]]) -> dict[str, Any]:
    """The ``access_control`` value for a session of ``role`` named ``name``; ``roster`` maps
    each role to the names of the certificates that hold it."""
    names = {r: sorted(set(roster.get(r, ()))) for r in (ROVER, OPERATOR, MONITOR, ROUTER)}
    b = _Builder()
    routers = b.subject("routers", names[ROUTER])
    operators = b.subject("operators", names[OPERATOR])
    monitors = b.subject("monitors", names[MONITOR])
    if role == ROUTER:
        _router(b, names[ROVER], routers, operators, monitors)
    elif role == ROVER:
        tells = b.rule("tell own state and status", "egress", ["put", "delete"], [own_keys(name)])
        answers = b.rule("answer own control", "egress", ["declare_queryable", "reply"],
                         [own_control(name)])
        asked = b.rule("take queries for own control", "ingress", ["query"], [own_control(name)])
        watched = b.rule("take subscriptions", "ingress", ["declare_subscriber"], [FLEET])
        b.policy([tells, answers, asked, watched], [routers, operators])
        b.policy([tells, watched], [monitors])
    else:
        rovers = b.subject("rovers", names[ROVER])
        hear = b.rule("hear the fleet", "ingress", ["put", "delete"], [FLEET])
        listen = b.rule("subscribe to the fleet", "egress", ["declare_subscriber"], [FLEET])
        rules = [hear, listen]
        if role == OPERATOR:
            rules += [b.rule("ask controls", "egress", ["query"], [CONTROLS]),
                      b.rule("hear control replies", "ingress", ["declare_queryable", "reply"],
                             [CONTROLS])]
        b.policy(rules, [routers, rovers])
    return b.config()


def _router(b: _Builder, rovers: list[str], routers: str | None, operators: str | None,
            monitors: str | None) -> None:
    told = b.rule("told who subscribes", "egress", ["declare_subscriber"], [FLEET])
    for rover in rovers:
        subject = b.subject(f"rover {rover}", [rover])
        b.policy([b.rule(f"{rover} publishes its own", "ingress", ["put", "delete"],
                         [own_keys(rover)]),
                  b.rule(f"{rover} answers its own control", "ingress",
                         ["declare_queryable", "reply"], [own_control(rover)]),
                  b.rule(f"{rover} is asked on its own control", "egress", ["query"],
                         [own_control(rover)]),
                  told], [subject])
    subscribe = b.rule("subscribe to the fleet", "ingress", ["declare_subscriber"], [FLEET])
    hear = b.rule("hear the fleet", "egress", ["put", "delete"], [FLEET])
    b.policy([subscribe, hear], [operators, monitors])
    b.policy([b.rule("ask controls", "ingress", ["query"], [CONTROLS]),
              b.rule("hear control replies", "egress", ["declare_queryable", "reply"],
                     [CONTROLS])], [operators])
    # Router to router (a site with several): each filtered its own edge already.
    b.policy([b.rule(f"relay {flow}", flow, ALL_MESSAGES, ["**"])
              for flow in ("ingress", "egress")], [routers])
