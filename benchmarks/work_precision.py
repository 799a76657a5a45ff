"""The work-precision study of three_mass f100 (the README's picture):
``cosim bench`` over Gauss-Seidel, Jacobi and implicit at five step sizes,
the paper's RK45 and the monolithic scheme at four tolerances, each row on
the scene and four copies moved by round-off (``--spread 5``).

Run from the project root: ``python benchmarks/work_precision.py [--out DIR]``
(needs the `plot` extra for the picture).  The table it prints starts with
the machine it ran on.
"""
import sys

from cosim.cli import main

#: the scene and four round-off copies (+1, -1, +2, -2 ulps) per row
SPREAD = 5

if __name__ == "__main__":
    out = sys.argv[sys.argv.index("--out") + 1] if "--out" in sys.argv else "runs/work-precision"
    sys.exit(main(["bench", "cases/three_mass.toml", "--variant", "f100", "--schemes",
                   "gauss_seidel,jacobi,implicit", "--steps", "8e-5,4e-5,3e-5,2e-5,1e-5",
                   "--spread", str(SPREAD), "--out", out]))
