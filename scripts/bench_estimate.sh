#!/bin/bash
# hrc show's calibrated compile estimate against the compile it estimates (docs/benchmarks.md, issue 38):
# for each task named (tasks/NAME.yaml), `hrc show --json` (its estimate and the sample it measured), then
# the default `hrc compile` timed by /usr/bin/time (wall, user, sys), the load before and after, and the
# size of compiled.json. EXTRA: more compile options (e.g. EXTRA="--stnu archive").
# Usage: PYTHONPATH=. scripts/bench_estimate.sh cube_stacking kitting_6picks kitting
set -u
out=${BENCH_OUT:-/tmp/hrc-bench-estimate}
for t in "$@"; do
  rm -rf "$out-$t"
  l0=$(cut -d' ' -f1 /proc/loadavg)
  est=$(.venv/bin/hrc show "tasks/$t.yaml" --json | python3 -c "import json,sys; e=json.load(sys.stdin)['estimate']; print(e['wall_seconds'], e['wall_seconds_now'], e['wall_seconds_archive'], e['wall_seconds_archive_no_report'], e['calibration'])")
  tm=$( { /usr/bin/time -f "%e %U %S" .venv/bin/hrc compile "tasks/$t.yaml" --out "$out-$t" -q ${EXTRA:-} ; } 2>&1 | tail -1)
  l1=$(cut -d' ' -f1 /proc/loadavg)
  echo "$t estimate (idle, now, archive, archive without report; sample)=[$est] real (wall user sys)=[$tm] load=$l0-$l1 compiled.json=$(stat -c %s "$out-$t/compiled.json")"
done
