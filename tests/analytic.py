"""Closed forms for the tests: the single copy lives in ``cosim.studies.analytic``
(``cosim verify`` needs them too); this module only names them for tests."""
from cosim.studies.analytic import (bounce_times, chatter_stop, held_force_rebound_factor,
                                    hertz_contact, kelvin_voigt_clipped, linear_contact,
                                    mass_on_pinned_beam, two_mass_oscillator, zeno_time)

__all__ = ["linear_contact", "kelvin_voigt_clipped", "held_force_rebound_factor",
           "hertz_contact", "two_mass_oscillator", "mass_on_pinned_beam", "bounce_times",
           "zeno_time", "chatter_stop"]
