"""hrc: a spatio-temporal schedule compiler and dispatcher for human-robot collaboration.

Pipeline (../shared/DESIGN.md): task + map -> plan generation -> motion acquisition -> temporal net
creator (one STNU per plan) -> DC / consistent / inconsistent -> ranked, compiled plan set.
"""

__version__ = "0.1.0"
