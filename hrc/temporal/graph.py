"""Distance graphs of STNs and the labelled distance graph of an STNU.

An edge ``u --w--> v`` means ``T(v) - T(u) <= w`` (Dechter, Meiri & Pearl 1991). A requirement link
``lb <= T(B) - T(A) <= ub`` gives ``A --ub--> B`` and ``B --(-lb)--> A``. A contingent link ``(A, C, l, u)``
gives the ordinary pair ``A --u--> C``, ``C --(-l)--> A`` plus, in the labelled distance graph of
Morris & Muscettola (2005, section 3), the lower-case edge ``A --c:l--> C`` and the upper-case edge
``C --C:-u--> A``, both labelled with the contingent timepoint ``C``.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from hrc.temporal.network import STNU

__all__ = ["Edge", "EdgeKind", "distance_edges", "labelled_edges"]


class EdgeKind(enum.Enum):
    ORDINARY = "ordinary"
    LOWER = "lower-case"
    UPPER = "upper-case"
    DERIVED = "derived"  # an ordinary edge added by a DC algorithm


@dataclass(frozen=True, slots=True)
class Edge:
    """``T(target) - T(source) <= value``; for ``LOWER``/``UPPER`` edges, ``label`` names the
    contingent timepoint (printed lower case ``c:`` or upper case ``C:`` as in the literature)."""

    source: str
    target: str
    value: int
    kind: EdgeKind = EdgeKind.ORDINARY
    label: str = ""

    def __str__(self) -> str:
        if self.kind is EdgeKind.LOWER:
            tag = f"lc({self.label}):{self.value}"
        elif self.kind is EdgeKind.UPPER:
            tag = f"UC({self.label}):{self.value}"
        elif self.kind is EdgeKind.DERIVED:
            tag = f"{self.value} derived"
        else:
            tag = str(self.value)
        return f"{self.source} --[{tag}]--> {self.target}"

    def to_json(self) -> dict[str, object]:
        return {"source": self.source, "target": self.target, "value": self.value,
                "kind": self.kind.value, "label": self.label}


def distance_edges(stnu: STNU, *, contingent_as_requirement: bool = True) -> list[Edge]:
    """Ordinary edges of the distance graph, in link order (requirements, then contingents)."""
    out: list[Edge] = []
    for r in stnu.requirements:
        if r.ub is not None:
            out.append(Edge(r.source, r.target, r.ub))
        if r.lb is not None:
            out.append(Edge(r.target, r.source, -r.lb))
    if contingent_as_requirement:
        for c in stnu.contingents:
            out.append(Edge(c.source, c.target, c.ub))
            out.append(Edge(c.target, c.source, -c.lb))
    return out


def labelled_edges(stnu: STNU) -> list[Edge]:
    """The labelled distance graph: ordinary edges (contingent pairs included) plus one lower-case
    and one upper-case edge per contingent link (Morris & Muscettola 2005)."""
    out = distance_edges(stnu)
    for c in stnu.contingents:
        out.append(Edge(c.source, c.target, c.lb, EdgeKind.LOWER, c.target))
        out.append(Edge(c.target, c.source, -c.ub, EdgeKind.UPPER, c.target))
    return out
