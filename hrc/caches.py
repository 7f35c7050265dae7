"""The per-process caches' one shared rule: keyed by identity (``id(obj)``, with the object kept beside
its value so the id cannot be reused while it is held), bounded, the oldest entry forgotten first.

The compiler reads one network or task many times over (`hrc.temporal.rul.edge_arrays`,
`hrc.compile.classify.packed_graph`, `hrc.temporal.network.lineage`, the links the temporal net creator
builds per task); hashing those frozen objects by value would cost more than what is kept.
"""

from __future__ import annotations

__all__ = ["make_room"]


def make_room(cache: dict, cap: int) -> None:
    """Forget the oldest entries of `cache` until it holds fewer than `cap`. Never raises, also when
    another thread trims or fills the same cache at once (a Dask worker's threads compile side by side):
    an entry the other thread took first is simply gone, and a dict changing size under the iterator
    ends this round, to be finished by the next call."""
    while len(cache) >= cap:
        try:
            cache.pop(next(iter(cache)), None)
        except (StopIteration, RuntimeError):
            return
