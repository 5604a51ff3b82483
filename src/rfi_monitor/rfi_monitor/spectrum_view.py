"""The monitor's spectrum as a picture: a rolling waterfall of block spectra on a fixed dB scale (pure module, no ROS).

The node (:mod:`rfi_monitor.spectrum_topics`) publishes it as a ``sensor_msgs/Image`` for Foxglove and rviz2. Nothing
here analyses anything: a row is the Welch spectrum the estimator computed for the block's analysis
(``RfiMonitor.last_spectrum``, :class:`rfi_monitor.estimate.BlockSpectrum`), put on a display scale.

Axes (also written into the image's ``header.frame_id``, :func:`axis_frame_id`):

* columns: frequency relative to the RF centre (``center_frequency_hz`` of the IF block), ascending from left to
  right, one column per Welch bin; column j is centred at ``f_lo_hz + j * (f_hi_hz - f_lo_hz) / (width - 1)``. A
  real IF stream gives nfft // 2 + 1 columns covering its Nyquist band (a negative IF, spectrally inverted, is
  flipped so that the axis still ascends); a complex one nfft columns from -fs/2 - IF.
* pixel value (mono8): power per bin in dB relative to the square of the quantiser's range
  (``2**(bits - 1)`` counts times ``scale`` V, "dBFS"), mapped linearly from ``min_dbfs`` (0, black) to ``max_dbfs``
  (255, white) and clipped; an empty bin (power 0) is 0. A fixed scale: a jammer raises the picture, an AGC that
  lowers the noise darkens it.
* rows: one per update (``rate_hz`` of stamp time), newest at the top (row 0), ``rows`` rows: the top row is the
  spectrum of the block stamped ``header.stamp``, row r about r / rate_hz seconds older. Rows of no update yet
  (after a start or a change of axis) are 0.

The swept band (:meth:`Waterfall.band_columns`): the jammer's ``sweep_start_frequency_hz`` .. + ``sweep_bandwidth_hz``
(relative to the RF centre, as on /rfi/jammer_state) of the block each row shows, in columns, NaN for a row whose block
reported none.

Example
-------
>>> import numpy as np
>>> from rfi_monitor.estimate import BlockSpectrum
>>> w = Waterfall(rows=4, min_dbfs=-80.0, max_dbfs=0.0)
>>> psd = np.full(129, 1e-4)            # real samples, nfft 256: -40 dB per bin at full scale 1
>>> w.add(BlockSpectrum(0, psd, 4e6, 1e6, False), full_scale=1.0, band_hz=(float('nan'), float('nan')))
True
>>> int(w.image()[0, 0]), int(w.image()[1, 0]), w.image().shape
(128, 0, (4, 129))
>>> w.f_lo_hz, w.f_hi_hz
(-1000000.0, 1000000.0)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rfi_monitor.estimate import BlockSpectrum, relative_frequency_hz
from rfi_node_common.params import parameter

FRAME_SEPARATOR = ';'
"""Separates the frame name from the axis fields in ``header.frame_id`` (:func:`axis_frame_id`)."""


@dataclass(frozen=True)
class WaterfallParams:
    """Parameters of the spectrum topics (defined here once; the node's MonitorNodeParams takes them over)."""

    spectrum_rate_hz: float = parameter(
        5.0, 'Rows per second of stamp time added to the waterfall rfi/spectrum/waterfall (sensor_msgs/Image, '
        'mono8) and its swept-band overlay rfi/spectrum/swept_band (visualization_msgs/ImageMarker), Hz. Published '
        'only while someone subscribes (nothing is computed otherwise); each row is the Welch spectrum of the '
        'latest analysed block (rfi_monitor/spectrum_view.py).', minimum=0.01, maximum=1000.0)
    spectrum_rows: int = parameter(
        300, 'Rows of the waterfall image (history shown: rows / spectrum_rate_hz s); newest row at the top.',
        minimum=1, maximum=10000)
    spectrum_min_dbfs: float = parameter(
        -80.0, 'Waterfall power per bin shown black (pixel 0), dB relative to the square of the quantiser range '
        '(2^(bits-1) counts x scale). A fixed scale: set it about 10 dB below the noise per bin of your front '
        'end.', minimum=-400.0, maximum=400.0)
    spectrum_max_dbfs: float = parameter(
        0.0, 'Waterfall power per bin shown white (pixel 255), dB relative to the square of the quantiser range; '
        'above spectrum_min_dbfs.', minimum=-400.0, maximum=400.0)
    spectrum_frame_id: str = parameter(
        'rfi_spectrum', 'Name at the start of the waterfall header.frame_id; the frequency axis (Hz relative to the '
        'RF centre) and the dB scale follow it: "<name>;f_hz=<lo>:<hi>;dbfs=<min>:<max>".')

    def __post_init__(self) -> None:
        if not self.spectrum_max_dbfs > self.spectrum_min_dbfs:
            raise ValueError(f'spectrum_max_dbfs {self.spectrum_max_dbfs} must be above spectrum_min_dbfs '
                             f'{self.spectrum_min_dbfs}')
        if FRAME_SEPARATOR in self.spectrum_frame_id:
            raise ValueError(f'spectrum_frame_id must not contain {FRAME_SEPARATOR!r}')


def quantiser_range(bits: int, scale: float) -> float:
    """The reference of the dBFS scale: ``2**(bits - 1) * scale``, V (the quantiser's range in volts)."""
    return float(2 ** (int(bits) - 1) * scale)


def frequency_axis_hz(n_bins: int, sample_rate_hz: float, intermediate_frequency_hz: float, cplx: bool
                      ) -> np.ndarray:
    """Frequency of each Welch bin (``classifier.welch_psd`` order) relative to the RF centre, Hz, shape (n_bins,).

    Real input: n_bins = nfft // 2 + 1 bins at k fs / nfft; complex: nfft bins at (k - nfft / 2) fs / nfft; both
    then as ``estimate.relative_frequency_hz`` (a negative real IF is spectrally inverted).
    """
    k = np.arange(n_bins, dtype=np.float64)
    f_dig = k / (2.0 * (n_bins - 1)) if not cplx else (k - n_bins // 2) / n_bins
    return np.asarray(relative_frequency_hz(f_dig, sample_rate_hz, intermediate_frequency_hz, cplx),  # type: ignore[arg-type]
                      dtype=np.float64)


def db_row(psd: np.ndarray, reference: float, min_db: float, max_db: float) -> np.ndarray:
    """A spectrum as a mono8 row: ``10 log10(psd / reference**2)`` mapped linearly from min_db (0) to max_db (255),
    clipped; bins of power 0 (or NaN) are 0. Shape (n,), uint8."""
    with np.errstate(divide='ignore', invalid='ignore'):
        db = 10.0 * np.log10(np.asarray(psd, dtype=np.float64) / (reference * reference))
    level = np.round((db - min_db) * (255.0 / (max_db - min_db)))
    return np.clip(np.nan_to_num(level, nan=0.0, neginf=0.0, posinf=255.0), 0.0, 255.0).astype(np.uint8)


def axis_frame_id(name: str, f_lo_hz: float, f_hi_hz: float, min_db: float, max_db: float) -> str:
    """``header.frame_id`` of the waterfall: ``"<name>;f_hz=<lo>:<hi>;dbfs=<min>:<max>"`` (module docstring)."""
    return f'{name};f_hz={f_lo_hz:.6g}:{f_hi_hz:.6g};dbfs={min_db:g}:{max_db:g}'


def parse_axis_frame_id(frame_id: str) -> tuple[str, float, float, float, float]:
    """Inverse of :func:`axis_frame_id`: (name, f_lo_hz, f_hi_hz, min_dbfs, max_dbfs).

    Raises:
        ValueError: not a frame id of that form.
    """
    parts = frame_id.split(FRAME_SEPARATOR)
    fields = dict(p.split('=', 1) for p in parts[1:] if '=' in p)
    if len(parts) != 3 or set(fields) != {'f_hz', 'dbfs'}:
        raise ValueError(f'not a waterfall frame id: {frame_id!r}')
    f_lo, f_hi = (float(v) for v in fields['f_hz'].split(':'))
    d_lo, d_hi = (float(v) for v in fields['dbfs'].split(':'))
    return parts[0], f_lo, f_hi, d_lo, d_hi


class Waterfall:
    """A rolling waterfall of spectra (module docstring).

    Args:
        rows: rows of the image (>= 1).
        min_dbfs, max_dbfs: the fixed display scale, dB (min < max).
    """

    def __init__(self, rows: int, min_dbfs: float, max_dbfs: float) -> None:
        if rows < 1 or not max_dbfs > min_dbfs:
            raise ValueError(f'waterfall needs rows >= 1 and max_dbfs > min_dbfs (got {rows}, {min_dbfs}, {max_dbfs})')
        self.rows = int(rows)
        self.min_dbfs = float(min_dbfs)
        self.max_dbfs = float(max_dbfs)
        self._ring = np.zeros((self.rows, 0), dtype=np.uint8)
        self._band = np.full((self.rows, 2), np.nan)
        self._head = -1                      # ring row of the newest spectrum
        self._axis: tuple[int, float, float, bool] | None = None
        self._order = np.zeros(0, dtype=np.int64)
        self.f_lo_hz = math.nan
        self.f_hi_hz = math.nan
        self.stamp_ns: int | None = None
        """Stamp of the newest row's block, ns (None: no row yet)."""

    @property
    def width(self) -> int:
        return int(self._ring.shape[1])

    def clear(self) -> None:
        """Forget every row (the axis is kept until the next spectrum)."""
        self._ring[:] = 0
        self._band[:] = np.nan
        self._head = -1
        self.stamp_ns = None

    def add(self, spectrum: BlockSpectrum, full_scale: float, band_hz: tuple[float, float]) -> bool:
        """Add a row: the spectrum (power per bin, sample units^2) in dB relative to ``full_scale**2`` (the
        quantiser's range, :func:`quantiser_range`), and the swept band ``(start_hz, bandwidth_hz)`` relative to the
        RF centre (NaN: none). A spectrum on another axis (bins, rate, IF, complexness) restarts the image.
        Returns False (nothing added) for a spectrum without bins or a full scale that is not positive and finite."""
        n = int(spectrum.psd.size)
        if n < 2 or not (math.isfinite(full_scale) and full_scale > 0):
            return False
        axis = (n, float(spectrum.sample_rate_hz), float(spectrum.intermediate_frequency_hz), bool(spectrum.cplx))
        if axis != self._axis:
            f = frequency_axis_hz(n, *axis[1:])
            self._order = np.argsort(f, kind='stable')
            self.f_lo_hz, self.f_hi_hz = float(f[self._order[0]]), float(f[self._order[-1]])
            self._ring = np.zeros((self.rows, n), dtype=np.uint8)
            self._axis = axis
            self.clear()
        self._head = (self._head + 1) % self.rows
        self._ring[self._head] = db_row(spectrum.psd[self._order], full_scale, self.min_dbfs, self.max_dbfs)
        start, bw = band_hz
        self._band[self._head] = ((start, start + bw) if math.isfinite(start) and math.isfinite(bw) and bw > 0
                                  else (math.nan, math.nan))
        self.stamp_ns = int(spectrum.stamp_ns)
        return True

    def image(self) -> np.ndarray:
        """The waterfall, newest row first: shape (rows, width), uint8 (a new array)."""
        if self._head < 0:
            return np.zeros_like(self._ring)
        idx = (self._head - np.arange(self.rows)) % self.rows
        return self._ring[idx]

    def column_of(self, f_hz: np.ndarray) -> np.ndarray:
        """Frequencies relative to the RF centre as fractional columns (column centres at integers)."""
        span = self.f_hi_hz - self.f_lo_hz
        return (np.asarray(f_hz, dtype=np.float64) - self.f_lo_hz) * ((self.width - 1) / span)

    def band_columns(self) -> np.ndarray:
        """The swept band of each row (newest first) in fractional columns, clipped to the image: shape (rows, 2)
        [low, high], NaN where the row's block reported no band."""
        if self._head < 0 or self.width < 2:
            return np.full((self.rows, 2), np.nan)
        idx = (self._head - np.arange(self.rows)) % self.rows
        cols = self.column_of(self._band[idx])
        return np.clip(cols, -0.5, self.width - 0.5)

    def frame_id(self, name: str) -> str:
        """``header.frame_id`` for the current axis (:func:`axis_frame_id`)."""
        return axis_frame_id(name, self.f_lo_hz, self.f_hi_hz, self.min_dbfs, self.max_dbfs)
