"""Record a simulated person's tracked positions and what they really did, for `hrc detect` and its tests.

    PYTHONPATH=. .venv/bin/python scripts/make_trace.py tasks/cube_stacking.yaml --out DIR [--run 0]
        [--seed 1] [--sigma 0.05] [--rate 10] [--dropout 0] [--latency 0]

Runs one `hrc simulate` run (policy hrc, the motion detector in front of the dispatcher) and writes
into DIR: ``trace.jsonl``, the stream a tracker and the robot's controller would have sent (the
person's noisy positions ``{"t", "x", "y"}`` and the robot's acknowledgements, in time order), and
``truth.jsonl``, the person's leg events as they happened on the floor.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from hrc.compile.compiler import compile_task
from hrc.detect.sensor import SensorModel
from hrc.io.atomic import write_text_atomic
from hrc.io.task_file import load_task
from hrc.sim.policies import DispatchedController, Policy
from hrc.sim.run import SimContext, SimSettings, make_controller, simulate_run


def record(cps: Any, run: int, seed: int,
           sensor: SensorModel) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """Run `run` of a simulation of the compiled plan set `cps` (seed `seed`): the stream a tracker and
    the robot's controller send, and the person's true leg events."""
    task = cps.task
    ctx = SimContext(task, {"motion": cps}, SimSettings(detector="motion", sensor=sensor), seed)
    stream: list[dict[str, Any]] = []
    human = next(a.id for a in task.agents if a.is_human)

    def controller(c: SimContext, policy: Policy) -> Any:
        ctl = make_controller(c, policy)
        assert isinstance(ctl, DispatchedController)
        position, observe = ctl.position, ctl.observe

        def logged_position(now: float, t: float, x: float, y: float) -> bool:
            stream.append({"t": t, "x": x, "y": y})
            return position(now, t, x, y)

        def logged_observe(h: Any) -> None:
            if h.agent != human or h.action is None:
                obs = {"t": round(h.t, 3), "agent": h.agent, "event": h.event}
                if h.action is not None:
                    obs.update(action=h.action, phase=h.phase)
                stream.append(obs)
            observe(h)

        ctl.position, ctl.observe = logged_position, logged_observe  # type: ignore[method-assign]
        return ctl

    result = simulate_run(ctx, "hrc", run, record=True, controller=controller)
    truth = [{"t": round(h.t, 3), "agent": h.agent, "action": h.action, "phase": h.phase, "event": h.event}
             for h in result.happenings if h.agent == human and h.action is not None]
    return stream, truth


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("task")
    p.add_argument("--out", required=True)
    p.add_argument("--run", type=int, default=0)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--sigma", type=float, default=0.05)
    p.add_argument("--rate", type=float, default=10.0)
    p.add_argument("--dropout", type=float, default=0.0)
    p.add_argument("--latency", type=float, default=0.0)
    a = p.parse_args()
    cps = compile_task(load_task(a.task), seed=0, jobs=1)
    stream, truth = record(cps, a.run, a.seed, SensorModel(a.sigma, a.rate, a.dropout, a.latency))
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    write_text_atomic(out / "trace.jsonl", "".join(json.dumps(x) + "\n" for x in stream))
    write_text_atomic(out / "truth.jsonl", "".join(json.dumps(x) + "\n" for x in truth))
    print(f"wrote {out}/trace.jsonl ({len(stream)} lines) and {out}/truth.jsonl ({len(truth)} events)")


if __name__ == "__main__":
    main()
