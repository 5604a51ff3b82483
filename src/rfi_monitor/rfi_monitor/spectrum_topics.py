"""The monitor's topics made to be drawn (issue 30): the spectrum waterfall and the swept band on it.

Thin ROS side of :mod:`rfi_monitor.spectrum_view` (the picture, pure):

* ``rfi/spectrum/waterfall`` (``sensor_msgs/Image``, mono8): the rolling waterfall; ``header.stamp`` the stamp of the
  block its top row shows, ``header.frame_id`` the frequency axis and the dB scale
  (``"rfi_spectrum;f_hz=<lo>:<hi>;dbfs=<min>:<max>"``, :func:`rfi_monitor.spectrum_view.axis_frame_id`);
* ``rfi/spectrum/swept_band`` (``visualization_msgs/ImageMarker``, LINE_LIST, same stamp): the edges of the jammer's
  swept band on each row that has one, in image pixels (x column, y row): Foxglove's Image panel draws it over the
  waterfall (select it as an annotation); the band's numbers are on /rfi/jammer_state (``sweep_start_frequency_hz``,
  ``sweep_bandwidth_hz``).

Cost: :meth:`SpectrumTopics.on_estimate` first asks both publishers for their subscription count and returns at once
when nobody listens: then no row is made and the waterfall is forgotten (a viewer that subscribes later starts with
an empty picture). While someone listens, a row is added and both topics published every ``1 / spectrum_rate_hz`` of
stamp time (never the wall clock: a replay gives the same pictures at any speed). The row is the spectrum the
analysis made (``RfiMonitor.last_spectrum``): nothing is analysed for the display. A failure here is counted
(``errors``) and logged by the node, never raised into the block's handling.
"""

from __future__ import annotations

import array
import math
from typing import Any

import numpy as np
from geometry_msgs.msg import Point
from sensor_msgs.msg import Image
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import ImageMarker

from rfi_monitor.estimate import JammerEstimate
from rfi_monitor.spectrum_view import Waterfall, quantiser_range
from rfi_node_common.diagnostics import StampTimer
from rfi_node_common.qos import VIEW_QOS
from rfi_node_common.stamps import NS_PER_S

WATERFALL_TOPIC = 'rfi/spectrum/waterfall'
"""The waterfall image (relative: moves with the node's namespace)."""
SWEPT_BAND_TOPIC = 'rfi/spectrum/swept_band'
"""The swept band drawn on it."""
TOPICS = ((WATERFALL_TOPIC, 'sensor_msgs/msg/Image'), (SWEPT_BAND_TOPIC, 'visualization_msgs/msg/ImageMarker'))
"""(topic, type) of every topic this module publishes (the viewer configurations are checked against it)."""
BAND_COLOR = (1.0, 0.2, 0.2, 1.0)
"""RGBA of the swept band's edges (red over the grey waterfall)."""


def _stamp(msg: Any, stamp_ns: int) -> None:
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(int(stamp_ns), NS_PER_S)


def band_segments(cols: np.ndarray) -> list[tuple[float, float, float, float]]:
    """The swept band's edges as vertical segments ``(x0, y0, x1, y1)`` in pixels: ``cols`` (rows, 2) the band's
    [low, high] columns per row (NaN: none), consecutive rows with the same edges (to a tenth of a column) merged."""
    segs: list[tuple[float, float, float, float]] = []
    start = 0
    rows = cols.shape[0]
    key = np.round(cols * 10.0)
    for r in range(1, rows + 1):
        if r < rows and (np.array_equal(key[r], key[start]) or (np.isnan(key[r]).all() and np.isnan(key[start]).all())):
            continue
        lo, hi = cols[start]
        if math.isfinite(lo) and math.isfinite(hi):
            y0, y1 = start - 0.5, r - 0.5
            segs.append((float(lo), y0, float(lo), y1))
            segs.append((float(hi), y0, float(hi), y1))
        start = r
    return segs


class SpectrumTopics:
    """The waterfall and swept-band publishers of one monitor node (module docstring).

    Args:
        node: the rclpy node that owns the publishers.
        params: anything with the fields of :class:`rfi_monitor.spectrum_view.WaterfallParams`.
    """

    def __init__(self, node: Any, params: Any) -> None:
        self.frame_name = str(params.spectrum_frame_id)
        self.waterfall = Waterfall(params.spectrum_rows, params.spectrum_min_dbfs, params.spectrum_max_dbfs)
        self._period_s = 1.0 / float(params.spectrum_rate_hz)
        self._timer = StampTimer(self._period_s)
        self.image_pub = node.create_publisher(Image, WATERFALL_TOPIC, VIEW_QOS)
        self.band_pub = node.create_publisher(ImageMarker, SWEPT_BAND_TOPIC, VIEW_QOS)
        self._logger = node.get_logger()
        self.active = False
        self.published = 0
        """Waterfall images published."""
        self.errors = 0
        """Updates that raised (counted by the node, never raised)."""

    def listened(self) -> bool:
        """Someone subscribes to either topic (the first thing asked for each block)."""
        return self.image_pub.get_subscription_count() > 0 or self.band_pub.get_subscription_count() > 0

    def on_estimate_logged(self, counts: Any, throttle_s: float, stamp_ns: int, est: JammerEstimate, spectrum: Any,
                           bits: int, scale: float) -> None:
        """:meth:`on_estimate`, a failure counted (``counts['spectrum_errors']``) and logged at most once per
        ``throttle_s``, never raised: a picture must never cost an estimate."""
        try:
            self.on_estimate(stamp_ns, est, spectrum, bits, scale)
        except Exception as err:  # noqa: BLE001 - a picture must never cost an estimate
            counts['spectrum_errors'] += 1
            self._logger.error(f'spectrum topics not published: {type(err).__name__}: {err}',
                               throttle_duration_sec=throttle_s)

    def on_estimate(self, stamp_ns: int, est: JammerEstimate, spectrum: Any, bits: int, scale: float) -> bool:
        """After a block's estimate: when someone listens and a row is due, add the latest spectrum (``spectrum``, a
        ``BlockSpectrum`` or None) with the estimate's swept band and publish both topics. Returns whether it
        published."""
        if not self.listened():
            if self.active:
                self.waterfall.clear()
                self._timer = StampTimer(self._period_s)
                self.active = False
            return False
        self.active = True
        if spectrum is None or not self._timer.due(stamp_ns):
            return False
        band = (float(est.sweep_start_frequency_hz), float(est.sweep_bandwidth_hz))
        if not self.waterfall.add(spectrum, quantiser_range(bits, scale), band):
            return False
        self.image_pub.publish(self.image_msg())
        self.band_pub.publish(self.band_msg())
        self.published += 1
        return True

    def image_msg(self) -> Image:
        """The waterfall as sensor_msgs/Image (mono8, newest row on top)."""
        w = self.waterfall
        img = w.image()
        msg = Image()
        _stamp(msg, w.stamp_ns or 0)
        msg.header.frame_id = w.frame_id(self.frame_name)
        msg.height, msg.width = int(img.shape[0]), int(img.shape[1])
        msg.encoding = 'mono8'
        msg.is_bigendian = 0
        msg.step = msg.width
        msg.data = array.array('B', img.tobytes())
        return msg

    def band_msg(self) -> ImageMarker:
        """The swept band's edges on the waterfall as visualization_msgs/ImageMarker (LINE_LIST, pixels)."""
        w = self.waterfall
        msg = ImageMarker()
        _stamp(msg, w.stamp_ns or 0)
        msg.header.frame_id = w.frame_id(self.frame_name)
        msg.ns = 'swept_band'
        msg.id = 0
        msg.type = ImageMarker.LINE_LIST
        msg.action = ImageMarker.ADD
        msg.scale = 1.0
        msg.outline_color = ColorRGBA(r=BAND_COLOR[0], g=BAND_COLOR[1], b=BAND_COLOR[2], a=BAND_COLOR[3])
        msg.points = [Point(x=x, y=y, z=0.0) for seg in band_segments(w.band_columns())
                      for x, y in ((seg[0], seg[1]), (seg[2], seg[3]))]
        return msg
