"""A control law's own fields in a FollowerState: their declaration and their checks.

A law (agents.law.interface) declares the numeric fields it publishes to its neighbours,
each with a kind, a bound and optionally the field that is its rate.  On the wire they
are a map from name to value in `FollowerState.law` (transport.codec), by kind:
- "scalar":   a float;
- "vec2":     a plane vector (x, y);
- "per_link": one plane vector per neighbour, ((j, x, y), ...): a receiver reads only
  the entry addressed to it (j = its own index), as the robust estimator's link sums.

The codec checks structure (types, finiteness, at most `MAX_FIELDS` names of at most
`MAX_NAME` characters, at most `MAX_LINKS` entries per field); a receiver that knows the
law checks the rest with `reason`: only declared names, each of its declared kind and
within its bound.  Pure and law-agnostic: transport knows nothing of any law.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

KINDS = ("scalar", "vec2", "per_link")
MAX_FIELDS = 16
MAX_NAME = 64
MAX_LINKS = 256
MAX_BOUND = 1e150  # squared, still a finite float: magnitudes are compared squared

LinkValue = tuple[int, float, float]  # (neighbour index, x, y)
LawValue = float | tuple[float, float] | tuple[LinkValue, ...]
LawFields = Mapping[str, LawValue]
NO_FIELDS: LawFields = {}


@dataclass(frozen=True)
class FieldSpec:
    """One field a law publishes.  `bound`: the largest magnitude (|value|, or |(x, y)|)
    a receiver accepts (at most MAX_BOUND); beyond it the message is a forgery or a fault
    and is dropped, as the platform's own positions beyond 100 km are.  `rate`: the name
    of the field that is this one's time derivative (same kind): a receiver extrapolates
    this field by it from the message's stamp, held after the hold limit, as it does the
    estimate r.  `odd`: a per_link field whose two ends cancel (x_ij + x_ji ~ 0, as the
    robust estimator's link sums): a receiver may hold a neighbour to that."""

    name: str
    kind: str
    bound: float
    rate: str | None = None
    odd: bool = False

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"field {self.name!r}: kind {self.kind!r} not in {KINDS}")
        if not (0 < len(self.name) <= MAX_NAME and self.name.isidentifier()):
            raise ValueError(f"field name {self.name!r}: an identifier of <= {MAX_NAME} chars")
        if not 0.0 < self.bound <= MAX_BOUND:
            raise ValueError(f"field {self.name!r}: bound must be in (0, {MAX_BOUND:g}]")
        if self.odd and self.kind != "per_link":
            raise ValueError(f"field {self.name!r}: only a per_link field can be odd")


def check_specs(specs: Iterable[FieldSpec]) -> dict[str, FieldSpec]:
    """The declaration by name; ValueError naming the field if it is not a usable one."""
    out: dict[str, FieldSpec] = {}
    for spec in specs:
        if spec.name in out:
            raise ValueError(f"field {spec.name!r} declared twice")
        out[spec.name] = spec
    if len(out) > MAX_FIELDS:
        raise ValueError(f"at most {MAX_FIELDS} fields, got {len(out)}")
    for spec in out.values():
        if spec.rate is None:
            continue
        rate = out.get(spec.rate)
        if rate is None or rate is spec or rate.kind != spec.kind:
            raise ValueError(f"field {spec.name!r}: rate {spec.rate!r} must be another "
                             f"declared field of kind {spec.kind}")
    return out


def _link_reason(value: tuple[Any, ...], bound2: float) -> str | None:
    """`reason` for a per_link value: entries (j >= 0, x, y), finite, |(x, y)|^2 <= bound2."""
    if len(value) > MAX_LINKS:
        return "law_kind"
    for link in value:
        if type(link) is not tuple or len(link) != 3:
            return "law_kind"
        j, x, y = link
        if type(j) is not int or j < 0 or type(x) is not float or type(y) is not float \
                or x - x + y - y != 0.0:
            return "law_kind"
        if not x * x + y * y <= bound2:
            return "law_bound"
    return None


def reason(fields: LawFields, specs: Mapping[str, FieldSpec]) -> str | None:
    """None if `fields` hold only declared names, each of its kind, finite and in bounds;
    else why not: "law_undeclared", "law_kind" (wrong shape or not finite), "law_bound".

    Every received state of a law with fields comes through here: one pass, no call per
    field but the per-link one (a bound is compared squared, so overflow is "beyond")."""
    for name, value in fields.items():
        spec = specs.get(name)
        if spec is None:
            return "law_undeclared"
        kind, bound2 = spec.kind, spec.bound * spec.bound
        if kind == "scalar":
            if type(value) is not float or value - value != 0.0:
                return "law_kind"
            if not value * value <= bound2:
                return "law_bound"
            continue
        if type(value) is not tuple:
            return "law_kind"
        if kind == "vec2":
            if len(value) != 2:
                return "law_kind"
            x, y = value
            if type(x) is not float or type(y) is not float or x - x + y - y != 0.0:
                return "law_kind"
            if not x * x + y * y <= bound2:
                return "law_bound"
            continue
        why = _link_reason(value, bound2)
        if why is not None:
            return why
    return None
