"""Feasible potentials of integer distance graphs (or a negative cycle), by the Goldberg-Radzik algorithm.

A potential p with ``p(v) <= p(u) + w`` for every edge u --w--> v is a schedule of an STN (``T = p``) and
makes the reduced weights ``w + p(u) - p(v)`` non-negative, so that Dijkstra's algorithm can search a
graph with negative edges (Johnson's reweighting). Such a p exists iff the graph has no negative cycle.

Source: A. V. Goldberg & T. Radzik, "A heuristic improvement of the Bellman-Ford algorithm", Applied
Mathematics Letters 6(3), 1993; B. V. Cherkassky, A. V. Goldberg & T. Radzik, "Shortest paths algorithms:
theory and experimental evaluation", Math. Programming 73, 1996 (section 3.4). Each pass keeps the nodes
that have an out-edge of negative reduced weight, orders the nodes reachable from them over *admissible*
edges (reduced weight <= 0) topologically by a depth-first search, and scans them in that order. A pass
costs O(n + m); the number of passes is O(n) in the worst case, like Bellman-Ford, but a pass settles
every admissible path at once, so a chain of negative edges takes one pass whatever the node order
(FIFO Bellman-Ford needs one pass per edge of the chain there: quadratic on a 100,000-node chain).

Negative cycles: a cycle of admissible edges found by the search is negative iff it has an edge of
negative reduced weight (the reduced weights of a cycle sum to its length); as a safeguard, after n passes
the parent pointers are walked, which close a cycle only when there is a negative one (Cherkassky &
Goldberg 1999, label-correcting lemma).

>>> out = [[(1, 2, 0)], [(2, -3, 1)], [(0, 0, 2)]]   # 0 -2-> 1 -(-3)-> 2 -0-> 0: a cycle of length -1
>>> feasible_potential(3, out, [0, 0, 0])               # its edges, in path order
[0, 1, 2]
>>> p = [0, 0, 0]; out[2] = [(0, 1, 2)]                  # now of length 0: p is a schedule
>>> feasible_potential(3, out, p), p
(None, [-2, 0, -3])
"""

from __future__ import annotations

from collections import deque

__all__ = ["feasible_potential"]

_WHITE, _GRAY, _BLACK = 0, 1, 2
_FIFO_SCANS = 3
_FIFO_NODES = 64


def _fifo(n: int, out: list[list[tuple[int, int, int]]], p: list[int], budget: int) -> bool:
    """FIFO Bellman-Ford from ``p``, stopped after ``budget`` node scans; True iff it converged."""
    queue = deque(range(n))
    queued = [True] * n
    pop, push = queue.popleft, queue.append
    while queue:
        budget -= 1
        if budget < 0:
            return False
        u = pop()
        queued[u] = False
        pu = p[u]
        for v, w, _eid in out[u]:
            if pu + w < p[v]:
                p[v] = pu + w
                if not queued[v]:
                    queued[v] = True
                    push(v)
    return True


def feasible_potential(n: int, out: list[list[tuple[int, int, int]]], p: list[int]) -> list[int] | None:
    """Lower ``p`` (in place) until ``p[v] <= p[u] + w`` for every edge ``(v, w, eid)`` in ``out[u]``.

    Returns None on success, or a negative cycle as the list of its edge ids in path order (``p`` is then
    left partly lowered). O(n m) worst case, O(n + m) per pass. Small and easy graphs are first given to
    FIFO Bellman-Ford for at most `_FIFO_SCANS` node scans per node (cheaper when it converges at once).
    """
    if n <= _FIFO_NODES and _fifo(n, out, p, _FIFO_SCANS * n):
        return None
    pred_edge = [-1] * n  # edge id of the last decrease of each node
    pred_node = [-1] * n
    color = [_WHITE] * n
    tree_edge = [-1] * n  # edge by which the current search reached a node
    negs = [0] * n  # edges of negative reduced weight on the search path from the root to a node
    candidates = list(range(n))
    passes = 0
    while candidates:
        passes += 1
        roots = []
        for u in candidates:
            pu = p[u]
            for v, w, _eid in out[u]:
                if pu + w < p[v]:
                    roots.append(u)
                    break
        if not roots:
            return None
        # depth-first search over admissible edges; post-order gives a reverse topological order
        order: list[int] = []
        touched: list[int] = []
        for root in roots:
            if color[root] != _WHITE:
                continue
            color[root] = _GRAY
            touched.append(root)
            tree_edge[root] = -1
            negs[root] = 0
            stack = [(root, 0)]
            while stack:
                u, i = stack[-1]
                edges = out[u]
                pu = p[u]
                pushed = False
                while i < len(edges):
                    v, w, eid = edges[i]
                    i += 1
                    reduced = pu + w - p[v]
                    if reduced > 0:
                        continue
                    cv = color[v]
                    if cv == _WHITE:
                        stack[-1] = (u, i)
                        color[v] = _GRAY
                        touched.append(v)
                        tree_edge[v] = eid
                        negs[v] = negs[u] + (reduced < 0)
                        stack.append((v, 0))
                        pushed = True
                        break
                    # a cycle of admissible edges v ~> u -> v: negative iff one of its reduced weights is
                    if cv == _GRAY and (reduced < 0 or negs[u] > negs[v]):
                        nodes = [node for node, _ in stack]
                        return [tree_edge[node] for node in nodes[nodes.index(v) + 1:]] + [eid]
                if not pushed:
                    stack.pop()
                    color[u] = _BLACK
                    order.append(u)
        for v in touched:
            color[v] = _WHITE
        # scan in topological order; the nodes whose label dropped are next pass's candidates
        changed: list[int] = []
        mark = set()
        for u in reversed(order):
            pu = p[u]
            for v, w, eid in out[u]:
                if pu + w < p[v]:
                    p[v] = pu + w
                    pred_edge[v] = eid
                    pred_node[v] = u
                    if v not in mark:
                        mark.add(v)
                        changed.append(v)
        candidates = changed
        if passes > n + 1:
            for v in changed:
                cycle = _parent_cycle(v, pred_edge, pred_node)
                if cycle is not None:
                    return cycle
    return None


def _parent_cycle(v: int, pred_edge: list[int], pred_node: list[int]) -> list[int] | None:
    seen: dict[int, int] = {}
    chain: list[int] = []
    while v not in seen:
        seen[v] = len(chain)
        if pred_edge[v] < 0:
            return None
        chain.append(pred_edge[v])
        v = pred_node[v]
    cycle = chain[seen[v]:]
    cycle.reverse()
    return cycle
