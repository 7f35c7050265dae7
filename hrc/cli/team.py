"""The online commands' one-line refusal of a task with more than one person or robot (issue 37).

The compile plans for any number of people and robots; `hrc dispatch` (and its ``--record``), `hrc
simulate`, the console and the ROS 2 node serve them, and the motion detector in ``hrc detect``, ``hrc
dispatch --detect motion`` and ``hrc simulate --detector motion`` (one detector per person); the console's
and the ROS 2 node's ``--detect motion`` still run one person and one robot (their tracker input names no
person yet). Each of them asks `refuse_team` first and ends with exit status 2 after one ``error:`` line,
before it opens a log or a port.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterable
from pathlib import Path

from hrc.errors import InputError
from hrc.model import Task

__all__ = ["refuse_team", "team_refusal"]


def team_refusal(command: str, kinds: Iterable[str]) -> str | None:
    """The refusal's text (after ``error: FILE: ``) for a task whose agents are of `kinds`, or None for one
    person and one robot."""
    kinds = list(kinds)
    people, robots = kinds.count("human"), kinds.count("robot")
    if (people, robots) == (1, 1) and len(kinds) == 2:
        return None
    return (f"hrc {command} runs one person and one robot; this task has {people} "
            f"{'person' if people == 1 else 'people'} and {robots} robot{'' if robots == 1 else 's'} (compile it, "
            f"read its report; the online side of more agents is not built yet: docs/dispatch.md)")


def refuse_team(command: str, out_dir: str | os.PathLike[str] | None = None, task: Task | None = None) -> bool:
    """Whether `command` must refuse the compiled folder `out_dir` (its ``compiled.json`` header names the
    agents) or `task`; if so, the ``error:`` line is printed. A folder that is not a compile output is
    not refused here: the command says what is wrong with it, as it always did."""
    if task is not None:
        where, kinds = task.source or task.name, [a.kind.value for a in task.agents]
    else:
        from hrc.compile.output import read_header

        try:
            agents = read_header(out_dir or ".")["task"].get("agents", {})
        except (InputError, AttributeError):
            return False
        if not isinstance(agents, dict):
            return False
        where, kinds = str(Path(out_dir or ".") / "compiled.json"), [str(k) for k in agents.values()]
    text = team_refusal(command, kinds)
    if text is None:
        return False
    print(f"error: {where}: {text}", file=sys.stderr)
    return True
