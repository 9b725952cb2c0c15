"""Scanner presets from manufacturers' datasheets: field of view, ranges, noise, rate, resolution settings.

``scanner_config("rtc360:6mm")`` gives a :class:`~nbs_env.config.ScannerConfig` with the Leica RTC360's
field of view, ranges, range noise and measurement rate, and the ``station_time`` of its 6 mm setting.

The station time, the density and the simulated pattern
-------------------------------------------------------
A real instrument's resolution settings are far finer than anything the simulator can cast: the RTC360's
3 mm setting is a 0.017° step, about 180 M directions per station (``MAX_RAYS`` refuses more than 50 M,
and the env casts ~0.1-0.2 M). So a preset sets three things:

- ``station_time``: the seconds the scan takes on the **real** instrument at the named setting, and
  ``setup_time``, the seconds before it ([A], below); :attr:`~nbs_env.sensing.scanner.Scan.acquisition_time`
  reports their sum for every scan;
- ``instrument_step``: the setting's step, so that each simulated return counts for
  ``(angular_step / instrument_step)²`` of the instrument's in the scan-quality density (a stated
  subsampling, measured in ``tests/test_scanner.py``): "dense %" is the instrument's;
- ``angular_step``: the step of the **simulated** cast, ``simulated_step`` if given, else the env default
  (``ScannerConfig().angular_step``, 0.5°). The clouds written hold this pattern's points.

Field of view, range limits, the range noise model (σ by range and incidence), the beam (its footprint
makes mixed pixels at depth edges) and rate are the instrument's and apply to the simulated cast.

Conventions
-----------
Elevations are from the horizontal (0°) up; the pattern covers 360° of azimuth. A scanner whose
datasheet gives a vertical field of V° with a mirror that sweeps both sides of the zenith (a half turn of
the head covers the dome) covers elevations -(V/2 - 90)°..+90°: 300° is -60°..+90°, 270° is -45°..+90°.
A point spacing ``s`` at 10 m is the angular step ``atan(s / 10 m)``. Where a datasheet lists no time for
a setting, the station time is **derived** as the directions of the setting's full field (columns over
360° times rows over the vertical field, counted as :class:`~nbs_env.config.ScannerConfig` counts them)
over the datasheet's measurement rate, rounded up to 0.1 s: a lower bound with no start-up, levelling,
imaging or mirror dead time (the VZ-400's also respects its line-rate and head-speed limits). All times
are scan only, without imaging.

Provenance marks: **[S]** found in a stored copy of the vendor's own text; **[S2]** found in a stored
secondary source that quotes the vendor; **[R]** not found in a stored copy, from the published datasheet
as recalled (a reviewer should check it); **[D]** derived here, as above; **[A]** an assumption, no
source found: the 10 s set-up of every preset (a robot-borne scanner reads its tilt instead of being
levelled), the RTC360's beam (taken as the BLK360 G2's) and the Leica scanners' 0.75 m echo
separation (taken as the VZ-400's).

The presets
-----------
=========  ==================  =============  ===========  ============  ===========  =====================
name       instrument          elevation      range (m)    σ (m)         rate (pt/s)  settings: step, time
=========  ==================  =============  ===========  ============  ===========  =====================
vz400      Riegl VZ-400        -40..+60 [R]   1.5-350      0.003 [R]     122,000 [R]  0.02deg: 0.02°, 737.9 s;
                                              ([S2]-[R])                              0.04deg: 0.04°, 184.5 s;
                                                                                      0.06deg: 0.06°, 82.0 s;
                                                                                      0.08deg: 0.08°, 46.2 s;
                                                                                      0.1deg: 0.1°, 30.0 s
                                                                                      (all [D]; default 0.04deg)
rtc360     Leica RTC360        -60..+90 [R]   0.5-130      0.0004 [R]    2,000,000    3mm: 0.0172°, 91.4 s;
                                              ([R]-[S2])                 [S]          6mm: 0.0344°, 22.9 s;
                                                                                      12mm: 0.0688°, 5.8 s
                                                                                      (steps [R], times [D];
                                                                                      default 6mm)
focus      FARO Focus S 350    -60..+90 [R]   0.6-350 [R]  0.0003 [R]    976,000 [R]  1/1: 0.00879°, 716.3 s;
                                                                                      1/2: 0.0176°, 179.1 s;
                                                                                      1/4: 0.0352°, 44.8 s;
                                                                                      1/5: 0.0439°, 28.7 s;
                                                                                      1/8: 0.0703°, 11.2 s;
                                                                                      1/10: 0.0879°, 7.2 s
                                                                                      (steps [R], times [D]
                                                                                      at quality 1x;
                                                                                      default 1/4)
blk360     Leica BLK360 G2     -45..+90 [R]   0.5-45       0.004 [S2]    680,000 [S]  fast+: 0.143°, 7 s;
                                              ([R]-[S2])                              dense: 0.0688°, 30 s;
                                                                                      dense+: 0.0437°, 75 s
                                                                                      (spacings [S2], dense+
                                                                                      [D]; times [S];
                                                                                      default dense+)
=========  ==================  =============  ===========  ============  ===========  =====================

Which figure is σ, and caveats
------------------------------
- **VZ-400.** σ is the datasheet's *precision*, 3 mm (1σ at 100 m, RIEGL test conditions) [R]. The env
  default σ = 5 mm is the datasheet's *accuracy* (conformity to the true value, which includes
  systematic error) [R]; HELIOS++ uses the same 5 mm as ``accuracy_m`` [S2]. The maximum range is the
  high-speed mode's (300 kHz PRR, 122,000 measurements/s) on targets of reflectance ≥ 90 %; it is
  160 m at ≥ 20 % [R]. The long-range mode (100 kHz, 42,000 measurements/s) reaches 600 m [R]. The
  datasheet's steps are continuous (0.0024°-0.288° along a line, 0.0024°-0.5° between lines [R]), so
  the settings are steps chosen here; their times are [D] at 122,000 measurements/s, 3-120 lines/s
  and ≤ 60°/s head rotation ([R], the last two also in HELIOS++ [S2]): the 0.1° setting is held to
  30 s by the line rate.
- **RTC360.** σ is the datasheet's range noise, 0.4 mm at 10 m (0.5 mm at 20 m) on 89 % albedo [R].
  Its 3D point accuracy is 1.9 mm at 10 m, 2.9 mm at 20 m, 5.3 mm at 40 m [S2]; range accuracy
  1.0 mm + 10 ppm [S2]. Times are [D] at 2 M points/s; a datasheet table of full-dome times was not
  found in a stored copy. The 130 m maximum and the 1.0 mm + 10 ppm are [S2]; the 0.5 m minimum [R].
- **Focus S 350** (the model taken for "FARO Focus"; the current Focus Premium line was not chosen
  because the stored sources disagree on its range variants). σ = 0.3 mm is the tech sheet's raw-data
  ranging noise at 10 m on 90 % reflectance, which FARO specifies at 122,000 points/s [R, low
  confidence on the exact tenth of a millimetre]; its ranging error is ±1 mm [R]. Settings are FARO's
  resolution fractions of 40,960 points per 360° (1/4 = 10,240 points, 6.1 mm at 10 m) [R]. Times are
  [D] at the top rate, 976,000 points/s (quality 1x); each quality step (2x, 3x, 4x: 488,000,
  244,000, 122,000 points/s [R]) doubles them, and FARO's quality setting lengthens the observation
  time per point [S].
- **BLK360 G2** (the 2022 model, not the G1). σ = 4 mm is its range accuracy at 10 m [S2] (7 mm at
  20 m [R]); the datasheet gives no separate range-noise figure that was found. Leica's text gives four
  settings taking 7, 13, 30 or 75 s at 680,000 points/s, and 20 s for a full dome *with* photospheres
  [S]; a stored secondary source names three densities: Dense+ 6 mm, Dense 12 mm, Fast+ 25 mm at 10 m
  [S2]. The times follow 360° x 270° of directions over the step squared at 680,000 points/s: 25 mm
  gives 7.0 s and 12 mm 30.2 s, so Fast+ is the 7 s setting and Dense the 30 s one. 6 mm would take
  121 s, more than any stated time, so Dense+ keeps the 75 s [S] and its step is derived from it [D]
  (0.0437°, 7.6 mm at 10 m). The 13 s setting, whose density no stored source names, is left out. The
  45 m maximum range is [S2]; 0.5 m minimum [R]. Beam 0.4 mrad, 2.25 mm at the window, single-return
  waveform digitising [S2].

Noise models and beams
----------------------
σ grows with range and incidence where a datasheet states σ at two ranges: the signal-dependent part
follows the returned power, ``noise_exponent`` 0.5, and the floor is fitted so that both figures hold
(RTC360: 0.36 mm floor; BLK360 G2: 2.24 mm). The Focus's single figure keeps no floor (0.15 mm at 5 m
head-on, 0.6 mm at 20 m). The VZ-400's single figure is at 100 m; extrapolated down it would give a
TOF scanner sub-millimetre noise indoors, so it stays constant. Beams [S2] unless marked: VZ-400
0.3 mrad (HELIOS++), its 5 ns pulse separating echoes 0.75 m apart; Focus S 350 0.3 mrad, 2.12 mm
at the window, phase-based (every straddling footprint blends); RTC360 [A] as the BLK360 G2.

Sources
-------
Each preset's ``sources`` lists the documents behind its figures, as above. The stored copies were found
with the project's search tools (web pages by address; GitHub files by repository and path where the
index named them, else by the index's file id).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from nbs_env.config.robot import ScannerConfig
from nbs_env.errors import ConfigError

__all__ = ["SCANNERS", "ResolutionSetting", "ScannerModel", "scanner_config", "step_for_spacing"]


def step_for_spacing(spacing: float, distance: float = 10.0) -> float:
    """Angular step in degrees of a point spacing ``spacing`` metres at ``distance`` metres.

    Datasheets state resolution as a spacing at 10 m; the step is ``atan(spacing / distance)``.
    """
    return math.degrees(math.atan(spacing / distance))


def _directions(step: float, elevation_min: float, elevation_max: float) -> int:
    """Directions of a full 360° pattern at ``step`` degrees, counted as :class:`ScannerConfig` counts them.

    Computed here rather than through ``ScannerConfig``: the real settings exceed its ``MAX_RAYS``.
    """
    cols = max(1, round(360.0 / step))
    rows = math.floor((elevation_max - elevation_min) / step + 1e-9) + 1
    return cols * rows


def _ceil_tenth(seconds: float) -> float:
    # Rounded up, so that a derived time never falls below the rate bound it was derived from.
    return math.ceil(seconds * 10.0 - 1e-9) / 10.0


def _rate_bound_time(step: float, elevation_min: float, elevation_max: float, rate: float) -> float:
    """Seconds to measure every direction of the full field at ``step`` at ``rate`` points per second."""
    return _ceil_tenth(_directions(step, elevation_min, elevation_max) / rate)


# Seconds a robot-borne station spends before its scan [A]: the base stops and its vibration settles,
# the scanner reads its tilt (every preset measures it: the VZ-400's inclination sensors, the RTC360's
# and the BLK360's inertial units, the Focus's dual-axis compensator) instead of being levelled by
# hand. No stored source gives such a time for any of the four.
_SETUP_TIME = 10.0

# The noise floor of a datasheet that gives σ at two ranges, R1 < R2, with the shot-noise model
# (``noise_exponent`` 0.5, σ² = floor² + s² · (R / R1)²): floor² = (4 σ1² - σ2²) / 3 when R2 = 2 R1.


def _floor_from_two_ranges(sigma_1: float, sigma_2: float) -> float:
    return math.sqrt((4.0 * sigma_1**2 - sigma_2**2) / 3.0)


# The BLK360 G2's beam [S2]: 0.4 mrad, 2.25 mm at the window, single-return waveform digitising; its
# echo separation is taken as the VZ-400's 0.75 m (a few-ns pulse) [A].
_BLK360_G2_BEAM = {"beam_divergence": 0.0004, "beam_diameter": 0.00225, "echo_separation": 0.75}


# RIEGL VZ-400 figures used by the derivation of its station times [R]: high-speed mode's effective
# rate, the line scan's top speed, the head's top rotation speed. HELIOS++ has the last two as well.
_VZ400_RATE = 122_000.0
_VZ400_MAX_LINES_PER_S = 120.0
_VZ400_MAX_HEAD_DEG_PER_S = 60.0


def _vz400_time(step: float) -> float:
    """Seconds of a VZ-400 panorama (360° x -40..+60°) at ``step`` degrees along and between lines [D].

    The slowest of three limits: the 122,000 measurements/s, the 120 lines/s of the mirror (one line per
    ``step`` of head rotation) and the head's 60°/s.
    """
    by_rate = _directions(step, -40.0, 60.0) / _VZ400_RATE
    by_lines = round(360.0 / step) / _VZ400_MAX_LINES_PER_S
    by_head = 360.0 / _VZ400_MAX_HEAD_DEG_PER_S
    return _ceil_tenth(max(by_rate, by_lines, by_head))


@dataclass(frozen=True)
class ResolutionSetting:
    """One resolution setting of a real instrument.

    Attributes
    ----------
    name : str
        The setting's key in a ``"scanner:setting"`` spec, lower case (``"6mm"``, ``"1/4"``).
    angular_step : float
        The real instrument's step at this setting, degrees (not the simulated cast's).
    station_time : float
        Seconds one full station takes on the real instrument at this setting, scan only.
    note : str
        Where the step and the time come from ([S], [S2], [R], [D]: see the module docstring).
    """

    name: str
    angular_step: float
    station_time: float
    note: str = ""


@dataclass(frozen=True)
class ScannerModel:
    """A real terrestrial laser scanner as its datasheet describes it.

    Attributes
    ----------
    name : str
        Registry key in :data:`SCANNERS` (``"vz400"``, ``"rtc360"``, ``"focus"``, ``"blk360"``).
    title : str
        Manufacturer and model (``"Riegl VZ-400"``).
    elevation_min, elevation_max : float
        Vertical field of view in degrees from the horizontal, over 360° of azimuth.
    min_range, max_range : float
        Range limits in metres.
    range_noise : float
        Standard deviation of the Gaussian range noise in metres (which datasheet figure: module docstring).
    points_per_second : float
        The datasheet's (top) measurement rate.
    settings : tuple of ResolutionSetting
        The resolution settings, finest first.
    default_setting : str
        The setting a bare ``"name"`` spec takes.
    sources : tuple of str
        The documents the figures come from, with their provenance.
    vendor : str
        The manufacturer as its data sheets name it (an E57 record's ``sensorVendor``).
    noise_floor, noise_range, noise_exponent : float
        The noise model (:class:`~nbs_env.config.ScannerConfig`): ``range_noise`` is σ at
        ``noise_range`` head-on; ``noise_exponent`` 0.5 where two ranges' figures fix the floor.
    beam_divergence, beam_diameter : float
        The beam's full angle (rad) and exit diameter (m): the footprint of the mixed pixels.
    echo_separation : float or None
        Echoes farther apart than this (m) are told apart (pulsed: c·τ/2); None blends all (phase).
    setup_time : float
        Seconds a station spends before its scan (the base stops and settles, the tilt is read).
    """

    name: str
    title: str
    elevation_min: float
    elevation_max: float
    min_range: float
    max_range: float
    range_noise: float
    points_per_second: float
    settings: tuple[ResolutionSetting, ...]
    default_setting: str
    sources: tuple[str, ...]
    vendor: str = ""
    noise_floor: float = 0.0
    noise_range: float = 10.0
    noise_exponent: float = 0.0
    beam_divergence: float = 0.0
    beam_diameter: float = 0.0
    echo_separation: float | None = None
    setup_time: float = 0.0

    def __post_init__(self) -> None:
        # A malformed table fails at import rather than when a run first asks for the preset.
        names = [s.name for s in self.settings]
        if not names or len(set(names)) != len(names) or any(n != n.strip().lower() or not n for n in names):
            raise ConfigError(f"{self.name}: setting names must be unique, non-empty and lower case, got {names}")
        if self.default_setting not in names:
            raise ConfigError(f"{self.name}: default setting {self.default_setting!r} is not one of {names}")
        for s in self.settings:
            if not (s.angular_step > 0 and math.isfinite(s.angular_step)):
                raise ConfigError(f"{self.name}:{s.name}: angular_step must be > 0, got {s.angular_step}")
            if not (s.station_time > 0 and math.isfinite(s.station_time)):
                raise ConfigError(f"{self.name}:{s.name}: station_time must be > 0, got {s.station_time}")

    @property
    def setting_names(self) -> tuple[str, ...]:
        return tuple(s.name for s in self.settings)

    def setting(self, name: str | None = None) -> ResolutionSetting:
        """The setting called ``name`` (case-insensitive), or the default one.

        Raises
        ------
        ConfigError
            No setting of that name; the message lists the valid ones.
        """
        key = self.default_setting if name is None else name.strip().lower()
        for s in self.settings:
            if s.name == key:
                return s
        raise ConfigError(
            f"{self.title} ({self.name}) has no setting {name!r}; valid settings: "
            f"{', '.join(self.setting_names)} (default {self.default_setting})"
        )


def _vz400() -> ScannerModel:
    steps = (0.02, 0.04, 0.06, 0.08, 0.1)
    return ScannerModel(
        name="vz400",
        title="Riegl VZ-400",
        vendor="RIEGL Laser Measurement Systems",
        elevation_min=-40.0,
        elevation_max=60.0,
        min_range=1.5,
        max_range=350.0,
        range_noise=0.003,
        # One figure (at 100 m) and none nearer: σ is kept constant rather than extrapolated down.
        noise_floor=0.003,
        noise_range=100.0,
        beam_divergence=0.0003,
        echo_separation=0.75,
        setup_time=_SETUP_TIME,
        points_per_second=_VZ400_RATE,
        settings=tuple(
            ResolutionSetting(
                f"{s:g}deg",
                s,
                _vz400_time(s),
                f"{s:g}° along and between lines ({1000 * math.tan(math.radians(s)) * 10:.1f} mm at 10 m), a "
                "step chosen in the datasheet's 0.0024°-0.288° [R]; time [D] at 122,000 meas./s, "
                "120 lines/s, 60°/s",
            )
            for s in steps
        ),
        default_setting="0.04deg",
        sources=(
            "RIEGL VZ-400 data sheet, '3D Terrestrial Laser Scanner with Online Waveform Processing' (RIEGL "
            "Laser Measurement Systems, riegl.com; version and date not recorded) [R], not found in a stored "
            "copy: field 100° (+60°/-40°) x 360°; minimum range 1.5 m; 350 m (reflectance >= 90 %) / 160 m "
            "(>= 20 %) at 300 kHz PRR, 122,000 meas./s (high-speed mode); 600 m / 42,000 meas./s at 100 kHz; "
            "accuracy 5 mm, precision 3 mm (1 sigma at 100 m); step 0.0024°-0.288° (line), 0.0024°-0.5° "
            "(frame); 3-120 lines/s; head 0-60°/s.",
            "HELIOS++ scanner definition 'riegl_vz400', github.com/3dgeo-heidelberg/helios data/scanners_tls.xml "
            "(stored at commit 00794e552a18; page of tag v1.2.0) [S2]: accuracy_m 0.005, rangeMin_m 1.5, "
            "pulseFreqs_Hz 100000/300000, scanFreqMin/Max_Hz 3/120, headRotatePerSecMax_deg 60, "
            "scanAngleEffectiveMax_deg 50 (+-50° = a 100° line).",
            "A ROS RIEGL VZ-400 driver, rieglctrl (GitHub file, full-text index id 49887197123; repository not "
            "named by the index) [S2]: default line range 30°-130° from the zenith (= +60°..-40° elevation), "
            "frame 0°-360°; measurement programs 0 = long range, 1 = high speed.",
        ),
    )


def _rtc360() -> ScannerModel:
    rate = 2_000_000.0
    spacings = (("3mm", 0.003), ("6mm", 0.006), ("12mm", 0.012))
    return ScannerModel(
        name="rtc360",
        title="Leica RTC360",
        vendor="Leica Geosystems",
        elevation_min=-60.0,
        elevation_max=90.0,
        min_range=0.5,
        max_range=130.0,
        range_noise=0.0004,
        noise_floor=_floor_from_two_ranges(0.0004, 0.0005),
        noise_exponent=0.5,
        # No stored source gives the RTC360's beam: the BLK360 G2's is taken [A].
        **_BLK360_G2_BEAM,
        setup_time=_SETUP_TIME,
        points_per_second=rate,
        settings=tuple(
            ResolutionSetting(
                name,
                step_for_spacing(s),
                _rate_bound_time(step_for_spacing(s), -60.0, 90.0, rate),
                f"{1000 * s:g} mm at 10 m [R]; time [D] at 2,000,000 points/s over 360° x 300°",
            )
            for name, s in spacings
        ),
        default_setting="6mm",
        sources=(
            "Leica RTC360 data sheet (Leica Geosystems; leica-geosystems.com/-/media/files/leicageosystems/"
            "products/datasheets/leica-rtc360-ds.ashx, the address as quoted by a stored secondary source; "
            "version and date not recorded) [R], not found in a stored copy: range 0.5-130 m; range noise "
            "0.4 mm at 10 m, 0.5 mm at 20 m (89 % albedo); up to 2,000,000 points/s; field 360° x 300°; "
            "resolution 3, 6 or 12 mm at 10 m.",
            "'Reality Capture 도구 지형도' (Korean survey of reality-capture tools, GitHub markdown, index id "
            "71243415636; written 2026-09-21, revised 2026-10-07) [S2], quoting the data sheet above: 3D point "
            "accuracy 1.9 mm at 10 m, 2.9 mm at 20 m, 5.3 mm at 40 m (68 %).",
            "Leica Geosystems US blog, 2019-02-26, psg.leica-geosystems.us/2019/02/26/laser-scanning-should-be-"
            "required-for-every-school-building-new-technology-makes-it-possible/ [S]: 'the RTC360 scans "
            "2 million points per second while simultaneously capturing HDR imagery'.",
            "A robot dataset's sensor table (GitHub README, index id 41606067301) [S2]: 'Leica RTC360 | 130m "
            "range, 1mm+10ppm accuracy'. A TLS fusion script (GitHub file, index id 71630571886) [S2]: on its "
            "RTC360 data 'elevations stop at -61.6 degrees', the lower edge of the 300° field.",
        ),
    )


def _focus() -> ScannerModel:
    rate = 976_000.0
    fractions = (1, 2, 4, 5, 8, 10)
    settings = []
    for f in fractions:
        step = 360.0 / (40_960 / f)
        spacing_mm = 1000 * math.tan(math.radians(step)) * 10
        settings.append(
            ResolutionSetting(
                f"1/{f}",
                step,
                _rate_bound_time(step, -60.0, 90.0, rate),
                f"{40_960 // f:,} points per 360° ({spacing_mm:.1f} mm at 10 m) [R]; time [D] at 976,000 points/s "
                "(quality 1x) over 360° x 300°",
            )
        )
    return ScannerModel(
        name="focus",
        title="FARO Focus S 350",
        vendor="FARO Technologies",
        elevation_min=-60.0,
        elevation_max=90.0,
        min_range=0.6,
        max_range=350.0,
        range_noise=0.0003,
        noise_exponent=0.5,
        beam_divergence=0.0003,
        beam_diameter=0.00212,
        echo_separation=None,
        setup_time=_SETUP_TIME,
        points_per_second=rate,
        settings=tuple(settings),
        default_setting="1/4",
        sources=(
            "FARO Focus S 350 tech sheet (FARO Technologies, faro.com; version and date not recorded) [R], not "
            "found in a stored copy: range 0.6-350 m (90 % reflectance, upright incidence); 122,000 / 244,000 "
            "/ 488,000 / 976,000 points/s; ranging error +-1 mm; raw ranging noise of a few tenths of a mm at "
            "10 m on 90 % reflectance, specified at 122,000 points/s (0.3 mm taken, low confidence); field "
            "300° vertical x 360°; finest step 0.009° (40,960 points per 360°).",
            "FARO knowledge base, 'Quality Setting Function on the Focus3D', knowledge.faro.com/Hardware/Focus/"
            "Focus/Quality_Setting_Function_on_the_Focus3D [S]: the quality factors lengthen the observation "
            "time per point to lower the ranging noise, at the cost of scan time.",
        ),
    )


def _blk360() -> ScannerModel:
    # Leica's times (7, 13, 30, 75 s at 680,000 points/s [S]) fit 360° x 270° over the step squared at
    # that rate: the 25 mm (Fast+) and 12 mm (Dense) spacings [S2] give 7.0 and 30.2 s. The 6 mm a
    # secondary source gives Dense+ would take 121 s that way, so Dense+ keeps Leica's 75 s and its
    # step is derived from it [D]: 0.0437°, 7.6 mm at 10 m. The 13 s setting, whose spacing no stored
    # source names, is left out.
    dense_plus = math.degrees(math.atan(_blk360_spacing(75.0) / 10.0))
    settings = (
        (
            "dense+",
            dense_plus,
            75.0,
            f"{10_000 * math.tan(math.radians(dense_plus)):.1f} mm at 10 m [D] from "
            "75 s [S] at 680,000 points/s over 360° x 270° (a stored secondary source's 6 mm would take 121 s)",
        ),
        ("dense", step_for_spacing(0.012), 30.0, "12 mm at 10 m [S2]; 30 s scan only [S] (30.2 s by the rate)"),
        ("fast+", step_for_spacing(0.025), 7.0, "25 mm at 10 m [S2]; 7 s scan only [S] (7.0 s by the rate)"),
    )
    return ScannerModel(
        name="blk360",
        title="Leica BLK360 G2",
        vendor="Leica Geosystems",
        elevation_min=-45.0,
        elevation_max=90.0,
        min_range=0.5,
        max_range=45.0,
        range_noise=0.004,
        noise_floor=_floor_from_two_ranges(0.004, 0.007),
        noise_exponent=0.5,
        **_BLK360_G2_BEAM,
        setup_time=_SETUP_TIME,
        points_per_second=680_000.0,
        settings=tuple(ResolutionSetting(name, step, t, note) for name, step, t, note in settings),
        default_setting="dense+",
        sources=(
            "Leica BLK360 (G2, 2022) product text as reproduced by a reseller's site (GitHub React file, index "
            "id 9452245420) [S]: 'captures point clouds at a rate of 680,000 points per second'; 'Four scan "
            "settings capture data in 7, 13, 30, or 75 seconds'; 'taking 20 seconds for a full-dome scan with "
            "photospheres'.",
            "Portuguese survey note on professional point-cloud capture (GitHub markdown, index id 71228734618, "
            "2026-09-17) [S2]: BLK360 G2 '6 mm (modo Dense+), 12 mm (Dense), 25 mm (Fast+)'.",
            "A laboratory equipment list (GitHub file, index id 65736433502) [S2]: BLK360 G2 'alcance de até "
            "45m', 'Precisão 4mm @ 10m'.",
            "Leica BLK360 (G2) data sheet (Leica Geosystems, leica-geosystems.com; version and date not "
            "recorded) [R], not found in a stored copy: range 0.5-45 m; field 360° x 270°; range accuracy "
            "4 mm at 10 m, 7 mm at 20 m; 3D point accuracy 6 mm at 10 m, 8 mm at 20 m.",
        ),
    )


def _blk360_seconds(step: float) -> float:
    """Seconds of a BLK360 G2 scan at ``step`` degrees by the rule its four stated times follow:
    360° x 270° of directions over the step squared, at 680,000 points/s [D]."""
    return 360.0 * 270.0 / step**2 / 680_000.0


def _blk360_spacing(seconds: float) -> float:
    """Spacing at 10 m (metres) of the BLK360 G2 setting that takes ``seconds`` by that rule [D]."""
    return 10.0 * math.tan(math.radians(math.sqrt(360.0 * 270.0 / (seconds * 680_000.0))))


#: The presets by name.
SCANNERS: dict[str, ScannerModel] = {m.name: m for m in (_vz400(), _rtc360(), _focus(), _blk360())}


def scanner_config(spec: str, *, simulated_step: float | None = None, height: float = 1.5) -> ScannerConfig:
    """A :class:`~nbs_env.config.ScannerConfig` for a real scanner at one of its resolution settings.

    Parameters
    ----------
    spec : str
        ``"NAME"`` (the model's default setting) or ``"NAME:SETTING"``, e.g. ``"rtc360:6mm"``,
        ``"focus:1/4"``, ``"vz400:0.04deg"``; case-insensitive. Names: :data:`SCANNERS`.
    simulated_step : float, optional
        Angular step of the simulated cast in degrees; default the env's (``ScannerConfig().angular_step``).
        It is **not** the setting's step: the real steps (0.01°-0.1°) would cast tens to hundreds of
        millions of rays per scan.
    height : float
        Optical centre above the floor, metres.

    Returns
    -------
    ScannerConfig
        The model's field of view, range limits, range noise and rate; ``station_time`` = the real
        instrument's seconds per station at the setting, which every scan reports as its acquisition
        time. The point density is that of the simulated pattern.

    Raises
    ------
    ConfigError
        Unknown scanner or setting (the message lists the valid ones), or a ``simulated_step`` or
        ``height`` that ``ScannerConfig`` refuses.
    """
    if not isinstance(spec, str):
        raise ConfigError(f"scanner spec must be a string 'NAME' or 'NAME:SETTING', got {spec!r}")
    name, colon, setting_name = spec.partition(":")
    key = name.strip().lower()
    model = SCANNERS.get(key)
    if model is None:
        raise ConfigError(f"unknown scanner {name.strip()!r} in {spec!r}; valid scanners: {', '.join(SCANNERS)}")
    setting = model.setting(setting_name if colon else None)
    step = ScannerConfig().angular_step if simulated_step is None else simulated_step
    return ScannerConfig(
        angular_step=step,
        elevation_min=model.elevation_min,
        elevation_max=model.elevation_max,
        min_range=model.min_range,
        max_range=model.max_range,
        range_noise=model.range_noise,
        noise_floor=model.noise_floor,
        noise_range=model.noise_range,
        noise_exponent=model.noise_exponent,
        beam_divergence=model.beam_divergence,
        beam_diameter=model.beam_diameter,
        echo_separation=model.echo_separation,
        instrument_step=setting.angular_step,
        setup_time=model.setup_time,
        height=height,
        points_per_second=model.points_per_second,
        station_time=setting.station_time,
        preset=f"{key}:{setting.name}",
    )


def datasheet_differences(scanner: ScannerConfig) -> list[str]:
    """The datasheet fields a scanner that names a preset holds at other values.

    ``ScannerConfig.preset`` is what ``metrics.json`` and the E57 header record as the instrument
    simulated, so it must describe the values the scanner holds. Only the simulated step and the
    height are the user's: neither is a datasheet figure.

    Parameters
    ----------
    scanner : ScannerConfig
        A scanner whose ``preset`` is a valid ``"NAME:SETTING"`` (or None).

    Returns
    -------
    list of str
        ``"max_range 350.0 (the datasheet's 130.0)"`` per differing field, in field order; empty when
        the preset is None or every datasheet value is held.
    """
    if scanner.preset is None:
        return []
    sheet = scanner_config(scanner.preset, simulated_step=scanner.angular_step, height=scanner.height)
    held, wanted = scanner.to_dict(), sheet.to_dict()
    return [
        f"{name} {held[name]!r} (the datasheet's {wanted[name]!r})" for name in wanted if held[name] != wanted[name]
    ]
