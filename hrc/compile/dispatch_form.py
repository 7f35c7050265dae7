"""The dispatch form: what the compile hands the dispatcher, so that online work grows with what an
observation changes, not with the number of plans (Strassmair & Taylor 2014, section III: the compiler
"transforms the initial temporal plan into an optimized form ahead of execution" so that the dispatcher
only adjusts; Muscettola, Morris & Tsamardinos 1998).

``compiled.json`` is for people and other tools (gigabytes for a large task); the dispatcher reads
this instead: every plan of the compile, in rank order, as a few flat numpy arrays in the folder
``dispatch/`` beside ``compiled.json``, each a ``.npy`` file that `numpy.load` memory-maps:

``plans.npy`` (P,) structured, one row per plan:
    ``id`` (S16, the plan id, padded), ``rank`` (1 = best), ``cls`` (its class at compile time: 0 DC,
    1 consistent, 2 inconsistent), ``blocked`` (no motion pattern: never promised), ``preference`` (APA's
    value to 6 decimals as ``compiled.json`` gives it: the last bits of a QP's optimum are not the same
    from one computation to the next; NaN: none), ``n`` (its timepoints), ``shape`` (plans with the same
    shape number have the same network arrays, byte for byte), ``line_at`` / ``line_len`` (where its line
    lies in ``compiled.json``, in bytes, for a reader that wants one plan's motions without reading the file).
``seq.npy`` (P, G, A) int16: agent g's k-th action (an index into the task's actions), -1 after its last.
``nodes.npy`` (P, G, L, 6) int16: the timepoint of agent g's k-th leg's events (depart, park, unpark,
    arrive, start, end; `LEG_EVENTS`), -1 where the leg has none (park, unpark) or there is no k-th leg.
``edges_ptr.npy`` (P + 1,) int64 and ``edges_u.npy``, ``edges_v.npy`` (uint16), ``edges_w.npy`` (int32 or
    int64): plan p's distance edges are rows ``edges_ptr[p]:edges_ptr[p + 1]``, each ``T(v) - T(u) <= w``
    (ticks), one per ordered pair (parallel bounds merged: the tightest kept), sorted by (v, u).
``conts_ptr.npy`` (P + 1,) int64 and ``conts_a``, ``conts_c`` (uint16), ``conts_lb``, ``conts_ub`` (int32
    or int64): plan p's contingent links ``A --[lb, ub]--> C``.
``form.json``: the version, the task's digest, the shapes, and the SHA-256 of every array file; with
    ``sensing`` (as ``compiled.json`` has it, `hrc.compile.sensing.sensing_dict`) when the task states how
    the human's events reach the robot: ``cls`` is then the class under that observation delay.
``routes.npy`` (S, G, L, 3) int32 or int64 (as the weights), by shape number (S shapes): the route
    signature of agent g's k-th leg in every plan of that shape (`hrc.compile.route_signatures`; -1 where
    there is no such leg), what set validation reads of a leg under way. Beside the form, not in it:
    ``routes.json`` names its version (`ROUTES_VERSION`), the SHA-256 of the ``form.json`` it belongs to
    and its file's (shape, type, SHA-256), so ``form.json``, and with it ``compiled.json``, are the same
    bytes as before it existed. A form without it (written before) is still read: the dispatcher then
    makes the signatures as it needs them (`DispatchForm.routes` None).
``compiled.json``'s header names the SHA-256 of ``form.json`` (``"dispatch_form"``), so a form that is not
the one compiled with it (a file truncated, swapped, or from another compile) is refused when read.

**Numbering.** A plan's timepoints are numbered with the origin ``Z`` first, then in a topological order
of its orderings (requirement edges that put one timepoint no earlier than another whatever the
bounds), ties broken by (agent, leg position, event). Nothing in a plan's arrays names an action: the
network is by agent and leg position, and which action is at which position is `seq`. So two plans that
differ only by which of two identical actions comes where (`hrc.plans.identical_actions`) have the same
arrays, and the dispatcher evaluates such twins once (`shape`). The topological numbering makes the
dispatcher's longest-path sweeps, visited in index order, settle in one or two passes.

The form of one plan is built in the compile's worker as a record (`plan_record`, bytes, shared by a
family of relabelled plans), spooled, and written in rank order by `FormWriter` at the end of the compile
(`hrc.compile.sink.PlanSink`) or by `write_compiled`. `read_form` checks and memory-maps it;
`build_form` makes the same arrays in memory (the simulator, and outputs written before the form
existed).
"""

from __future__ import annotations

import hashlib
import heapq
import itertools
import json
import os
import struct
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import numpy as np

from hrc.compile.route_signatures import route_signatures
from hrc.compile.temporal_net_creator import ORIGIN, block_target, leg_names
from hrc.errors import InputError
from hrc.io.task_file import task_digest
from hrc.model import Plan, Task
from hrc.plans import agent_legs
from hrc.temporal.graphml import tool_name
from hrc.temporal.network import STNU, ContingentLink, RequirementLink
from hrc.temporal.rul import edge_arrays

__all__ = ["FORM_FOLDER", "FORM_VERSION", "LEG_EVENTS", "PLAN_DTYPE", "ROUTES_VERSION", "DispatchForm", "FormWriter",
           "PlanArrays", "build_form", "concat_forms", "parse_record", "plan_record", "plans_routes", "plan_sequences",
           "read_form", "task_sizes"]

FORM_FOLDER = "dispatch"
FORM_VERSION = 1
ROUTES_VERSION = 1
"""``routes.json``'s version (the module docstring: ``routes.npy``)."""
LEG_EVENTS = ("depart", "park", "unpark", "arrive", "start", "end")
"""An agent's events on one leg, in the order they happen (as `hrc.dispatch.messages.LEG_EVENTS`)."""

PLAN_DTYPE = np.dtype([("id", "S16"), ("rank", "<i4"), ("cls", "i1"), ("blocked", "u1"), ("preference", "<f8"),
                       ("n", "<u2"), ("shape", "<i4"), ("line_at", "<i8"), ("line_len", "<i8")])
_CLASS_CODE = {"DC": 0, "consistent": 1, "inconsistent": 2}
_RECORD_HEAD = struct.Struct("<HIHB")  # timepoints, edges, contingent links, blocked
_MAX_NODES = 0xFFFF  # timepoints per plan: indices are uint16
_PARSED_CAP = 256  # records `FormWriter.add_many` keeps parsed (a few kB each; a family's come together)


def _preference(value: float | None) -> float:
    return np.nan if value is None else round(value, 6)


def task_sizes(task: Task) -> tuple[int, int, int]:
    """``(G, A, L)``: agents, actions, and legs of the whole task (an agent doing everything has L)."""
    return len(task.agents), len(task.actions), sum(len(a.phases) for a in task.actions)


# ------------------------------------------------------------------------------------------- one plan
@dataclass(frozen=True, slots=True)
class PlanArrays:
    """One plan's network in the form's numbering (module docstring): `edges` (m, 3) int64 rows
    ``(u, v, w)``, `conts` (k, 4) int64 rows ``(a, c, lb, ub)``, `nodes` (G, L, 6) int16."""

    n: int
    edges: np.ndarray
    conts: np.ndarray
    nodes: np.ndarray
    blocked: bool


def _positions(task: Task, plan: Plan, graphml_names: bool) -> dict[str, tuple[int, int, int]]:
    """Timepoint name -> (agent, leg position, event), for every timepoint the plan's legs may have."""
    out: dict[str, tuple[int, int, int]] = {}
    table = leg_names(task, plan)
    for g, agent in enumerate(task.agents):
        legs = agent_legs(task, plan, agent.id) if task.has_joint else ()
        for k, names in enumerate(table[agent.id]):
            # a joint phase's one start and end sit in its lead's slots (`Task.lead`, the first robot of its
            # crew), not in the last crew member's: a crew of two robots has another robot after its lead
            other = bool(legs) and task.action(legs[k].action).joint and plan.agent_of(legs[k].action) != agent.id
            for e, event in enumerate(LEG_EVENTS):
                name = tool_name(names[event]) if graphml_names else names[event]
                if other and event in ("start", "end") and name in out:
                    continue
                out[name] = (g, k, e)
    return out


def plan_record(task: Task, plan: Plan, stnu: STNU, blocked: bool, *, graphml_names: bool = False,
                where: str = "") -> bytes:
    """The plan's network as the form stores it (`parse_record` reads it back): `stnu` is the plan's
    STNU with its timepoints named as `hrc.compile.temporal_net_creator` names them (``AGENT.PHASE.ACTION.
    EVENT`` and ``Z``), or as its GraphML file does (`graphml_names`: `tool_name` of those). The network
    is the one the GraphML file holds as `hrc.temporal.graphml.read_graphml` reads it: every timepoint at
    or after ``Z``, a contingent link of one fixed duration a requirement link, parallel bounds merged to the
    tightest, and for a `blocked` plan the block its file carries (its first timepoint after ``Z`` before
    ``Z``: `hrc.compile.temporal_net_creator.blocked_stnu`). Raises `InputError`
    (naming `where`) for a timepoint that is none of the plan's events, or a network too large for the
    form. Cost: O(links log links)."""
    G, _A, L = task_sizes(task)
    origin = tool_name(ORIGIN) if graphml_names else ORIGIN
    pos = _positions(task, plan, graphml_names)
    names = stnu.timepoints
    n = len(names)
    if origin not in names:
        raise InputError(where, "", f"the STNU has no origin timepoint {origin!r}")
    if n > _MAX_NODES:
        raise InputError(where, "", f"{n} timepoints: the dispatch form takes at most {_MAX_NODES}")
    key: list[tuple[int, int, int]] = []
    for name in names:
        if name == origin:
            key.append((-1, -1, -1))
        elif name in pos:
            key.append(pos[name])
        else:
            raise InputError(where, "", f"timepoint {name!r} is no event of plan {plan.id} (not compiled from this "
                                        "task?)")
    # the distance edges (``T(v) - T(u) <= w``) as the plan's GraphML file reads (`hrc.temporal.graphml`):
    # each requirement link's bounds (`edge_arrays`, kept by the compile for the network it classified),
    # every timepoint at or after the origin, a contingent link of one fixed duration a requirement link
    # (nature has no choice in it), and for a blocked plan the block its file carries (`blocked_stnu`)
    src, dst, wt, act, ctg, xs, ys = edge_arrays(stnu)
    z = names.index(origin)
    fixed = [k for k in range(len(act)) if xs[k] == ys[k]]
    conts = [(act[k], ctg[k], xs[k], ys[k]) for k in range(len(act)) if xs[k] != ys[k]]
    others = [i for i in range(n) if i != z]
    block = [(z, block_target(names, origin))] if blocked else []
    u = np.array([*src, *others, *(a for a, _ in block), *(act[k] for k in fixed), *(ctg[k] for k in fixed)],
                 dtype=np.int64)
    v = np.array([*dst, *([z] * len(others)), *(b for _, b in block), *(ctg[k] for k in fixed),
                  *(act[k] for k in fixed)], dtype=np.int64)
    w = np.array([*wt, *([0] * len(others)), *([-1] * len(block)), *(ys[k] for k in fixed),
                  *(-xs[k] for k in fixed)], dtype=np.int64)
    keep = (u != v) | (w < 0)
    u, v, w = u[keep], v[keep], w[keep]
    pair = u * n + v
    first = np.lexsort((w, pair))  # per pair, the tightest bound first
    tight = first[np.r_[True, pair[first][1:] != pair[first][:-1]]] if len(first) else first
    u, v, w = u[tight], v[tight], w[tight]
    order = _topological(n, z, key, u.tolist(), v.tolist(), w.tolist(), conts)
    new = np.empty(n, dtype=np.int64)
    new[np.array(order, dtype=np.int64)] = np.arange(n)
    edges = np.column_stack([new[u], new[v], w]).reshape(-1, 3)
    if len(edges):
        edges = edges[np.lexsort((edges[:, 0], edges[:, 1]))]  # by (v, u): a longest-path sweep's order
    cont_rows = np.array([(new[a], new[c], lb, ub) for a, c, lb, ub in conts], dtype=np.int64).reshape(-1, 4)
    nodes = np.full((G, L, len(LEG_EVENTS)), -1, dtype=np.int16)
    for i, (g, k, e) in enumerate(key):
        if g >= 0:
            nodes[g, k, e] = new[i]
    head = _RECORD_HEAD.pack(n, len(edges), len(cont_rows), int(blocked))
    return head + edges.tobytes() + cont_rows.tobytes() + nodes.tobytes()


def _topological(n: int, origin: int, key: list[tuple[int, int, int]], us: list[int], vs: list[int], ws: list[int],
                 conts: Sequence[tuple[int, int, int, int]]) -> list[int]:
    """The origin, then the other timepoints in a topological order of the orderings (an edge u -> v
    whenever T(v) >= T(u) whatever the bounds: a lower bound >= 0, or an upper bound <= 0 read
    backwards; contingent links, whose lower bound is >= 0), least (agent, leg, event) first among the
    ready; timepoints on zero-length cycles last, in that order too. The distance edges are
    ``T(vs[i]) - T(us[i]) <= ws[i]``, one per ordered pair (the order in which they come does not matter:
    ties among the ready go by key, and every key is its timepoint's own)."""
    succ: list[list[int]] = [[] for _ in range(n)]
    indeg = [0] * n
    for u, v, w in zip(us, vs, ws, strict=True):  # T(u) >= T(v) - w: an ordering v -> u if w <= 0
        if w <= 0:
            succ[v].append(u)
            indeg[u] += 1
    for a, c, _lb, _ub in conts:
        succ[a].append(c)
        indeg[c] += 1
    seen = [False] * n
    order = [origin]
    seen[origin] = True
    for v in succ[origin]:
        indeg[v] -= 1
    ready = [(key[i], i) for i in range(n) if indeg[i] == 0 and i != origin]
    heapq.heapify(ready)
    while ready:
        _, u = heapq.heappop(ready)
        seen[u] = True
        order.append(u)
        for v in succ[u]:
            indeg[v] -= 1
            if indeg[v] == 0 and not seen[v]:
                heapq.heappush(ready, (key[v], v))
    order += sorted((i for i in range(n) if not seen[i]), key=lambda i: key[i])
    return order


def parse_record(data: bytes, sizes: tuple[int, int, int]) -> PlanArrays:
    """A `plan_record` back as arrays; `sizes` is the task's `task_sizes`."""
    G, _A, L = sizes
    n, m, k, blocked = _RECORD_HEAD.unpack_from(data)
    at = _RECORD_HEAD.size
    edges = np.frombuffer(data, dtype=np.int64, count=3 * m, offset=at).reshape(m, 3)
    at += 24 * m
    conts = np.frombuffer(data, dtype=np.int64, count=4 * k, offset=at).reshape(k, 4)
    at += 32 * k
    nodes = np.frombuffer(data, dtype=np.int16, count=G * L * len(LEG_EVENTS), offset=at).reshape(G, L, -1)
    return PlanArrays(n, edges, conts, nodes, bool(blocked))


def plans_routes(batch: Sequence[PlanArrays]) -> np.ndarray:
    """(len(batch), G, L, 3) int64: the route signature of each leg position of each plan
    (`hrc.compile.route_signatures.route_signatures` of their arrays, in one call: a few hundred plans
    at once cost about 30 us a plan, one alone about 300 us)."""
    if not batch:
        raise ValueError("no plans")
    nodes = np.stack([a.nodes for a in batch])
    e = np.concatenate([a.edges for a in batch]).reshape(-1, 3)
    c = np.concatenate([a.conts for a in batch]).reshape(-1, 4)
    e_ptr = np.cumsum([0, *(len(a.edges) for a in batch)], dtype=np.int64)
    c_ptr = np.cumsum([0, *(len(a.conts) for a in batch)], dtype=np.int64)
    return route_signatures(nodes, (e_ptr, e[:, 0], e[:, 1], e[:, 2]), (c_ptr, c[:, 0], c[:, 1], c[:, 3]),
                            np.arange(len(batch), dtype=np.int64))


_ROUTE_BATCH = 512
"""Shapes whose route signatures are made in one call (`plans_routes`) as a form is written."""


def plan_sequences(task: Task, plan: Plan) -> np.ndarray:
    """(G, A) int16: each agent's actions in order (task action indices), -1 after its last."""
    G, A, _L = task_sizes(task)
    index = {a: i for i, a in enumerate(task.action_ids)}
    out = np.full((G, A), -1, dtype=np.int16)
    for g, agent in enumerate(task.agent_ids):
        seq = plan.sequence(agent)
        out[g, :len(seq)] = [index[a] for a in seq]
    return out


# ------------------------------------------------------------------------------------------- the form
@dataclass(frozen=True)
class DispatchForm:
    """Every plan of a compile as arrays (the module docstring), in rank order; built by `read_form`
    (memory-mapped) or `build_form` (in memory). `rank_by` is the compile's (`CompileOptions.rank_by`).
    `routes`: ``routes.npy`` (by shape number), None for a form written without it."""

    task: Task
    rank_by: str
    plans: np.ndarray
    seq: np.ndarray
    nodes: np.ndarray
    edges_ptr: np.ndarray
    edges_u: np.ndarray
    edges_v: np.ndarray
    edges_w: np.ndarray
    conts_ptr: np.ndarray
    conts_a: np.ndarray
    conts_c: np.ndarray
    conts_lb: np.ndarray
    conts_ub: np.ndarray
    source: str = ""
    routes: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.plans)

    def plan_id(self, p: int) -> str:
        return self.plans["id"][p].decode("ascii").rstrip()

    def plan(self, p: int) -> Plan:
        """Plan `p` (allocation and sequences) from its `seq` row."""
        task = self.task
        sequences = []
        agent_of: dict[str, str] = {}
        for g, agent in enumerate(task.agent_ids):
            row = [task.action_ids[int(a)] for a in self.seq[p, g] if a >= 0]
            sequences.append((agent, tuple(row)))
            agent_of.update((a, agent) for a in row)
        if task.has_joint:  # a joint action is its crew's lead's (`Task.lead`: the first robot), not its last
            for a in task.actions:  # agent's (two robots in a crew: robot2 is last, robot leads; issue 37)
                if a.joint:
                    lead = task.crew_lead(ag for ag, row in sequences if a.id in row)
                    assert lead is not None
                    agent_of[a.id] = lead
        return Plan(tuple((a, agent_of[a]) for a in task.action_ids), tuple(sequences))

    def arrays(self, p: int) -> PlanArrays:
        """Plan `p`'s network (copies of its rows)."""
        e0, e1 = int(self.edges_ptr[p]), int(self.edges_ptr[p + 1])
        c0, c1 = int(self.conts_ptr[p]), int(self.conts_ptr[p + 1])
        edges = np.stack([self.edges_u[e0:e1].astype(np.int64), self.edges_v[e0:e1].astype(np.int64),
                          self.edges_w[e0:e1].astype(np.int64)], axis=1).reshape(-1, 3)
        conts = np.stack([self.conts_a[c0:c1].astype(np.int64), self.conts_c[c0:c1].astype(np.int64),
                          self.conts_lb[c0:c1].astype(np.int64), self.conts_ub[c0:c1].astype(np.int64)],
                         axis=1).reshape(-1, 4)
        return PlanArrays(int(self.plans["n"][p]), edges, conts, np.array(self.nodes[p]),
                          bool(self.plans["blocked"][p]))

    def record(self, p: int) -> bytes:
        """Plan `p` as its `plan_record` (to carry it over into another compile: ``--resume``)."""
        a = self.arrays(p)
        head = _RECORD_HEAD.pack(a.n, len(a.edges), len(a.conts), int(a.blocked))
        return head + a.edges.tobytes() + a.conts.tobytes() + a.nodes.astype(np.int16).tobytes()

    def timepoint_names(self, p: int) -> list[str]:
        """Plan `p`'s timepoints by index, named as its GraphML file names them (`tool_name` of
        ``AGENT.PHASE.ACTION.EVENT``, and ``Z``)."""
        n = int(self.plans["n"][p])
        names = [""] * n
        names[0] = tool_name(ORIGIN)
        plan = self.plan(p)
        for g, agent in enumerate(self.task.agents):
            for k, leg in enumerate(agent_legs(self.task, plan, agent.id)):
                for e, event in enumerate(LEG_EVENTS):
                    x = int(self.nodes[p, g, k, e])
                    if x >= 0:
                        names[x] = tool_name(f"{agent.id}.{leg.phase}.{leg.action}.{event}")
        return names

    def stnu(self, p: int) -> STNU:
        """Plan `p`'s STNU as an `STNU` value (one requirement link per distance edge), timepoints named
        as in its GraphML file, in the form's order: for the decisions' Python path and for tests."""
        a = self.arrays(p)
        names = self.timepoint_names(p)
        reqs = tuple(RequirementLink(names[u], names[v], None, int(w)) for u, v, w in a.edges.tolist())
        conts = tuple(ContingentLink(names[x], names[c], int(lb), int(ub)) for x, c, lb, ub in a.conts.tolist())
        return STNU(tuple(names), reqs, conts, f"{self.task.name}:{self.plan_id(p)}")


class _NpyColumn:
    """A ``.npy`` file written as its rows come, its header (shape) rewritten at the end (`close`): the
    same bytes whether the rows came one by one or all at once."""

    def __init__(self, path: Path, dtype: np.dtype, tail: tuple[int, ...] = ()) -> None:
        self.path, self.dtype, self.tail, self.rows = path, np.dtype(dtype), tail, 0
        # room for the header with any row count: the text with the largest, rounded up to 64 bytes
        longest = len(self._text((1 << 63) - 1))
        self.size = -(-(10 + longest + 1) // 64) * 64
        self.file: IO[bytes] = open(path, "wb")  # noqa: SIM115 - closed in close
        self.file.write(b"\0" * self.size)
        self.hash = hashlib.sha256()

    def _text(self, rows: int) -> bytes:
        header = {"descr": np.lib.format.dtype_to_descr(self.dtype), "fortran_order": False,
                  "shape": (rows, *self.tail)}
        return repr(header).encode("latin1")

    def add(self, values: np.ndarray) -> None:
        data = np.ascontiguousarray(values, dtype=self.dtype)
        self.rows += len(data)
        raw = data.tobytes()
        self.file.write(raw)
        self.hash.update(raw)

    def close(self) -> tuple[str, dict[str, Any]]:
        shape = (self.rows, *self.tail)
        room = self.size - 10
        text = self._text(self.rows).ljust(room - 1) + b"\n"
        head = b"\x93NUMPY\x01\x00" + struct.pack("<H", room) + text
        self.file.seek(0)
        self.file.write(head)
        self.file.flush()
        os.fsync(self.file.fileno())
        self.file.close()
        digest = hashlib.sha256(head)
        digest.update(self.hash.digest())  # the file's digest: of its header, then of its data's SHA-256
        return self.path.name, {"dtype": np.lib.format.dtype_to_descr(self.dtype), "shape": list(shape),
                                "sha256": digest.hexdigest()}

    def abandon(self) -> None:
        self.file.close()


def _file_digest(path: Path) -> str:
    """The digest `_NpyColumn.close` gives a file: SHA-256 of its header, then of its data's SHA-256."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        start = f.read(10)
        size = 10 + struct.unpack("<H", start[8:10])[0] if len(start) == 10 and start[:6] == b"\x93NUMPY" else 0
        h.update(start + f.read(max(0, size - len(start))))
        data = hashlib.sha256()
        while chunk := f.read(1 << 20):
            data.update(chunk)
    h.update(data.digest())
    return h.hexdigest()


class FormWriter:
    """Writes the form of a compile into ``FOLDER/dispatch/``, plan after plan in rank order (`add`),
    in memory that grows by about 60 bytes a plan (and a shape's route signatures, `plans_routes`, made
    for its first plan, `_ROUTE_BATCH` shapes at a time); `close` writes ``plans.npy``, ``form.json``,
    then ``routes.npy`` and ``routes.json``, and returns the SHA-256 of ``form.json`` for
    ``compiled.json``'s header. A bound that does not fit the form's 32-bit weights raises OverflowError
    from `add`: write again with `wide`."""

    def __init__(self, folder: Path, task: Task, rank_by: str, wide: bool = False) -> None:
        self.task, self.rank_by = task, rank_by
        self.sizes = G, A, L = task_sizes(task)
        self.folder = Path(folder) / FORM_FOLDER
        self.folder.mkdir(exist_ok=True)
        (self.folder / "routes.json").unlink(missing_ok=True)  # an earlier compile's, until this one's is written
        self.digest = task_digest(task)
        weight = np.dtype("<i8") if wide else np.dtype("<i4")
        self.wide, self.weight = wide, weight
        d = self.folder
        self.cols = {
            "seq": _NpyColumn(d / "seq.npy", np.dtype("<i2"), (G, A)),
            "nodes": _NpyColumn(d / "nodes.npy", np.dtype("<i2"), (G, L, len(LEG_EVENTS))),
            "edges_u": _NpyColumn(d / "edges_u.npy", np.dtype("<u2")),
            "edges_v": _NpyColumn(d / "edges_v.npy", np.dtype("<u2")),
            "edges_w": _NpyColumn(d / "edges_w.npy", weight),
            "conts_a": _NpyColumn(d / "conts_a.npy", np.dtype("<u2")),
            "conts_c": _NpyColumn(d / "conts_c.npy", np.dtype("<u2")),
            "conts_lb": _NpyColumn(d / "conts_lb.npy", weight),
            "conts_ub": _NpyColumn(d / "conts_ub.npy", weight),
        }
        self.rows: list[tuple] = []  # the plans.npy row of each plan
        self.edges_ptr, self.conts_ptr = [0], [0]
        self.shapes: dict[bytes, int] = {}
        self.routes: list[np.ndarray] = []  # batches of route signatures, by shape number (`plans_routes`)
        self.pending: list[PlanArrays] = []  # the first plan of each new shape, not in `routes` yet
        self._parsed: dict[bytes, tuple[PlanArrays, int]] = {}  # record -> its arrays and shape

    def add(self, plan_id: str, compiled_class: str, preference: float | None, sequences: np.ndarray,
            record: bytes, line_at: int = 0, line_len: int = 0) -> None:
        """The next plan (in rank order): its id, class, preference value, `plan_sequences`, its
        `plan_record`, and where its line lies in ``compiled.json``."""
        self.add_many([plan_id], [compiled_class], [preference], sequences[None], [record], [line_at], [line_len])

    def add_many(self, plan_ids: Sequence[str], classes: Sequence[str], preferences: Sequence[float | None],
                 sequences: np.ndarray, records: Sequence[bytes], line_at: Sequence[int],
                 line_len: Sequence[int]) -> None:
        """The next plans (in rank order), as `add` takes one each, `sequences` stacked (k, G, A): the
        same files as `add` plan by plan (each column's rows appended in one write). A record is parsed,
        checked and numbered once however many plans share it (a family's plans do:
        `hrc.compile.compiler.compile_family`), and each column gets one write per call, not per plan
        (issue 38: kitting_7picks' 40,320 plans, written at the end of its compile, one after another)."""
        limit = (1 << 63) if self.wide else (1 << 31)
        parsed = self._parsed
        known: list[tuple[PlanArrays, int]] = []
        for record in records:
            found = parsed.get(record)
            if found is None:
                a = parse_record(record, self.sizes)
                if (len(a.edges) and np.abs(a.edges[:, 2]).max() >= limit) or \
                        (len(a.conts) and np.abs(a.conts[:, 2:]).max() >= limit):
                    raise OverflowError("a bound does not fit the form's weights")  # the caller goes wide
                new = len(self.shapes)
                shape = self.shapes.setdefault(hashlib.sha256(record).digest(), new)
                if shape == new:  # a new shape: its route signatures, `_ROUTE_BATCH` shapes at a time
                    self.pending.append(a)
                    if len(self.pending) >= _ROUTE_BATCH:
                        self.routes.append(plans_routes(self.pending))
                        self.pending = []
                if len(parsed) >= _PARSED_CAP:  # a family's plans come together in rank order (same keys)
                    parsed.clear()
                found = parsed[record] = (a, shape)
            known.append(found)
        first = len(self.rows)
        self.rows.extend((pid.encode("ascii"), first + j + 1, _CLASS_CODE[cls], a.blocked, _preference(pref), a.n,
                          shape, at, size)
                         for j, (pid, cls, pref, (a, shape), at, size)
                         in enumerate(zip(plan_ids, classes, preferences, known, line_at, line_len, strict=True)))
        if not known:
            return
        c = self.cols
        c["seq"].add(sequences)
        c["nodes"].add(np.stack([a.nodes for a, _ in known]))
        edges = np.concatenate([a.edges for a, _ in known])
        conts = np.concatenate([a.conts for a, _ in known])
        c["edges_u"].add(edges[:, 0])
        c["edges_v"].add(edges[:, 1])
        c["edges_w"].add(edges[:, 2])
        c["conts_a"].add(conts[:, 0])
        c["conts_c"].add(conts[:, 1])
        c["conts_lb"].add(conts[:, 2])
        c["conts_ub"].add(conts[:, 3])
        for ptr, counts in ((self.edges_ptr, [len(a.edges) for a, _ in known]),
                            (self.conts_ptr, [len(a.conts) for a, _ in known])):
            ptr.extend(itertools.islice(itertools.accumulate(counts, initial=ptr[-1]), 1, None))

    def abandon(self) -> None:
        for col in self.cols.values():
            col.abandon()

    def close(self) -> str:
        files = dict(col.close() for col in self.cols.values())
        for name, values in (("edges_ptr", self.edges_ptr), ("conts_ptr", self.conts_ptr)):
            col = _NpyColumn(self.folder / f"{name}.npy", np.dtype("<i8"))
            col.add(np.array(values, dtype=np.int64))
            files.update([col.close()])
        plans = np.array(self.rows, dtype=PLAN_DTYPE)
        col = _NpyColumn(self.folder / "plans.npy", PLAN_DTYPE)
        col.add(plans)
        files.update([col.close()])
        meta = {"hrc_dispatch_form": FORM_VERSION, "task_digest": self.digest, "rank_by": self.rank_by,
                "plans": len(plans), "sizes": dict(zip(("agents", "actions", "legs"), self.sizes, strict=True)),
                "files": dict(sorted(files.items()))}
        if self.task.sensing is not None:  # what the classes (`cls`) assume; absent: events learnt at once
            from hrc.compile.sensing import sensing_dict

            meta["sensing"] = sensing_dict(self.task.sensing)
        text = (json.dumps(meta, indent=1, sort_keys=True) + "\n").encode("utf-8")
        with open(self.folder / "form.json", "wb") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        digest = hashlib.sha256(text).hexdigest()
        G, _A, L = self.sizes
        col = _NpyColumn(self.folder / "routes.npy", self.weight, (G, L, 3))
        for batch in (*self.routes, *([plans_routes(self.pending)] if self.pending else [])):
            col.add(batch)
        name, entry = col.close()
        routes = {"hrc_routes": ROUTES_VERSION, "form_sha256": digest, "files": {name: entry}}
        with open(self.folder / "routes.json", "wb") as f:
            f.write((json.dumps(routes, indent=1, sort_keys=True) + "\n").encode("utf-8"))
            f.flush()
            os.fsync(f.fileno())
        return digest


def build_form(task: Task, rank_by: str, entries: Iterable[tuple[str, str, float | None, Plan, bytes]],
               source: str = "<memory>") -> DispatchForm:
    """The form of `entries` (rank order: id, class, preference value, plan, `plan_record`) in memory:
    the arrays `FormWriter` writes (weights in 64 bits), without their files."""
    sizes = task_sizes(task)
    rows: list[tuple] = []
    seqs: list[np.ndarray] = []
    nodes: list[np.ndarray] = []
    edges: list[np.ndarray] = []
    conts: list[np.ndarray] = []
    shapes: dict[bytes, int] = {}
    firsts: list[PlanArrays] = []  # the first plan of each shape
    for plan_id, cls, pref, plan, record in entries:
        a = parse_record(record, sizes)
        shape = shapes.setdefault(hashlib.sha256(record).digest(), len(shapes))
        if shape == len(firsts):
            firsts.append(a)
        rows.append((plan_id.encode("ascii"), len(rows) + 1, _CLASS_CODE[cls], a.blocked, _preference(pref), a.n,
                     shape, 0, 0))
        seqs.append(plan_sequences(task, plan))
        nodes.append(a.nodes)
        edges.append(a.edges)
        conts.append(a.conts)
    G, A, L = sizes
    e = np.concatenate(edges) if edges else np.zeros((0, 3), dtype=np.int64)
    c = np.concatenate(conts) if conts else np.zeros((0, 4), dtype=np.int64)
    return DispatchForm(
        task, rank_by, np.array(rows, dtype=PLAN_DTYPE),
        np.array(seqs, dtype=np.int16).reshape(-1, G, A), np.array(nodes, dtype=np.int16).reshape(-1, G, L, 6),
        np.cumsum([0, *(len(x) for x in edges)], dtype=np.int64), e[:, 0].astype(np.uint16),
        e[:, 1].astype(np.uint16), np.ascontiguousarray(e[:, 2]),
        np.cumsum([0, *(len(x) for x in conts)], dtype=np.int64), c[:, 0].astype(np.uint16),
        c[:, 1].astype(np.uint16), np.ascontiguousarray(c[:, 2]), np.ascontiguousarray(c[:, 3]), source,
        np.concatenate([plans_routes(firsts[i:i + _ROUTE_BATCH]) for i in range(0, len(firsts), _ROUTE_BATCH)]
                       or [np.zeros((0, G, L, 3), dtype=np.int64)]))


def concat_forms(a: DispatchForm, b: DispatchForm) -> DispatchForm:
    """`a`'s plans followed by `b`'s (the same task and ``rank_by``), in memory: `b`'s ranks and shape
    numbers after `a`'s, its edge and contingent-link offsets moved past `a`'s. What a dispatcher takes
    when plans compiled on demand join its set (`hrc.dispatch.on_demand`): `a`'s plans keep their indices."""
    if task_sizes(a.task) != task_sizes(b.task) or a.rank_by != b.rank_by:
        raise ValueError("forms of different tasks or rankings cannot be joined")
    rows_b = np.array(b.plans, dtype=PLAN_DTYPE)
    rows_b["rank"] += len(a)
    rows_b["shape"] += int(np.max(a.plans["shape"], initial=-1)) + 1
    rows_b["line_at"] = rows_b["line_len"] = 0
    cat = np.concatenate

    def wide(x: np.ndarray) -> np.ndarray:
        return np.asarray(x, dtype=np.int64)

    def ptr(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return cat([wide(x), wide(y[1:]) + int(x[-1])])

    return DispatchForm(
        a.task, a.rank_by, cat([np.asarray(a.plans), rows_b]), cat([a.seq, b.seq]), cat([a.nodes, b.nodes]),
        ptr(a.edges_ptr, b.edges_ptr), cat([a.edges_u, b.edges_u]), cat([a.edges_v, b.edges_v]),
        cat([wide(a.edges_w), wide(b.edges_w)]), ptr(a.conts_ptr, b.conts_ptr), cat([a.conts_a, b.conts_a]),
        cat([a.conts_c, b.conts_c]), cat([wide(a.conts_lb), wide(b.conts_lb)]),
        cat([wide(a.conts_ub), wide(b.conts_ub)]), a.source,
        None if a.routes is None or b.routes is None or len(a.routes) != int(np.max(a.plans["shape"], initial=-1)) + 1
        else cat([wide(a.routes), wide(b.routes)]))


_ARRAYS = ("seq", "nodes", "edges_ptr", "edges_u", "edges_v", "edges_w", "conts_ptr", "conts_a", "conts_c",
           "conts_lb", "conts_ub")


def read_form(folder: str | os.PathLike[str], task: Task, rank_by: str, *, expected: str | None = None,
              check: bool = True) -> DispatchForm:
    """The form in ``folder/dispatch/``, memory-mapped. With `check`, every file is checked against
    ``form.json`` (shape, type, SHA-256) and ``form.json`` against `expected` (the SHA-256 that
    ``compiled.json`` names), and the arrays against each other; raises `InputError` naming the file and
    what is wrong. `task` (the compiled task) and `rank_by` come from the caller."""
    base = Path(folder) / FORM_FOLDER
    meta_path = base / "form.json"
    meta: dict[str, Any] = {}
    files: dict[str, Any] = {}
    raw = b""
    if check:
        try:
            raw = meta_path.read_bytes()
        except OSError as err:
            raise InputError(str(meta_path), "", f"cannot read the dispatch form: {err.strerror or err}") from err
        if expected is not None and hashlib.sha256(raw).hexdigest() != expected:
            raise InputError(str(meta_path), "", "not the dispatch form compiled.json was written with (its SHA-256 "
                                                 "differs): compile again")
        try:
            meta = json.loads(raw)
        except ValueError as err:
            raise InputError(str(meta_path), "", f"not JSON ({err})") from err
        if not isinstance(meta, dict) or meta.get("hrc_dispatch_form") != FORM_VERSION:
            raise InputError(str(meta_path), "hrc_dispatch_form", f"expected version {FORM_VERSION}")
        files = meta.get("files")  # type: ignore[assignment]
        if not isinstance(files, dict):
            raise InputError(str(meta_path), "files", "missing or not an object")
    arrays: dict[str, np.ndarray] = {}
    for name in ("plans", *_ARRAYS):
        path = base / f"{name}.npy"
        if check:
            want = files.get(f"{name}.npy")
            if not isinstance(want, dict):
                raise InputError(str(meta_path), f"files.{name}.npy", "missing")
            if (_file_digest(path) if path.is_file() else None) != want.get("sha256"):
                raise InputError(str(path), "", "does not match form.json (truncated, changed or from another "
                                                "compile): compile again")
        try:
            arrays[name] = np.load(path, mmap_mode="r", allow_pickle=False)
        except (OSError, ValueError) as err:
            raise InputError(str(path), "", f"cannot read it: {err}") from err
        descr = json.loads(json.dumps(np.lib.format.dtype_to_descr(arrays[name].dtype)))  # as form.json has it
        if check and (list(arrays[name].shape) != files[f"{name}.npy"].get("shape")
                      or descr != files[f"{name}.npy"].get("dtype")):
            raise InputError(str(path), "", "its shape or type differs from form.json")
    rows = arrays.pop("plans")
    routes = _read_routes(base, raw if check else None, (int(np.max(rows["shape"], initial=-1)) + 1,
                                                          *task_sizes(task)[::2], 3))
    form = DispatchForm(task, rank_by, rows, source=str(folder), routes=routes, **arrays)
    if check:
        _check_consistent(form, meta, str(base))
    return form


def _read_routes(base: Path, form_json: bytes | None, shape: tuple[int, ...]) -> np.ndarray | None:
    """``routes.npy`` memory-mapped, None when ``routes.json`` is absent (a form written before it). With
    `form_json` (the form's ``form.json``, read and checked), checked against ``routes.json``: the form it
    belongs to, its file's SHA-256, type and `shape`; raises `InputError` naming the file otherwise."""
    meta_path = base / "routes.json"
    if not meta_path.is_file():
        return None
    path = base / "routes.npy"
    if form_json is not None:
        try:
            meta = json.loads(meta_path.read_bytes())
        except (OSError, ValueError) as err:
            raise InputError(str(meta_path), "", f"cannot read it: {err}") from err
        if not isinstance(meta, dict) or meta.get("hrc_routes") != ROUTES_VERSION:
            raise InputError(str(meta_path), "hrc_routes", f"expected version {ROUTES_VERSION}")
        if meta.get("form_sha256") != hashlib.sha256(form_json).hexdigest():
            raise InputError(str(meta_path), "form_sha256", "not the route signatures of this dispatch form: compile "
                                                            "again")
        want = meta.get("files", {}).get("routes.npy") if isinstance(meta.get("files"), dict) else None
        if not isinstance(want, dict):
            raise InputError(str(meta_path), "files.routes.npy", "missing")
        if (_file_digest(path) if path.is_file() else None) != want.get("sha256"):
            raise InputError(str(path), "", "does not match routes.json (truncated, changed or from another compile): "
                                            "compile again")
    try:
        routes = np.load(path, mmap_mode="r", allow_pickle=False)
    except (OSError, ValueError) as err:
        raise InputError(str(path), "", f"cannot read it: {err}") from err
    if routes.shape != shape or routes.dtype.kind != "i":
        raise InputError(str(path), "", f"shape {routes.shape} ({routes.dtype}), expected {shape} of integers")
    return routes


def _check_consistent(form: DispatchForm, meta: Mapping[str, Any], where: str) -> None:
    """The arrays fit each other and the task (cheap checks, O(P) on small columns; the edges' indices
    are checked by the dispatcher's core as it reads them)."""
    P = len(form.plans)
    G, A, L = task_sizes(form.task)
    if meta.get("task_digest") != task_digest(form.task):
        raise InputError(where, "form.json: task_digest", "compiled from another task than input/ holds")
    want = {"seq": (P, G, A), "nodes": (P, G, L, len(LEG_EVENTS)), "edges_ptr": (P + 1,), "conts_ptr": (P + 1,)}
    for name, shape in want.items():
        if getattr(form, name).shape != shape:
            raise InputError(where, f"{name}.npy", f"shape {getattr(form, name).shape}, expected {shape}")
    for ptr, cols in (("edges_ptr", ("edges_u", "edges_v", "edges_w")),
                      ("conts_ptr", ("conts_a", "conts_c", "conts_lb", "conts_ub"))):
        p = getattr(form, ptr)
        if P and (p[0] != 0 or np.any(np.diff(p) < 0) or any(len(getattr(form, c)) != p[-1] for c in cols)):
            raise InputError(where, f"{ptr}.npy", "offsets do not fit the arrays they index")
    n = form.plans["n"]
    if P and (n.min() < 1 or np.any(form.nodes.max(axis=(1, 2, 3)) >= n)):
        raise InputError(where, "nodes.npy", "a timepoint index beyond its plan's timepoints")
    if P and (form.seq.min() < -1 or form.seq.max() >= A):
        raise InputError(where, "seq.npy", "an action index outside the task")
