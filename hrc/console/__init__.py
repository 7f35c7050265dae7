"""The operator console (issue 14): a local web page where the person tells the robot what they do,
and where the engineer sees what it will do.

Strassmair & Taylor 2014, section V.B: a lean human action detector "could rely on buttons". The
console is that detector: it holds one `hrc.dispatch.Dispatcher`, turns the person's presses and the
robot controller's acknowledgements into the dispatcher's JSON lines (`hrc.dispatch.protocol`), and
pushes every decision to the page and the robot over websockets.

    access    who may connect: the run's secrets, this server's Host and Origin only (AccessGuard)
    clock     RunClock: a monotonic clock in run seconds (``--speed``; a resumed run goes on)
    runlog    a new log file per run, or the log of a run to resume (the dispatcher's log)
    views     the map, each plan's routes, the Gantt bars
    session   ConsoleSession: the one dispatcher (written ahead to its log), the page's and robot's messages
    inbox     each client's rate limit, the robot's messages before the pages' (Inbox, TokenBucket)
    connections  the connections held: a cap under the open-file limit, a header deadline, the
              unauthenticated shed first (ConnectionLimiter)
    supervise faults said once a second, not once an event (Throttle, ThrottleFilter, DenialFilter)
    robot     SimulatedRobot: ``--simulate-robot``
    server    ConsoleServer: the Starlette app (page, /ws, /robot)
    run       open_console, serve
    page/     index.html, console.js, console.css (hand-written, no library, served by hrc)
"""
