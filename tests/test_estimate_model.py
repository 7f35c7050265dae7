"""The calibrated compile estimate (`hrc.compile.estimate.Calibration`, what ``hrc show TASK`` says) held
to within +-50 % of compiles measured on this project's 2-core machine (docs/benchmarks.md, issue 38).

A test that compiled and timed here would fail whenever the shared machine is loaded, so the model is
tested on recorded numbers: what `calibrate` measured for each bundled task (its sample's paces, line
and GraphML bytes, wall-over-CPU ratio) next to ``hrc compile TASK -q`` run right after it
(`scripts/bench_estimate.sh`: wall and user + sys seconds of the process tree, `/usr/bin/time`, and the
load). Three readings of the same model:

- the work, on one worker, against the compile's CPU seconds (what the load changes least);
- on an idle machine, against the wall time of runs at load 1.1-2.2 (other engineers' jobs at nice 19)
  and of runs on a quiet machine (within a quarter);
- at the load the sample saw (`now`), against a run the load stretched (kitting_7picks, load 2.2-3.0).
"""

from __future__ import annotations

import pytest

from hrc.compile.estimate import Calibration, fmt_seconds

# task: (calibration as measured 2026-11-29 03:03-03:06 UTC, plans, --stnu, wall s, user + sys s, load)
RECORDED = {
    "cube_stacking": (Calibration(16, 16, 0.04095, 0.00687, 0.65, 9366, 2463, 1.59, 2), 32, "graphml",
                      2.37, 4.07, (1.11, 1.18)),
    "kitting": (Calibration(16, 16, 0.05955, 0.01018, 0.79, 19107, 3770, 1.60, 2), 2880, "graphml",
                20.92, 39.44, (1.18, 1.35)),
    "kitting_7picks": (Calibration(64, 16, 0.00896, 0.00151, 0.74, 22624, 3470, 1.60, 2), 40320, "graphml",
                       51.09, 82.94, (1.32, 2.16)),
}
# the same at 04:48-04:50 on a quiet machine (nothing else running; the load is the compile's own two workers)
QUIET = {
    "cube_stacking": (Calibration(16, 16, 0.02158, 0.00412, 0.38, 9366, 2463, 1.66, 2), 32, "graphml",
                      1.39, 2.45, (2.03, 2.02)),
    "kitting": (Calibration(16, 16, 0.03241, 0.00606, 0.47, 19107, 3770, 1.64, 2), 2880, "graphml",
                12.50, 23.87, (2.02, 2.02)),
    "kitting_7picks": (Calibration(64, 16, 0.00497, 0.000921, 0.39, 22624, 3470, 1.63, 2), 40320, "graphml",
                       27.16, 50.67, (1.94, 1.94)),
    "kitting_7picks archive": (Calibration(64, 16, 0.00497, 0.000921, 0.39, 22624, 3470, 1.63, 2), 40320,
                               "archive", 26.14, 49.89, (1.94, 2.01)),
}
# kitting_7picks --stnu archive right after, on the same sample, while the load rose to 3
LOADED = (RECORDED["kitting_7picks"][0], 40320, "archive", 78.76, 96.24, (2.16, 3.0))


def _within(estimate: float, real: float) -> bool:
    return 0.5 * real <= estimate <= 1.5 * real


@pytest.mark.parametrize("task", sorted(RECORDED))
def test_the_work_is_estimated_within_half(task):
    cal, plans, stnu, _wall, cpu, _load = RECORDED[task]
    assert _within(cal.wall(plans, 1, stnu), cpu), (cal.wall(plans, 1, stnu), cpu)


@pytest.mark.parametrize("task", sorted(RECORDED))
def test_an_idle_machine_is_estimated_within_half(task):
    cal, plans, stnu, wall, _cpu, _load = RECORDED[task]
    assert _within(cal.wall(plans, 2, stnu), wall), (cal.wall(plans, 2, stnu), wall)


@pytest.mark.parametrize("task", sorted(QUIET))
def test_a_quiet_machine_is_estimated_within_a_quarter(task):
    """The issue's measure (+-50 %) with room: +4 % to +21 % on the quiet runs."""
    cal, plans, stnu, wall, cpu, _load = QUIET[task]
    assert 0.75 * wall <= cal.wall(plans, 2, stnu) <= 1.25 * wall, (cal.wall(plans, 2, stnu), wall)
    assert _within(cal.wall(plans, 1, stnu), cpu)


def test_the_wall_time_at_the_samples_load_is_estimated_within_half():
    cal, plans, stnu, wall, cpu, _load = LOADED
    assert _within(cal.wall(plans, 2, stnu, now=True), wall), (cal.wall(plans, 2, stnu, now=True), wall)
    assert _within(cal.wall(plans, 1, stnu), cpu)
    assert cal.wall(plans, 2, stnu, now=True) > 1.5 * cal.wall(plans, 2, stnu)  # the load read into it


def test_a_sample_on_an_idle_core_reads_no_load():
    """A wall-over-CPU ratio of 1.0003 is an idle core, not ``cores - 1`` other jobs (it was, before)."""
    cal = RECORDED["kitting"][0]
    idle = Calibration(*[getattr(cal, f) for f in ("plans", "families", "first_pace", "pace", "paths_seconds",
                                                    "line_bytes", "graphml_bytes")], wall_ratio=1.0003, cores=2)
    assert idle.wall(2880, 2, now=True) == pytest.approx(idle.wall(2880, 2), rel=1e-3)


def test_the_old_range_said_nothing_and_the_model_keeps_its_parts():
    """What the model adds up (the module docstring): more plans, more time; more workers, less; an
    idle machine never slower than a loaded one; the report and GraphML files cost."""
    cal, plans, *_ = RECORDED["kitting"]
    assert cal.wall(2 * plans, 2) > cal.wall(plans, 2) > cal.wall(plans, 4)
    assert cal.wall(plans, 2, now=True) > cal.wall(plans, 2)
    assert cal.wall(plans, 2, "graphml") > cal.wall(plans, 2, "archive") > cal.wall(plans, 2, "archive", report=False)
    idle = Calibration(10, 10, 0.1, 0.02, 0.0, 1000, 100, 1.0, 2)
    assert idle.wall(100, 2, now=True) == idle.wall(100, 2)
    assert fmt_seconds(cal.wall(plans, 2)).endswith(" s")
