"""The default noise, actuator and offset models by registered name: plain strings in a
module that imports nothing, so the command line's parsers can show them without loading
the models (and JAX)."""

__all__ = ["DEFAULT_ACTUATOR", "DEFAULT_NOISE", "DEFAULT_OFFSET"]

DEFAULT_NOISE = "ar1"
DEFAULT_ACTUATOR = "slope"
DEFAULT_OFFSET = "constant"
