"""The swarm's Zenoh `access_control` section: who may publish what.

Every peer carries the same rules and enforces them on its own ingress (in peer mode a
peer enforces only its own ACL: notes/security.md).  Subjects are certificate common
names (mTLS, see transport.credentials), so a rule is bound to an authenticated process.

- Everybody in the swarm may declare subscribers, liveliness subscribers and queries on
  the swarm's keys, both ways (with default deny, the subscribing node must also allow
  egress `declare_subscriber`, or publishers never route to it).
- Everybody may send (egress) puts and tokens: a receiver decides, on its ingress.
- Ingress puts and liveliness tokens are allowed per process, on its own keys only:
  follower i its states (both rates), status and token; the simulator sensor and truth keys; targets
  and the recorder their status; only the launcher run control.
- Across hosts (deploy.hosts.host_keys), a router relays for others, and a rule binds the *link*
  a message arrived on, never the process that made it (Zenoh 1.10's ACL interceptor is
  built per transport from its peer's certificate).  So each host's ACL is its own
  (`here`): its own router and the first host's (the hub of the star every other router
  links to) relay every key; any other host's router only the keys of that host's own
  processes and its clock probes.  A stolen host folder, router key and all, then puts
  nothing past the other hosts' ingress but what its own processes may.
Anything else, and any link without a swarm certificate, is denied.
"""

from __future__ import annotations

from collections.abc import Sequence

from transport.key_exprs import SwarmKeys

READ_MESSAGES = ["declare_subscriber", "declare_liveliness_subscriber", "liveliness_query",
                 "query", "reply"]
WRITE_MESSAGES = ["put", "liveliness_token"]


def process_names(n_followers: int, n_targets: int, n_routers: int = 0) -> list[str]:
    """Every process of a swarm run, by the name its certificate carries; `router-<k>` is
    the Zenoh router of host k in a swarm over several hosts (deploy.hosts)."""
    return (["launcher", "sim", "recorder"] + [f"follower-{i}" for i in range(n_followers)]
            + [f"target-{j}" for j in range(n_targets)]
            + [f"router-{k}" for k in range(n_routers)])


def sender_id(name: str) -> str:
    """The sender id process `name` stamps its messages with: `follower-2`, `router-1`;
    the processes of one (launcher, sim, recorder) carry index 0 (`sim-0`)."""
    role, _, idx = name.rpartition("-")
    return name if role and idx.isdigit() else f"{name}-0"


def sender_ids(n_followers: int, n_targets: int, n_routers: int = 0) -> frozenset[str]:
    """Every sender of a swarm run: whatever else a message claims is refused
    (transport.decoder), so no table a receiver keeps per sender outgrows the scenario."""
    return frozenset(map(sender_id, process_names(n_followers, n_targets, n_routers)))


HUB = 0  # the router every other host's links to (deploy.hosts.deployment.router_links)


def relayed_keys(keys: SwarmKeys, k: int, hosts: Sequence[Sequence[str]] | None,
                 here: int | None, n_followers: int) -> list[str]:
    """The keys router k's link may bring into a process of host `here`: all of them from
    this host's own router and from the hub (they relay for every host), or when the hosts
    are not known; else what host k's own processes may put, and k's clock probes.  The
    simulator's sensing of a follower on host k comes to k straight (sim_backend.sensor_links)
    and goes no further: the hub's recorder records the sensing of its own host only."""
    if hosts is None or k in (here, HUB):
        return [keys.everything()]
    sensing = {keys.sensor_targets(i) for i in range(n_followers)}
    out = [key for name in hosts[k] for key in own_keys(keys, name, n_followers)
           if key not in sensing]
    return [*out, keys.clock("router", k)]


def own_keys(keys: SwarmKeys, name: str, n_followers: int) -> list[str]:
    """The keys process `name` may publish on (put, liveliness token); a router's are its
    host's (`relayed_keys`)."""
    role, _, idx = name.rpartition("-")
    if role == "router":  # without hosts: relays everybody's, trusted like the network
        return [keys.everything()]
    if name in ("launcher", "sim", "recorder"):
        role, i = name, 0
    else:
        i = int(idx)
    out = [keys.status(role, i), keys.alive(role, i)]
    if role == "follower":
        out += [keys.follower_state(i), keys.follower_estimate(i)]
    elif role == "sim":
        out += [keys.truth()] + [keys.sensor_targets(k) for k in range(n_followers)]
    elif role == "launcher":
        out.append(keys.control())
    return out


def _rule(rule_id: str, messages: list[str], flows: list[str], key_exprs: list[str]) -> dict:
    return {"id": rule_id, "messages": messages, "flows": flows, "permission": "allow",
            "key_exprs": key_exprs}


def access_control(keys: SwarmKeys, n_followers: int, n_targets: int, n_routers: int = 0,
                   hosts: Sequence[Sequence[str]] | None = None,
                   here: int | None = None) -> dict[str, object]:
    """The `access_control` config section for a swarm of n followers and m targets
    (and its hosts' routers: each checks its own clients' puts on ingress).  `hosts`: the
    processes of each host k (router-k's), for the ACL of host `here`'s processes: what
    another host's router relays to them is only its own host's (`relayed_keys`)."""
    if hosts is not None and len(hosts) != n_routers:
        raise ValueError(f"{len(hosts)} hosts for {n_routers} routers")
    names = process_names(n_followers, n_targets, n_routers)
    rules = [_rule("read", READ_MESSAGES, ["ingress", "egress"], [keys.everything()]),
             _rule("send", WRITE_MESSAGES, ["egress"], [keys.everything()])]
    subjects: list[dict[str, object]] = [{"id": "swarm", "cert_common_names": names}]
    policies: list[dict[str, object]] = [{"rules": ["read", "send"], "subjects": ["swarm"]}]
    for name in names:
        role, _, idx = name.rpartition("-")
        mine = (relayed_keys(keys, int(idx), hosts, here, n_followers) if role == "router"
                else own_keys(keys, name, n_followers))
        rules.append(_rule(f"own-{name}", WRITE_MESSAGES, ["ingress"], mine))
        subjects.append({"id": f"is-{name}", "cert_common_names": [name]})
        policies.append({"rules": [f"own-{name}"], "subjects": [f"is-{name}"]})
    return {"enabled": True, "default_permission": "deny", "rules": rules,
            "subjects": subjects, "policies": policies}
