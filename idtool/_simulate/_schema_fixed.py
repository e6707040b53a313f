# ruff: noqa: E501  (the schema's descriptions are long sentences)
"""The fixed sections of the simulator parameter file's schema: all but the ``contact``,
``coupling`` and ``actuator`` sections, which :mod:`idtool._simulate._schema` makes from
the registries (``None`` here), and those sections' fields common to every part."""

from __future__ import annotations

from typing import Any

__all__ = ["DIRECTION", "FIXED", "LEVEL_CREEP", "PULL_START"]

# The contact's optional creep of the friction level (every law).
LEVEL_CREEP: dict[str, Any] = {
    "type": "number",
    "default": 0,
    "description": "Optional, default 0: relative creep rate of the friction coefficient with sliding time [1/s]: mu(t) = friction_coefficient * (1 + level_creep_per_s * max(t - pull_start_s, 0)), so the OFF and ON levels both creep by this fraction of themselves per second (unlike the load cell's additive offset drift, which moves every level by the same newtons and the baseline before the pull too). Truth only: the fit's levels are constant.",
}
# The vibration's direction relative to the sliding (every law); its names are the
# registry's, filled in by idtool._simulate._schema.
DIRECTION: dict[str, Any] = {
    "type": "string",
    "default": "along",
    "description": "Optional, default 'along': the direction of the vibration relative to "
    "the sliding, a name of idtool.DIRECTIONS ('idtool fit --direction' takes the same "
    "names). The contact's cycle average follows it; the coupling law gives the slip "
    "amplitude in every direction (the 'sdof' law, whose contact loads the horn, along "
    "only).",
}
# The actuator's pull start (every model).
PULL_START: dict[str, Any] = {
    "type": "number",
    "minimum": 0,
    "description": "Time at which the pull starts [s]; before it the load cell reads its offset.",
}
# Every section but the registries' (None here, filled by simulator_params_schema).
FIXED: dict[str, Any] = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "$id": "urn:idtool:schema:simulator-params:1",
    "title": "idtool bench simulator parameters, version 1",
    "description": "Input of 'idtool simulate-bench': the true contact and coupling, the actuator, the horn switching, the load cell's noise and the experiment matrix. SI units; every field name ends in its unit (dimensionless ones excepted). The fields of the fit's own model are required, so a file documents the whole simulation; the fields marked optional add departures of the bench from that model (pull-to-pull scatter, a lagging actuator, load-cell offset drift, a coupling law the fit does not ship, a horn fading within its ON windows, a creeping friction level) or noise of the block means drawn from a registered noise model (block_mean_noise), and their defaults (no departure, no block-mean noise) reproduce a file without them bit for bit.",
    "type": "object",
    "required": [
        "params_version",
        "name",
        "material",
        "rig",
        "contact",
        "coupling",
        "actuator",
        "horn_switching",
        "load_cell",
        "experiments",
        "output",
    ],
    "properties": {
        "$schema": {
            "type": "string",
            "description": "Optional: where this file's schema lives (ignored).",
        },
        "params_version": {
            "const": "1",
            "description": 'Version of this parameter format, the string "1".',
        },
        "name": {
            "type": "string",
            "minLength": 1,
            "description": "Name written into dataset.json.",
        },
        "material": {
            "type": "string",
            "minLength": 1,
            "description": "Material written into dataset.json.",
        },
        "description": {
            "type": "string",
            "description": "Optional free text, copied into dataset.json.",
        },
        "rig": {"$ref": "urn:idtool:schema:dataset:1#/$defs/rig"},
        "contact": None,
        "coupling": None,
        "actuator": None,
        "scatter": {
            "type": "object",
            "description": "Optional: pull-to-pull scatter of the contact, one log-normal multiplier per trace drawn from the trace's own random stream; omitted or 0, no scatter.",
            "properties": {
                "friction_ratio_sd": {
                    "type": "number",
                    "minimum": 0,
                    "default": 0,
                    "description": "Standard deviation of the log of the trace's friction-ratio multiplier [-]: the trace's ON level is FR * exp(N(0, friction_ratio_sd)) (capped at 1) times its OFF level, FR being the operating point's.",
                },
                "friction_coefficient_sd": {
                    "type": "number",
                    "minimum": 0,
                    "default": 0,
                    "description": "Standard deviation of the log of the trace's friction-coefficient multiplier [-]: the trace's mu is friction_coefficient * exp(N(0, friction_coefficient_sd)), so its OFF level mu N scatters (its FR stays the operating point's).",
                },
            },
            "additionalProperties": False,
        },
        "horn_fading": {
            "type": "object",
            "description": "Optional: a horn whose slip amplitude fades within each ON window (it heats and detunes), a(t_on) = a0 * (1 - fade_fraction * (1 - exp(-t_on / fade_time_constant_s))), t_on the time since the horn switched on; the ON level rises through the window as the reduction weakens. Omitted or fade_fraction 0: no fading. Truth only: the fit's ON level is constant.",
            "properties": {
                "fade_fraction": {
                    "type": "number",
                    "minimum": 0,
                    "maximum": 0.9,
                    "default": 0,
                    "description": "Fraction f of the slip amplitude a long ON window loses [-]: the amplitude tends to a0 (1 - f).",
                },
                "fade_time_constant_s": {
                    "type": "number",
                    "exclusiveMinimum": 0,
                    "default": 1.0,
                    "description": "Time constant tau of the fade [s].",
                },
            },
            "additionalProperties": False,
        },
        "horn_switching": {
            "type": "object",
            "description": "The horn switches ON and OFF a random delay after the logged ultrasound_on flag does; one delay per switching, Gaussian, clipped at 0.",
            "required": ["delay_mean_s", "delay_std_s"],
            "properties": {
                "delay_mean_s": {
                    "type": "number",
                    "minimum": 0,
                    "description": "Mean lag of the physical switching behind the logged flag [s].",
                },
                "delay_std_s": {
                    "type": "number",
                    "minimum": 0,
                    "description": "Standard deviation of that lag [s].",
                },
            },
            "additionalProperties": False,
        },
        "load_cell": {
            "type": "object",
            "description": "What the load cell adds to the true force.",
            "required": [
                "offset_mean_n",
                "offset_std_n",
                "white_noise_std_n",
                "correlated_noise_std_n",
                "correlated_noise_time_s",
                "mains_frequency_hz",
                "mains_amplitude_n",
                "adc_lsb_n",
            ],
            "properties": {
                "offset_mean_n": {
                    "type": "number",
                    "description": "Mean zero offset of the load cell [N].",
                },
                "offset_std_n": {
                    "type": "number",
                    "minimum": 0,
                    "description": "Trace-to-trace standard deviation of the offset [N].",
                },
                "white_noise_std_n": {
                    "type": "number",
                    "minimum": 0,
                    "description": "Standard deviation of white Gaussian noise [N].",
                },
                "correlated_noise_std_n": {
                    "type": "number",
                    "minimum": 0,
                    "description": "Stationary standard deviation of AR(1) (exponentially correlated) noise [N].",
                },
                "correlated_noise_time_s": {
                    "type": "number",
                    "exclusiveMinimum": 0,
                    "description": "Correlation time of the AR(1) noise [s]; lag-1 correlation exp(-1 / (sample_rate_hz * this)).",
                },
                "mains_frequency_hz": {
                    "type": "number",
                    "exclusiveMinimum": 0,
                    "description": "Frequency of the mains hum [Hz] (50 in Europe, 60 in North America).",
                },
                "mains_amplitude_n": {
                    "type": "number",
                    "minimum": 0,
                    "description": "Amplitude of the mains hum [N]; its phase is random per trace.",
                },
                "adc_lsb_n": {
                    "type": "number",
                    "minimum": 0,
                    "description": "Quantisation step of the analogue-to-digital converter [N]; 0 for none.",
                },
                "offset_drift_sd_n_s": {
                    "type": "number",
                    "minimum": 0,
                    "default": 0,
                    "description": "Optional, default 0: standard deviation of the per-trace rate of a linear drift of the offset [N/s]. Each trace's offset is offset + rate * time_s (0 at time 0, so the offset is the reading at the start), rate ~ N(0, offset_drift_sd_n_s) drawn from the trace's own random stream.",
                },
            },
            "additionalProperties": False,
        },
        "experiments": {
            "type": "object",
            "description": "The experiment matrix: one trace per (normal load, amplitude fraction, ON duration, pull speed, repeat).",
            "required": [
                "normal_loads_n",
                "amplitude_fractions",
                "on_durations_s",
                "pull_speed_m_s",
                "sliding_before_s",
                "sliding_after_s",
                "sample_rate_hz",
                "repeats",
            ],
            "properties": {
                "normal_loads_n": {
                    "type": "array",
                    "minItems": 1,
                    "uniqueItems": True,
                    "items": {"type": "number", "exclusiveMinimum": 0},
                    "description": "Static normal loads [N].",
                },
                "amplitude_fractions": {
                    "type": "array",
                    "minItems": 1,
                    "uniqueItems": True,
                    "items": {"type": "number", "minimum": 0, "maximum": 1},
                    "description": "Commanded horn amplitudes as fractions of max_amplitude_m [-].",
                },
                "on_durations_s": {
                    "type": "array",
                    "minItems": 1,
                    "uniqueItems": True,
                    "items": {"type": "number", "minimum": 0},
                    "description": "Durations of the logged ultrasound ON window [s]; 0 for a trace without ultrasound.",
                },
                "pull_speed_m_s": {
                    "oneOf": [
                        {"type": "number", "exclusiveMinimum": 0},
                        {
                            "type": "array",
                            "minItems": 1,
                            "uniqueItems": True,
                            "items": {"type": "number", "exclusiveMinimum": 0},
                        },
                    ],
                    "description": "Steady pull speed [m/s], or several: the matrix is repeated at each (pulls at two or more speeds at each load and amplitude pin Kt whatever the coupling law).",
                },
                "sliding_before_s": {
                    "type": "number",
                    "minimum": 0,
                    "description": "Steady sliding at the OFF level before the ON window [s], counted from the end of the start-up ramp.",
                },
                "sliding_after_s": {
                    "type": "number",
                    "minimum": 0,
                    "description": "Time recorded after the ON window ends [s].",
                },
                "sample_rate_hz": {
                    "type": "number",
                    "exclusiveMinimum": 0,
                    "description": "Load-cell sample rate [Hz].",
                },
                "repeats": {
                    "type": "integer",
                    "minimum": 1,
                    "description": "Traces per operating point, each with its own noise and timing.",
                },
            },
            "additionalProperties": False,
        },
        "output": {
            "type": "object",
            "description": "How the dataset is written.",
            "required": ["trace_format"],
            "properties": {
                "trace_format": {
                    "enum": ["csv", "parquet"],
                    "description": "'csv' (readable anywhere) or 'parquet' (zstd-compressed, about 4x smaller).",
                }
            },
            "additionalProperties": False,
        },
    },
    "additionalProperties": False,
}
