"""Linear structural models (discrete chain, beam, cable, rod).

The structures arrive with their own issue; this package holds no model yet
and imports nothing heavy, so a scene without a structure pays nothing for it.
"""

__all__: list[str] = []
