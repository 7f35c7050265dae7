"""Motion acquisition (Strassmair & Taylor 2014, section V.A): travel paths, durations, interference.

    World                  pymunk space + FCL objects of the map; clearance and swept-disc queries
    plan_paths(task)       -> PathLibrary: OMPL PRM* roadmap per clearance, shortened paths, durations
    plan_motions(task, plan, paths[, routes]) -> (Motion, ...): each leg's route and its time
    find_conflicts(task, plan, paths[, routes]) -> (Conflict, ...): where the co-workers' occupancies
                           meet, each with its two passing orders as difference constraints
    detour(task, paths, agent, origin, target, places, label) -> Path | None: the way round

Modules: `world` (geometry), `planner` (OMPL), `paths` (library, durations), `motions`, `conflicts`
(the co-worker model), `detours`, `exact` (visibility-graph oracle for tests and the benchmark only).
"""

from hrc.motion.conflicts import Conflict, Occupancy, Separation, TimeRef, find_conflicts
from hrc.motion.detours import detour
from hrc.motion.motions import Motion, plan_motions
from hrc.motion.paths import Path, PathLibrary, plan_paths
from hrc.motion.world import World

__all__ = ["Conflict", "Motion", "Occupancy", "Path", "PathLibrary", "Separation", "TimeRef", "World", "detour",
           "find_conflicts", "plan_motions", "plan_paths"]
