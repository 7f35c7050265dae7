"""The temporal network value type: timepoints, requirement links and contingent links.

An STNU (Morris, Muscettola & Vidal 2001) is a set of timepoints with two kinds of links:

* a **requirement link** ``(A, B, lb, ub)`` demands ``lb <= T(B) - T(A) <= ub``; ``None`` for a bound
  means "no bound" (this is the module's `INF` convention: ``INF is None``);
* a **contingent link** ``(A, C, lb, ub)`` says that once ``A`` is executed, nature executes ``C`` at
  some ``T(C) - T(A)`` in ``[lb, ub]`` that the agent only observes when it happens.

An STN is an STNU without contingent links. All numbers are exact integers (ticks); conversion from
seconds or decimal text happens at the edges (`hrc.temporal.ticks`). There is no implicit origin: a
file format that has one (the CSTNU Tool's ``Z``) adds its edges when it is read.

Contingent links need ``0 <= lb <= ub < INF``: ``lb == ub`` (HEATlab has such links) and ``lb == 0``
are accepted, which is what the formats allow; the algorithms handle both. A timepoint may be the
target of at most one contingent link (it is *that link's* contingent timepoint), and a contingent
link's target must not be its own activation timepoint.

>>> n = STNU(("A", "C"), (), (ContingentLink("A", "C", 1, 3),))
>>> n.contingent_timepoints
frozenset({'C'})
"""

from __future__ import annotations

import operator
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from hrc.caches import make_room
from hrc.errors import HrcError

__all__ = ["INF", "ContingentLink", "NetworkError", "RequirementLink", "STNU", "bound_count", "lineage"]

INF = None
"""Marks a missing bound of a requirement link (``lb=INF`` is -infinity, ``ub=INF`` is +infinity)."""


_SOURCE, _TARGET = operator.attrgetter("source"), operator.attrgetter("target")


class NetworkError(HrcError):
    """An STNU was built from inconsistent parts (unknown timepoint, ``lb > ub``, two contingent
    links onto one timepoint, ...). This is misuse of the API, not an expected verdict."""


def _check_int(value: object, what: str, link: RequirementLink | ContingentLink) -> None:
    """`value` (a bound of `link`, `what`: e.g. "lower bound of") must be an int (not a bool). The
    message is built only on failure: networks are built by the thousand in a compile."""
    if type(value) is not int and (isinstance(value, bool) or not isinstance(value, int)):
        raise NetworkError(f"{what} {link.source}->{link.target} must be an integer number of ticks, got {value!r}")


@dataclass(frozen=True, slots=True)
class RequirementLink:
    """``lb <= T(target) - T(source) <= ub``; ``None`` (= `INF`) leaves that side unbounded."""

    source: str
    target: str
    lb: int | None
    ub: int | None

    def __post_init__(self) -> None:
        lb, ub = self.lb, self.ub
        # the usual case in one expression (a compile builds links by the million), the rest checked in turn
        if (lb is None or type(lb) is int) and (ub is None or type(ub) is int) and (lb is None or ub is None
                                                                                    or lb <= ub):
            return
        if lb is not None:
            _check_int(lb, "lower bound of", self)
        if ub is not None:
            _check_int(ub, "upper bound of", self)
        if lb is not None and ub is not None and lb > ub:
            raise NetworkError(f"requirement {self.source}->{self.target}: lb {lb} > ub {ub}")

    def __str__(self) -> str:
        lb = "-inf" if self.lb is None else str(self.lb)
        ub = "+inf" if self.ub is None else str(self.ub)
        return f"{self.target} - {self.source} in [{lb}, {ub}]"


@dataclass(frozen=True, slots=True)
class ContingentLink:
    """Nature picks ``T(target) - T(source)`` in ``[lb, ub]`` (``0 <= lb <= ub``) after ``source``."""

    source: str
    target: str
    lb: int
    ub: int

    def __post_init__(self) -> None:
        if type(self.lb) is int and type(self.ub) is int and 0 <= self.lb <= self.ub and self.source != self.target:
            return  # the usual case in one expression; the rest checked in turn
        _check_int(self.lb, "lower bound of contingent", self)
        _check_int(self.ub, "upper bound of contingent", self)
        if not 0 <= self.lb <= self.ub:
            raise NetworkError(
                f"contingent {self.source}->{self.target}: need 0 <= lb <= ub, got [{self.lb}, {self.ub}]"
            )
        if self.source == self.target:
            raise NetworkError(f"contingent link {self.source}->{self.target} is a loop")

    def __str__(self) -> str:
        return f"{self.target} - {self.source} in [{self.lb}, {self.ub}] (contingent)"


Lineage = tuple["STNU", int, tuple[RequirementLink, ...], bool]
_LINEAGE: dict[int, tuple[STNU, Lineage]] = {}  # by identity, the last few derived networks (kept alive here)


def lineage(stnu: STNU) -> Lineage | None:
    """How `stnu` was derived, if it is one of the last few networks `STNU.truncated` or `STNU.inserted`
    made: ``(parent, at, links, rest)``, its requirement links being the parent's first `at`, then
    `links`, then (if `rest`) the parent's others. Readers that keep per-network arrays (the native
    core's, `hrc.temporal.rul.edge_arrays`) derive the child's from the parent's instead of reading
    all of its links again."""
    hit = _LINEAGE.get(id(stnu))
    return hit[1] if hit is not None and hit[0] is stnu else None


def _derived(parent: STNU, child: STNU, at: int, links: tuple[RequirementLink, ...], rest: bool) -> STNU:
    make_room(_LINEAGE, 16)
    _LINEAGE[id(child)] = (child, (parent, at, links, rest))
    return child


def bound_count(links: Sequence[RequirementLink]) -> int:
    """The finite bounds of `links`: the edges of the distance graph they make."""
    return sum((r.lb is not None) + (r.ub is not None) for r in links)


@dataclass(frozen=True, slots=True)
class STNU:
    """An immutable STNU; validated on construction (raises `NetworkError`).

    ``timepoints`` fixes the order used by every algorithm (and so every output); names are unique.
    """

    timepoints: tuple[str, ...]
    requirements: tuple[RequirementLink, ...] = ()
    contingents: tuple[ContingentLink, ...] = ()
    name: str = ""

    def __post_init__(self) -> None:
        for field_name in ("timepoints", "requirements", "contingents"):
            if not isinstance(getattr(self, field_name), tuple):
                object.__setattr__(self, field_name, tuple(getattr(self, field_name)))
        known = set(self.timepoints)
        reqs, conts = self.requirements, self.contingents
        # the usual case in a few set operations (a compile builds networks by the thousand); anything
        # else (a subclass of a link, a problem) goes through `_diagnose`, which names the first problem
        if (len(known) == len(self.timepoints) and set(map(type, reqs)) <= {RequirementLink}
                and set(map(type, conts)) <= {ContingentLink}):
            ends = set(map(_SOURCE, reqs))
            targets = set(map(_TARGET, conts))
            ends.update(map(_TARGET, reqs), map(_SOURCE, conts), targets)
            if ends <= known and len(targets) == len(conts):
                return
        self._diagnose(known)

    def _diagnose(self, known: set[str]) -> None:
        """Raise `NetworkError` for the first problem of the network, if any (one link at a time)."""
        if len(known) != len(self.timepoints):
            seen: set[str] = set()
            dup = next(t for t in self.timepoints if t in seen or seen.add(t))  # type: ignore[func-returns-value]
            raise NetworkError(f"timepoint {dup!r} is listed twice")
        for link in (*self.requirements, *self.contingents):
            if not isinstance(link, RequirementLink | ContingentLink):
                raise NetworkError(f"not a link: {link!r}")
            for end in (link.source, link.target):
                if end not in known:
                    raise NetworkError(f"link {link} names unknown timepoint {end!r}")
        targets: set[str] = set()
        for link in self.contingents:
            if not isinstance(link, ContingentLink):
                raise NetworkError(f"contingents must hold ContingentLink, got {link!r}")
            if link.target in targets:
                raise NetworkError(f"timepoint {link.target!r} is the target of two contingent links")
            targets.add(link.target)
        for link in self.requirements:
            if not isinstance(link, RequirementLink):
                raise NetworkError(f"requirements must hold RequirementLink, got {link!r}")

    @property
    def contingent_timepoints(self) -> frozenset[str]:
        """The timepoints nature executes (targets of contingent links)."""
        return frozenset(c.target for c in self.contingents)

    @property
    def n_edges(self) -> int:
        """Number of finite bounds, i.e. edges of the distance graph from requirement links."""
        return bound_count(self.requirements)

    def truncated(self, n: int) -> STNU:
        """The network with only its first `n` requirement links. Nothing to check again (a part of a
        checked network): a compiler derives networks by the thousand."""
        return _derived(self, self._unchecked(self.requirements[:n]), n, (), False)

    def inserted(self, at: int, links: tuple[RequirementLink, ...]) -> STNU:
        """The network with the requirement `links` inserted before its requirement link number `at`.
        Only they are checked (a link, between timepoints of the network)."""
        known = set(self.timepoints)
        for link in links:
            if type(link) is not RequirementLink or link.source not in known or link.target not in known:
                reqs = self.requirements  # built in full, which names the problem
                return STNU(self.timepoints, reqs[:at] + tuple(links) + reqs[at:], self.contingents, self.name)
        return _derived(self, self._unchecked(self.requirements[:at] + tuple(links) + self.requirements[at:]), at,
                        tuple(links), True)

    def _unchecked(self, requirements: tuple[RequirementLink, ...]) -> STNU:
        net = object.__new__(STNU)
        for field_name, value in (("timepoints", self.timepoints), ("requirements", requirements),
                                  ("contingents", self.contingents), ("name", self.name)):
            object.__setattr__(net, field_name, value)
        return net

    def renamed(self, names: Mapping[str, str], name: str | None = None) -> STNU:
        """The same network with every timepoint ``t`` called ``names[t]`` (the same order and links;
        `name`: the network's new name, if given). Raises `NetworkError` if two timepoints would share a
        name, and KeyError for a timepoint `names` leaves out."""
        return STNU(tuple(names[t] for t in self.timepoints),
                    tuple(RequirementLink(names[r.source], names[r.target], r.lb, r.ub) for r in self.requirements),
                    tuple(ContingentLink(names[c.source], names[c.target], c.lb, c.ub) for c in self.contingents),
                    self.name if name is None else name)

    def as_stn(self) -> STNU:
        """The STN obtained by treating every contingent link as a requirement link."""
        extra = tuple(RequirementLink(c.source, c.target, c.lb, c.ub) for c in self.contingents)
        return STNU(self.timepoints, self.requirements + extra, (), self.name)
