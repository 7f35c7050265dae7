"""The compile's defaults and names that the command line offers, in a module that imports nothing.

``hrc compile``'s argument parser reads them before the command runs (issue 38): were they where they
are used (`hrc.compile.output`, `hrc.compile.search`, `hrc.compile.sink`), building the parser would
import the whole compiler first, and the report's figure process (`hrc.report.drawer`), forked once the
task is read, would start a second later. Those modules export them as before.
"""

from __future__ import annotations

__all__ = ["COVER_DEPTH", "DEFAULT_K", "REPORT_TOP", "SAMPLE_MIN_PLANS", "SEARCH_FAMILIES", "STNU_ARCHIVE",
           "STNU_MODES"]

STNU_MODES = ("graphml", "archive", "none")
"""How the plans' STNUs are written (``hrc compile --stnu``): one GraphML file per plan in ``stnu/`` (the
default), the same files packed into one zip file `STNU_ARCHIVE` (member names as the ``stnu`` paths),
or not at all (``"stnu": null`` per plan)."""

STNU_ARCHIVE = "stnu.zip"

REPORT_TOP = 100
"""Plans the report's ranked table shows by default (plus the best of each class)."""

DEFAULT_K = 50
"""Plans ``hrc compile`` searches for when it switches to the search on its own."""

SEARCH_FAMILIES = 2
"""Default budget of the best-K search: at most this many families compiled per plan asked for (``K``)."""

COVER_DEPTH = 2
"""Default depth of the coverage: the person's first choice, and each choice after it."""

SAMPLE_MIN_PLANS = 64
"""A compile of fewer plans than this takes no up-front sample for its estimate (`hrc.compile.stream`):
its workers start on every plan as soon as the paths are planned. The sample compiles its plans in the
parent, twice, while the workers wait (the workshop's 32 plans: 8 sample plans took 0.11 s each, 0.01 s
the second time, about 1 s of the compile's 6), and a compile this small is over about as soon as a
sample would have said how long it takes (issue 38). `hrc.compile.estimate`'s model leaves it out too."""
