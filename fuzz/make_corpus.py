"""Write the seed corpus ``fuzz/corpus/TARGET/`` from the bundled tasks, maps and test data, and from a
compile of the workshop (its STNUs, a log of a short run) and of the two workers' team (the team's frames):
``python fuzz/make_corpus.py COMPILED_DIR TEAM_DIR``.

Small on purpose (a few files per target, most under 4 KiB): libFuzzer grows it; the long run
(``make fuzz``) adds what it finds with ``--grow``. Re-running it rewrites the same files.
"""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CORPUS = ROOT / "fuzz" / "corpus"


def _put(target: str, data: bytes) -> None:
    folder = CORPUS / target
    folder.mkdir(parents=True, exist_ok=True)
    (folder / hashlib.sha1(data).hexdigest()).write_bytes(data)  # noqa: S324 - a name, as libFuzzer names units


def team(folder: str) -> None:
    """Frames for `team_frames` (alice's page, bob's page, the shared view, the robot's controller, the
    protocol, in turn) from the first answer of the compiled team in `folder`: each person presses what
    they are told, the robot acknowledges its step, then undo, away and back."""
    from hrc.dispatch import Dispatcher
    from hrc.dispatch.protocol import answer

    first = json.loads(answer(Dispatcher.from_folder(folder), b'{"t": 0, "event": "tick"}'))
    people, robots = list(first["people"]), list(first["robots"])
    event = ("action", "phase", "event")

    def press(person: str, hseq: int) -> bytes:
        hint = first["people"][person] or {}
        return json.dumps({"type": "press", "hseq": hseq, **{k: hint.get(k, "") for k in event}}).encode()

    step = first["robots"][robots[0]] or {}
    frames = [*(press(p, 0) for p in people), press(people[0], 1),
              json.dumps({"type": "ack", **{k: step.get(k, "") for k in event}}).encode(),
              b'{"t": 1.0, "event": "tick"}', json.dumps({"type": "undo", "hseq": 1}).encode(),
              json.dumps({"type": "away", "hseq": 1}).encode(), b'{"type": "back", "hseq": 0}',
              json.dumps({"type": "ack", "robot": people[0], **{k: step.get(k, "") for k in event}}).encode(),
              json.dumps({"t": 2.0, "agent": people[1], "event": "back"}).encode()]
    _put("team_frames", b"\n".join(frames[:5]))
    _put("team_frames", b"\n".join(frames))


def main(compiled: str) -> None:
    sys.path.insert(0, str(ROOT))
    from hrc.dispatch import Dispatcher
    from hrc.dispatch.protocol import answer
    from hrc.temporal.graphml import read_graphml, write_graphml
    from hrc.temporal.stnu_text import write_stnu_text

    for task in ("cube_stacking.yaml", "floorplan_demo.yaml"):
        text = (ROOT / "tasks" / task).read_text()
        text = text.replace("../maps/floorplan_demo.yaml", "map.yaml").replace("../maps/workshop.yaml", "workshop.yaml")
        _put("task_yaml", text.encode())
    for name in ("workshop.yaml", "floorplan_demo.yaml"):
        _put("map_yaml", (ROOT / "maps" / name).read_bytes())
    for name in ("room.yaml", "detour.yaml"):
        _put("map_yaml", (ROOT / "tests" / "data" / "spatial" / name).read_bytes())
    _put("dxf", (ROOT / "maps" / "floorplan.dxf").read_bytes())
    _put("dxf", b"0\nSECTION\n2\nENTITIES\n0\nLWPOLYLINE\n8\n0\n90\n4\n70\n1\n10\n1\n20\n1\n"
                b"10\n3\n20\n1\n10\n3\n20\n3\n10\n1\n20\n3\n0\nENDSEC\n0\nEOF\n")
    folder = Path(compiled)
    stnus = sorted((folder / "stnu").glob("*.graphml"))[:3]
    for path in stnus:
        data = path.read_bytes()
        _put("graphml", data)
        _put("network_file", data)
        stnu = read_graphml(data)
        _put("stnu_text", write_stnu_text(stnu).encode())
        _put("network_file", write_stnu_text(stnu).encode())
        _put("graphml", write_graphml(stnu).encode())
    heat = ('{"nodes": [{"node_id": 1}, {"node_id": 2}, {"node_id": 3}, {"node_id": 4}], "constraints": ['
            '{"first_node": 0, "second_node": 1, "type": "stc", "min_duration": 0, "max_duration": "inf"},'
            '{"first_node": 1, "second_node": 2, "type": "stcu", "min_duration": 1.5, "max_duration": 2.25},'
            '{"first_node": 2, "second_node": 3, "type": "stc", "min_duration": 0.1, "max_duration": 3},'
            '{"first_node": 3, "second_node": 4, "type": "stcu", "min_duration": -1.0, "max_duration": 2}]}')
    _put("heatlab", heat.encode())
    _put("network_file", heat.encode())
    _put("apa", (ROOT / "tasks" / "apa_fig6.stpp.json").read_bytes())
    _put("apa", (ROOT / "tests" / "data" / "apa_rigid_past.json").read_bytes())

    d = Dispatcher.from_folder(folder)
    lines = [b'{"t": 0, "event": "tick"}']
    first = json.loads(answer(d, lines[0]))
    wait = first["robot"]["wait_for"].split(".")
    obs = {"t": 0.5, "agent": wait[0], "action": wait[1], "phase": wait[2], "event": wait[3]}
    lines.append(json.dumps(obs).encode())
    robot = json.loads(answer(d, lines[1])).get("robot") or {}
    if "action" in robot:
        lines.append(json.dumps({"t": robot["earliest"], "agent": "robot",
                                 **{k: robot[k] for k in ("action", "phase", "event")}}).encode())
    lines += [b'{"t": 9.0, "agent": "human", "action": "cube3", "phase": "put", "event": "start"}',
              b'{"t": 10, "event": "undo"}', b'{"t": 11, "agent": "human", "event": "away"}']
    _put("dispatch_lines", b"\n".join(lines[:3]))
    _put("dispatch_lines", b"\n".join(lines))
    _put("console_frames", b"\n".join(
        [json.dumps({"type": "press", "hseq": 0, "id": 1, "action": obs["action"], "phase": obs["phase"],
                     "event": obs["event"]}).encode(),
         json.dumps({"type": "ack", "id": "a", "t": 3.5, **{k: robot.get(k, "") for k in ("action", "phase",
                                                                                       "event")}}).encode(),
         b'{"type": "undo", "id": 2}', b'{"type": "position", "t": 1, "x": 2, "y": 3}']))
    from hrc.dispatch.logfile import LOG_VERSION, encode_answer, encode_header, encode_input
    from hrc.dispatch.protocol import log_header

    d = Dispatcher.from_folder(folder)
    log = encode_header(log_header(d, LOG_VERSION))
    for line in lines[:3]:
        log += encode_input(line) + encode_answer(answer(d, line))
    _put("dispatch_log", log)
    _put("dispatch_log", log[:-7])  # a torn end
    for name in ("workshop_005_10hz.trace.jsonl", "workshop_015_5hz_drop5.trace.jsonl"):
        trace = (ROOT / "tests" / "data" / "detect" / name).read_bytes().split(b"\n")
        _put("detect_trace", b"\n".join(trace[:30]))
    _put("rul_verdict", bytes(range(64)))
    _put("rul_verdict", bytes([5, 2, 1, 0, 3, 10, 20, 8, 1, 2, 40, 9, 1, 3, 0, 2, 30, 1, 1]))
    _put("stn_distances", bytes(range(40)))
    _put("stn_distances", bytes([4, 6, 0, 1, 10, 1, 2, 20, 2, 3, 5, 3, 0, 200, 1, 3, 7, 2, 0, 9]))
    _put("dispatch_history", bytes(range(80)))
    _put("dispatch_history", bytes([20, *([0, 50] * 30)]))


if __name__ == "__main__":
    main(sys.argv[1])
    team(sys.argv[2])
