"""The qualitative (ordinary-net) and quantitative (GSPN) views of a task net (paper sections 2-3).

Reachability and coverability, invariants, liveness and their robotic reading; the GSPN view, its
CTMC solution, discrete-event simulation and the cost function J. Pure: no I/O.
"""

__all__: list[str] = []
