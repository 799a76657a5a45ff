"""The modes of a connection (see :mod:`couplers.connection`), on their own so
that code which only tests a mode need not define the connection classes."""

__all__ = ["MODES", "OPEN", "GRASPED", "RELEASED"]

#: Modes of a connection, in the only order they can follow each other.
MODES = ("open", "grasped", "released")
OPEN, GRASPED, RELEASED = range(3)
