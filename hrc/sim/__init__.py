"""Simulation: the task carried out many times over by a simulated person and the robot, on the floor.

Strassmair & Taylor 2014 leave their central hypothesis to future work (section VI): that taking the
co-workers' motion into account makes the team more efficient. `hrc.sim` tests it: one run is the task
executed in the pymunk world in simulated time, the dispatcher (`hrc.dispatch`, the same code as
``hrc dispatch``) in charge of the robot, and the Monte Carlo driver compares policies on the same
seeded people.

    human       HumanModel, draw_human: the simulated person's choice and duration model (seeded)
    detector    Detector: what the dispatcher learns of the person, and when (detection delay)
    floor       Floor: the two discs in the pymunk world, moving along routes; the robot's safety rule
    giveway     Ways: where to make room for the co-worker, and the way round it (on the roadmap)
    policies    POLICIES (hrc, motion-blind, feasible-only, fixed) and the controllers that carry them out
    blind       blind_compile: the motion-blind compile (straight lines, no interference)
    run         simulate_run: one run, and what it measured (RunResult)
    team_run    simulate_team_run: one run of a team (issue 37: any number of people and robots)
    team_floor  TeamFloor: every agent's disc on the floor, the separation per robot-person pair
    team_policies  TeamDispatched, TeamFixed: each robot's order, each person's own hint
    replay      broken_constraints: a run checked against every constraint of its plan's STNU
    metrics     aggregate: per-policy measures
    montecarlo  simulate, simulation_json: many runs, in an executor; the deterministic JSON

It imports the dispatcher, never the reverse (../shared/DESIGN.md); figures live in `hrc.report.simulation`.
"""
