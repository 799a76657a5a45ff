"""Studies built on runs: the verification cases and their closed-form
answers, the accuracy-cost benchmark, parameter sweeps, and the metrics they
read from a run (intervals, exit velocities, impact regimes).
"""
