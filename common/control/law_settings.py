"""The lane laws' names and settings, light (numpy only), for the configuration's checks:
the laws themselves and their Warp kernels are common/control/law_pairs.py."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from haptic.common.control.wave import WaveSettings
from haptic.common.model.passivity import PassivitySettings

#: The lane laws, in the order of their message kinds (common/wire/law_messages.py).
LANE_CONTROLS = ("wave", "four-channel", "four-channel-tdpa", "mmt")
#: The laws' period in the comparison, s: the paper's (common/config/defaults, section 4.1).
PERIOD_S = 0.00054
#: Wave impedance b of the wave control in the comparison, N s/m.
WAVE_IMPEDANCE_N_S_PER_M = 20.0


@dataclass(frozen=True)
class LawSettings:
    """What a pair is built with: the period (s), the wave variables' impedance (N s/m), wave
    filter bandwidth (rad/s) and drift gain (1/s), and the TDPA's settings for
    ``four-channel-tdpa``."""

    period_s: float = PERIOD_S
    wave_impedance_N_s_per_m: float = WAVE_IMPEDANCE_N_S_PER_M
    wave_filter_bandwidth_rad_s: float = WaveSettings.filter_bandwidth_rad_s
    wave_drift_gain_per_s: float = WaveSettings.drift_gain_per_s
    passivity: PassivitySettings = dataclasses.field(default_factory=PassivitySettings)

    def wave_settings(self) -> WaveSettings:
        """The wave ports' settings (validated by :class:`WaveSettings`)."""
        return WaveSettings(period_s=self.period_s,
                            impedance_N_s_per_m=self.wave_impedance_N_s_per_m,
                            filter_bandwidth_rad_s=self.wave_filter_bandwidth_rad_s,
                            drift_gain_per_s=self.wave_drift_gain_per_s)


__all__ = ["LANE_CONTROLS", "PERIOD_S", "WAVE_IMPEDANCE_N_S_PER_M", "LawSettings"]
