"""RINEX 2.10/2.11, 3.0x and 4.0x observation and navigation readers (GPS, Galileo, BeiDou, QZSS, GLONASS).

Readers return plain frozen dataclasses; malformed input raises :class:`RinexFormatError`
(a ``ValueError``) whose message names the file and the 1-based line number.

Files are read as stations publish them: plain, gzip (``.gz``), Unix compress (``.Z``) and
Hatanaka-compressed (``.crx``, ``.crx.gz``, RINEX 2 ``.yyd``) are recognised from their content
and decompressed with the ``hatanaka`` package (the reference CRX2RNX algorithm); a truncated or
corrupted compressed file raises :class:`RinexFormatError` naming the file.

Scope
-----
- Observation files, RINEX 2.x (``# / TYPES OF OBSERV``, 80-column epoch records with
  continuation lines for > 12 satellites and > 5 observables) and RINEX 3.x / 4.x
  (``SYS / # / OBS TYPES``, ``>`` epoch records; RINEX 4 observation records are those of 3.05).
  Event flags 2-5 (header records inside the data) and 6 (cycle-slip records) are skipped. Blank
  or zero-filled fields become NaN. Satellite ids are normalised to ``"G05"`` style (RINEX 2 blank
  system letter means GPS).
- Navigation files: GPS LNAV records from RINEX 2.x GPS nav files (``N``), GLONASS records from
  RINEX 2.x GLONASS nav files (``G``), and, from RINEX 3.x (``N``, mixed or one file per system),
  GPS, Galileo (I/NAV; F/NAV records only for satellites without an I/NAV record in the file, the
  others skipped and counted), BeiDou, QZSS and GLONASS records. SBAS and NavIC records are
  skipped and counted by system; records of a supported system that describe no usable orbit
  (e.g. sqrt(A) of a few sqrt(m)) are skipped and counted too, with the reason. Klobuchar
  parameters from ``ION ALPHA`` / ``ION BETA`` (2.x) or ``IONOSPHERIC CORR GPSA/GPSB`` (3.x).
- RINEX 4.x navigation files (records under ``> EPH SAT MESSAGE`` lines, e.g. the IGS / DLR
  ``BRD400DLR`` daily files): the ephemeris messages that have a RINEX 3 record (GPS and QZSS
  LNAV, Galileo I/NAV and F/NAV, BeiDou D1/D2, GLONASS FDMA) are read as above; CNAV, CNV1-3,
  SBAS and NavIC messages and the ``STO`` / ``EOP`` records are counted, not used; Klobuchar from
  the first ``ION G.. LNAV`` record (a RINEX 4 header has no ``IONOSPHERIC CORR``).
- Several nav files (one per system, as some archives publish them) are merged with
  :func:`read_rinex_navs`.
- Observation epochs are converted to GPS time from the file's time system (GPS, GAL, QZS, BDT,
  GLO; :data:`OBS_TIME_SYSTEMS`); others are rejected with a clear error. In nav records, Galileo
  times are GST (= GPST), BeiDou times BDT (kept as such: :mod:`gnss_common.ephemeris` shifts by
  14 s), GLONASS t_b is UTC and converted here to GPS time with the header's LEAP SECONDS (else
  :data:`gnss_common.gps_time.LEAP_SECONDS`).

Notes
-----
Gurtner & Estey, RINEX 2.11 (2007), tables A1-A4; IGS RINEX 3.04/3.05 (2020), tables A1-A8;
IGS RINEX 4.01 (2022): the navigation record types (EPH, STO, EOP, ION) and message types.

Layout: the readers live in :mod:`gnss_common.rinex_obs` and :mod:`gnss_common.rinex_nav`, what they share (file
reading and decompression, fields, time) in :mod:`gnss_common.rinex_format`; this module is their public interface.
"""

from gnss_common.rinex_format import SYSTEM_NAMES, RinexFormatError
from gnss_common.rinex_nav import NAV_SKIP_REASONS, RinexNav, RinexNavHeader, read_rinex_nav, read_rinex_navs
from gnss_common.rinex_obs import OBS_TIME_SYSTEMS, RinexObs, RinexObsEpoch, RinexObsHeader, read_rinex_obs

__all__ = ["NAV_SKIP_REASONS", "OBS_TIME_SYSTEMS", "SYSTEM_NAMES", "RinexFormatError", "RinexNav", "RinexNavHeader",
           "RinexObs", "RinexObsEpoch", "RinexObsHeader", "read_rinex_nav", "read_rinex_navs", "read_rinex_obs"]
