"""Temporal core: STN / STNU values, consistency, dynamic controllability, file formats.

Pure functions over the immutable `STNU` type (`hrc.temporal.network`); exact integer ticks throughout
(`hrc.temporal.ticks` converts seconds and decimal text). Modules: `network` (value types), `graph`
(distance graphs), `potential` (schedules or negative cycles, Goldberg-Radzik), `stn` (consistency, APSP,
minimal dispatchable network, propagation), `dc` (`check_dc`, the registry of DC algorithms, Morris 2014),
`rul` (the default DC algorithm, RUL family, with its C core `_rulcore.c`), `bypass` (bypass closure),
`oracle` (independent exhaustive DC and delay-controllability checks for tests), `delay` (controllability
when contingent timepoints are learnt late: `check_delay`, and the strategy's `delay_window`), `graphml` /
`stnu_text` / `heatlab` (file formats; `read_network` detects the format by content), `limits` /
`xmlread` (bounded, hardened reading), `execution` (real-time execution: the residual network of a
partial execution and the RTE*-style window of each timepoint).
"""

from hrc.temporal.dc import DCResult, Verdict, check_dc
from hrc.temporal.delay import ObservationDelay, check_delay, delay_window
from hrc.temporal.execution import (
    ExecutionMode,
    ExecutionWindow,
    MustWait,
    RealTimeState,
    real_time_state,
    residual_network,
    violated_links,
)
from hrc.temporal.graph import Edge, EdgeKind
from hrc.temporal.network import INF, STNU, ContingentLink, NetworkError, RequirementLink
from hrc.temporal.stn import (
    ConsistencyResult,
    DispatchableSTN,
    Window,
    all_pairs_shortest_paths,
    check_consistency,
    earliest_times,
    minimal_dispatchable_network,
    propagate_execution,
    time_windows,
)

__all__ = [
    "INF",
    "STNU",
    "ConsistencyResult",
    "ContingentLink",
    "DCResult",
    "DispatchableSTN",
    "Edge",
    "EdgeKind",
    "ExecutionMode",
    "ExecutionWindow",
    "MustWait",
    "NetworkError",
    "ObservationDelay",
    "RealTimeState",
    "RequirementLink",
    "Verdict",
    "Window",
    "all_pairs_shortest_paths",
    "check_consistency",
    "check_dc",
    "check_delay",
    "delay_window",
    "earliest_times",
    "minimal_dispatchable_network",
    "propagate_execution",
    "real_time_state",
    "residual_network",
    "time_windows",
    "violated_links",
]
