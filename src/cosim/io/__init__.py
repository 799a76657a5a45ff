"""Files: the run folder (names, lock, signals, write errors), TOML read and
write with input limits, and the meshio export of structure fields.

The bottom layer: it imports nothing of cosim but :mod:`cosim.errors`.
"""
