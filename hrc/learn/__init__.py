"""Learning from the floor (docs/learn.md): recorded runs in (dispatcher logs, ``hrc simulate`` logs,
MCAP recordings), the task's duration bounds, worker types and the sensing path's delays out.

Above dispatch and sim, below the CLI: it reads what they recorded and writes a *task* (never the
compile's output), which is then compiled again as any task is.

- `hrc.learn.runs`: the records read back and checked against the task;
- `hrc.learn.tolerance`: distribution-free tolerance intervals from order statistics;
- `hrc.learn.estimate`: per phase and agent, durations, travels, bounds, overruns; delays;
- `hrc.learn.task_edit`: the task file with new bounds, comments kept; its diff;
- `hrc.learn.worker_types`: runs clustered into worker types (APA, section VI).
"""
