"""How often a person who follows the first plan keeps its promise (issue 32), with buttons on time.

    PYTHONPATH=. .venv/bin/python scripts/measure_promise.py OUT_DIR [--seeds 20] [--robot anywhere|near]

OUT_DIR is an `hrc compile` output. Each seed plays one run through `hrc.dispatch.protocol.handle_line`
with the independent client of tests/dispatch_client.py: the person follows the first answer's plan,
announces each next action (``next``) and obeys every hint; the robot acts anywhere in its windows
(``--robot near``: within 2 s of each opening). A run keeps the promise when every answer is DC, the
final plan gives the person the first plan's actions in its order, and every link of its STNU holds on
the times that happened. Prints each run and the share, and the makespan median.
"""

from __future__ import annotations

import argparse
import statistics
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT))

from dispatch_client import Run, broken_links  # noqa: E402

from hrc.dispatch import Dispatcher  # noqa: E402
from hrc.dispatch.plan_set import load_plan_set  # noqa: E402
from hrc.dispatch.protocol import handle_line  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out_dir")
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--robot", choices=("anywhere", "near"), default="anywhere")
    args = ap.parse_args()
    plan_set = load_plan_set(args.out_dir)
    base = Dispatcher(plan_set, threads=1)
    kept, spans = 0, []
    for seed in range(args.seeds):
        d = base.fork()
        out = Run(plan_set, lambda line, d=d: handle_line(d, line), seed, human_choice="plan", timing="hinted",
                  announce=True, robot_window=args.robot).play()
        first = plan_set.entry(plan_set.index(out.first["plan"]))
        final = plan_set.entry(plan_set.index(out.answers[-1]["plan"]))
        same = dict(final.plan.sequences)["human"] == dict(first.plan.sequences)["human"]
        broken = broken_links(final.stnu, out.times)
        good = same and not broken and not out.refused and all(a["class"] == "DC" for a in out.answers)
        kept += good
        spans.append(max(t for key, t in out.times.items() if key[3] == "end"))
        print(f"seed {seed}: {'kept' if good else 'BROKEN'} (first {first.id}, final {final.id}"
              f"{'' if same else ', another person part'}{', ' + broken[0] if broken else ''})")
    print(f"{kept} of {args.seeds} runs kept every constraint of the followed plan; makespan median "
          f"{statistics.median(spans):.2f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
