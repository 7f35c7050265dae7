"""Worker types from recorded runs: runs clustered by how the person worked, with each type's duration
bounds and preferences (Wilcox, Nikolaidis & Shah 2012, section VI: people fall into groups that work
differently, and APA switches between one preference set per group).

**Features** of a run (the person's timing and choices): their mean *normalised* duration over the
phases they did, ``(d - lb) / (ub - lb)`` with the task's bounds (a fast and a slow worker differ in it
whichever phases they took); for each action whether they took it (the allocation they chose); for each
pair of actions they both took, +1 or -1 for the order they took them in (0: not both). Each feature is
standardised (zero mean, unit variance; constant ones dropped), and the choice features divided by the
square root of their number, so that the choices as a block weigh as much as the timing (else fifteen
order features would drown the one timing feature).

**Clustering**: k-means (Lloyd's algorithm with k-means++ seeding, `scipy.cluster.vq.kmeans2`, from a
fixed seed: the same runs give the same types) for ``k = 2 .. k_max``, the best of several starts by
within-cluster sum of squares; ``k`` is chosen by the **mean silhouette** (Rousseeuw 1987) rather than
BIC: BIC needs a likelihood, i.e. a Gaussian mixture with a covariance per type, whose estimate is poor
for the tens of runs a type has here, while the silhouette needs only distances. A split is kept when its
silhouette reaches `SPLIT` (0.5, the lower end of "a reasonable structure" in Kaufman & Rousseeuw 1990);
below it, the runs are one type; a larger k is taken only when it beats a smaller one by `TIE_K`.

**Per type**: the duration bounds learned from that type's runs alone (`hrc.learn.estimate.learn`, the
same guard rails), written as the type's **preference set** (the form ``preference_sets`` in the task,
which APA's worker-type switch `hrc.apa.workers.best_worker_type` reads): on each of the person's phases
with a learned bound, the concave quadratic ``-(d - m)^2`` (coefficients ``[-m^2, 2m, -1]``) peaked at
the type's median duration ``m``, on the type's bound as its domain. An observed duration outside a type's domain makes
that type infeasible for the switch; inside, the type whose median is nearer scores higher.

`adjusted_rand_index` (Hubert & Arabie 1985) compares two labellings (1: the same partition; about 0:
as good as chance).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from hrc.learn.estimate import Learned, durations_of, learn
from hrc.learn.runs import Run
from hrc.learn.task_edit import format_seconds
from hrc.model import Task

__all__ = ["SPLIT", "TIE_K", "WorkerTypes", "adjusted_rand_index", "features", "find_types", "kmeans", "silhouette",
           "types_markdown", "types_yaml"]

SPLIT = 0.5
"""The mean silhouette a split into types must reach (else: one type)."""
TIE_K = 0.05
"""A larger k must beat the best smaller one's silhouette by this much (parsimony: ties go to fewer types)."""


@dataclass(frozen=True, slots=True)
class WorkerTypes:
    """The types found: `labels[i]` is run i's type (0 .. k-1), `silhouette` of the chosen k (None for
    k = 1), `scores` the silhouette of each k tried, and per type what `learn` found in its runs and the
    share of its runs in which the person took each action (`took`)."""

    labels: tuple[int, ...]
    silhouette: float | None
    scores: tuple[tuple[int, float], ...]
    learned: tuple[Learned, ...]
    took: tuple[tuple[tuple[str, float], ...], ...]

    @property
    def k(self) -> int:
        return len(self.learned)

    def name(self, i: int) -> str:
        return f"type_{i + 1}"


def features(task: Task, runs: Sequence[Run]) -> np.ndarray:
    """One row per run (see the module docstring), standardised; shape (runs, features)."""
    human = next(a.id for a in task.agents if a.is_human)
    actions = task.action_ids
    rows = []
    for run in runs:
        norm = []
        for (agent, action, phase), ds in durations_of([run]).items():
            if agent != human:
                continue
            b = task.action(action).phase(phase).duration(agent)
            width = b.ub - b.lb if b.ub > b.lb else 1.0
            norm += [(d - b.lb) / width for d in ds]
        seq = run.sequence(human)
        pos = {a: i for i, a in enumerate(seq)}
        row = [float(np.mean(norm)) if norm else 0.0] + [1.0 if a in pos else 0.0 for a in actions]
        for i, a in enumerate(actions):
            for b_ in actions[i + 1:]:
                row.append(0.0 if a not in pos or b_ not in pos else (1.0 if pos[a] < pos[b_] else -1.0))
        rows.append(row)
    x = np.array(rows, dtype=float).reshape(len(runs), -1)
    sd = x.std(axis=0)
    keep = sd > 1e-12
    z = np.zeros_like(x)
    z[:, keep] = (x[:, keep] - x[:, keep].mean(axis=0)) / sd[keep]
    choices = int(keep[1:].sum())
    if choices:  # the choices weigh as much as the timing together, not once per feature
        z[:, 1:] /= math.sqrt(choices)
    return z[:, keep]


def kmeans(x: np.ndarray, k: int, seed: int = 0, starts: int = 8) -> np.ndarray:
    """Labels of the best of `starts` k-means runs (k-means++ seeding, `scipy.cluster.vq.kmeans2`) by the
    within-cluster sum of squares; deterministic for a seed. O(starts * iterations * n * k * d)."""
    from scipy.cluster.vq import kmeans2

    rng = np.random.default_rng(seed)
    best: tuple[float, np.ndarray] | None = None
    for _ in range(starts):
        centres, labels = kmeans2(x, k, minit="++", seed=rng, iter=50)
        sse = float(((x - centres[labels]) ** 2).sum())
        if best is None or sse < best[0] - 1e-12:
            best = (sse, labels)
    assert best is not None
    # number the types by their first run, so that labels do not depend on the seeding's order
    first = {lab: i for i, lab in reversed(list(enumerate(best[1])))}
    order = {lab: j for j, lab in enumerate(sorted(first, key=first.__getitem__))}
    return np.array([order[lab] for lab in best[1]], dtype=int)


def silhouette(x: np.ndarray, labels: np.ndarray) -> float:
    """Mean silhouette (Rousseeuw 1987) of a labelling with at least two clusters; a point alone in its
    cluster scores 0. O(n^2 d)."""
    d = np.sqrt(((x[:, None, :] - x[None, :, :]) ** 2).sum(axis=2))
    ks = sorted(set(labels.tolist()))
    s = np.zeros(len(x))
    for i in range(len(x)):
        own = labels == labels[i]
        if own.sum() <= 1:
            continue
        a = d[i, own].sum() / (own.sum() - 1)
        b = min(d[i, labels == k].mean() for k in ks if k != labels[i])
        s[i] = 0.0 if max(a, b) == 0 else (b - a) / max(a, b)
    return float(s.mean())


def adjusted_rand_index(a: Sequence[int], b: Sequence[int]) -> float:
    """The adjusted Rand index of two labellings of the same items (Hubert & Arabie 1985):
    ``(index - expected) / (max - expected)`` over pairs, from the contingency table. 1.0 when both
    labellings are one partition (also when both put everything together).

    >>> adjusted_rand_index([0, 0, 1, 1], [1, 1, 0, 0]), adjusted_rand_index([0, 0, 1, 1], [0, 1, 0, 1])
    (1.0, -0.5)
    """
    if len(a) != len(b):
        raise ValueError("the two labellings must have the same length")
    pairs: dict[tuple[int, int], int] = {}
    for x, y in zip(a, b, strict=True):
        pairs[(x, y)] = pairs.get((x, y), 0) + 1
    rows: dict[int, int] = {}
    cols: dict[int, int] = {}
    for (x, y), c in pairs.items():
        rows[x] = rows.get(x, 0) + c
        cols[y] = cols.get(y, 0) + c
    index = sum(math.comb(c, 2) for c in pairs.values())
    sa = sum(math.comb(c, 2) for c in rows.values())
    sb = sum(math.comb(c, 2) for c in cols.values())
    total = math.comb(len(a), 2)
    expected = sa * sb / total if total else 0.0
    top = (sa + sb) / 2
    return 1.0 if top == expected else (index - expected) / (top - expected)


def find_types(task: Task, runs: Sequence[Run], coverage: float = 0.90, confidence: float = 0.95,
               k_max: int = 4, seed: int = 0) -> WorkerTypes:
    """Cluster `runs` into worker types (module docstring) and learn each type's bounds."""
    x = features(task, runs)
    scores: list[tuple[int, float]] = []
    labels = np.zeros(len(runs), dtype=int)
    best = None
    if x.shape[1] and len(runs) >= 4:
        for k in range(2, min(k_max, len(runs) - 1) + 1):
            lab = kmeans(x, k, seed)
            if len(set(lab.tolist())) < k:
                continue
            s = silhouette(x, lab)
            scores.append((k, s))
            if s >= SPLIT and (best is None or s > best[0] + TIE_K):
                best = (s, lab)
    if best is not None:
        labels = best[1]
    k = int(labels.max()) + 1 if len(runs) else 1
    human = next(a.id for a in task.agents if a.is_human)
    learned, took = [], []
    for t in range(k):
        mine = [r for r, lab in zip(runs, labels, strict=True) if lab == t]
        learned.append(learn(task, mine, coverage, confidence))
        took.append(tuple((a, sum(1 for r in mine if a in r.sequence(human)) / len(mine)) for a in task.action_ids))
    return WorkerTypes(tuple(int(v) for v in labels), None if best is None else best[0], tuple(scores),
                       tuple(learned), tuple(took))


def _preferences(types: WorkerTypes, t: int) -> list[str]:
    out = []
    for b in types.learned[t].bounds:
        if b.kept or not b.n:
            continue
        m = round(float(np.median(b.samples)), 3)
        coefficients = f"[{format_seconds(-m * m)}, {format_seconds(2 * m)}, -1]"
        out.append(f"    - {{from: {b.action}.{b.phase}.start, to: {b.action}.{b.phase}.end, "
                   f"domain: [{format_seconds(b.new.lb)}, {format_seconds(b.new.ub)}], kind: quadratic, "
                   f"coefficients: {coefficients}}}")
    return out


def types_yaml(task: Task, types: WorkerTypes) -> str:
    """The ``preference_sets`` block to append to the task (empty with one type, or when the task has
    sets already: its own are kept, and the report says so)."""
    if types.k < 2 or task.preference_sets:
        return ""
    sets = [(types.name(t), _preferences(types, t)) for t in range(types.k)]
    if any(not prefs for _, prefs in sets):
        return ""
    lines = [f"# hrc learn: {types.k} worker types in {len(types.labels)} runs (k-means, k by silhouette "
             f"{types.silhouette:.2f}); each type prefers its own durations: peak at its median, domain its bound",
             "preference_sets:"]
    for name, prefs in sets:
        lines += [f"  {name}:", *prefs]
    return "\n".join(lines) + "\n"


def types_markdown(types: WorkerTypes) -> str:
    """The report's section on worker types."""
    tried = ", ".join(f"k={k}: {s:.2f}" for k, s in types.scores) or "none (too few runs or no spread)"
    out = ["## Worker types", "",
           f"Runs clustered by the person's timing and choices (k-means; mean silhouette per k: {tried}; a split "
           f"needs {SPLIT}): **{types.k} type{'s' if types.k > 1 else ''}**.", ""]
    if types.k < 2:
        return "\n".join(out)
    out += ["| type | runs | bounds learned | actions the person took (share of runs) |", "|---|---:|---:|---|"]
    for t in range(types.k):
        n = sum(1 for v in types.labels if v == t)
        learned = sum(1 for b in types.learned[t].bounds if not b.kept)
        took = ", ".join(f"{a} {share:.0%}" for a, share in types.took[t])
        out.append(f"| {types.name(t)} | {n} | {learned} | {took} |")
    for t in range(types.k):
        rows = [f"{b.action}.{b.phase} [{b.new.lb:g}, {b.new.ub:g}] (n={b.n})"
                for b in types.learned[t].bounds if not b.kept]
        out.append("")
        out.append(f"{types.name(t)}'s bounds: " + ("; ".join(rows) if rows else "none (too few observations)"))
    return "\n".join(out)
