"""The default coupling law and noise, actuator, offset and level models by registered name:
plain strings in a module that imports nothing, so the command line's parsers can show
them without loading the models (and JAX)."""

__all__ = [
    "DEFAULT_ACTUATOR",
    "DEFAULT_COUPLING",
    "DEFAULT_LEVEL_MODEL",
    "DEFAULT_NOISE",
    "DEFAULT_OFFSET",
]

DEFAULT_NOISE = "ar1"
DEFAULT_ACTUATOR = "slope"
DEFAULT_OFFSET = "constant"
# Levels constant within their plateaus (idtool._model._level_model); "auto" fits try the
# relaxing ON level or the creeping level only where the steady fit's plateaus drift.
DEFAULT_LEVEL_MODEL = "steady"
# The power limit, as the paper reports it (idtool._model._coupling_power_limited). The
# load-power law (its small-signal gain free to fall with the load) covered Kt on benches
# whose coupling falls otherwise with the load, but widened a clean bench's bands 23%
# past the noise-only model's and to 0.085 in FR on a paper-like bench with every
# departure (tests/test_coverage.py): not yet the default (issue 26, item 3).
DEFAULT_COUPLING = "power-limited"
