"""Vibration along the sliding direction (the default; model notes §3-4)."""

from __future__ import annotations

from idtool._model._contact import prescribed_cycle_average
from idtool._model._direction import DIRECTIONS, AbstractDirection

__all__ = ["Along"]


@DIRECTIONS.register("along")
class Along(AbstractDirection):
    """Slip ``u(theta) = (v / w) theta + a sin(theta)``, parallel to the sliding: the
    kernel :func:`idtool.prescribed_cycle_average` at its default ``n_phase``, exactly
    as before the direction became a choice (the same program, bit for bit)."""

    description = "vibration along the sliding"

    @classmethod
    def cycle_average(
        cls, law, sliding_speed_m_s, amplitude_m, angular_frequency_rad_s, normal_load_n
    ):
        del normal_load_n
        return prescribed_cycle_average(
            law, sliding_speed_m_s, amplitude_m, angular_frequency_rad_s
        )
