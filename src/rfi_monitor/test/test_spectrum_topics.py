"""The monitor's topics made to be drawn (issue 30): the waterfall picture (pure) and the node's topics, published
valid and only while subscribed (in-process: one Context per test, a SingleThreadedExecutor, bounded spins)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from sensor_msgs.msg import Image
from visualization_msgs.msg import ImageMarker

from rfi_monitor.estimate import BlockSpectrum
from rfi_monitor.rfi_monitor_node import TOPICS as NODE_TOPICS
from rfi_monitor.rfi_monitor_node import RfiMonitorNode
from rfi_monitor.spectrum_topics import SWEPT_BAND_TOPIC, TOPICS, WATERFALL_TOPIC, band_segments
from rfi_monitor.spectrum_view import (
    Waterfall,
    WaterfallParams,
    axis_frame_id,
    db_row,
    frequency_axis_hz,
    parse_axis_frame_id,
    quantiser_range,
)
from rfi_msgs.msg import IfSamples, JammerState
from rfi_node_common import testing
from rfi_node_common.qos import DATA_QOS
from rfi_node_common.stamps import ns_to_stamp
from rfi_node_common.testing import NodeRig
from rfi_sim.if_signal import ChirpJammer, CwJammer, FrontEndConfig, IfSimulator

START_NS = 1_700_000_000_000_000_000
L1_HZ = 1575.42e6
NAN2 = (math.nan, math.nan)


# ---------------------------------------------------------------------------------------------- pure
def test_frequency_axis_real_complex_and_inverted():
    fs, fif = 4.0e6, 1.0e6
    f = frequency_axis_hz(129, fs, fif, False)             # nfft 256, real: 0 .. fs/2 minus the IF
    assert f[0] == -fif and f[-1] == fs / 2 - fif and np.allclose(np.diff(f), fs / 256)
    f = frequency_axis_hz(256, fs, 0.25e6, True)           # complex, fftshift order: -fs/2 .. fs/2 - df
    assert f[0] == -fs / 2 - 0.25e6 and f[128] == -0.25e6 and np.allclose(np.diff(f), fs / 256)
    f = frequency_axis_hz(129, fs, -fif, False)            # negative IF: spectrally inverted, descending
    assert f[0] == fif and f[-1] == fif - fs / 2


def test_db_row_is_a_fixed_linear_scale():
    ref = 2.0
    psd = ref ** 2 * np.array([10 ** -9.0, 10 ** -4.0, 1.0, 10.0, 0.0, np.nan])
    row = db_row(psd, ref, -80.0, 0.0)
    # -90 dB clipped to black, -40 mid grey, 0 white, +10 clipped white, no power and NaN black
    assert row.tolist() == [0, 128, 255, 255, 0, 0] and row.dtype == np.uint8
    assert quantiser_range(2, 0.5) == 1.0 and quantiser_range(12, 1.0 / 2048) == 1.0


def test_waterfall_rolls_newest_first_and_restarts_on_a_new_axis():
    w = Waterfall(rows=3, min_dbfs=-80.0, max_dbfs=0.0)
    assert w.image().shape == (3, 0)
    for k, level in enumerate((1e-8, 1e-6, 1e-4, 1e-2)):
        assert w.add(BlockSpectrum(k, np.full(129, level), 4e6, 1e6, False), 1.0, NAN2)
    img = w.image()
    # 4 rows added to 3: the newest (-20 dB) on top, the oldest kept (-60 dB) at the bottom
    assert img.shape == (3, 129) and img[:, 0].tolist() == [191, 128, 64] and w.stamp_ns == 3
    assert w.add(BlockSpectrum(4, np.full(256, 1e-2), 4e6, 0.0, True), 1.0, NAN2)   # complex: another axis
    img = w.image()
    assert img.shape == (3, 256) and img[0, 0] == 191 and not img[1:].any()
    assert (w.f_lo_hz, w.f_hi_hz) == (-2e6, 2e6 - 4e6 / 256)
    assert not w.add(BlockSpectrum(5, np.full(256, 1e-2), 4e6, 0.0, True), 0.0, NAN2)   # no full scale: nothing


def test_inverted_axis_is_flipped_so_that_columns_ascend():
    w = Waterfall(rows=1, min_dbfs=-80.0, max_dbfs=0.0)
    psd = np.full(129, 1e-8)
    psd[10] = 1.0                                           # digital 10 / 256 cycles: with IF -1 MHz, +843750 Hz
    w.add(BlockSpectrum(0, psd, 4e6, -1e6, False), 1.0, NAN2)
    col = int(np.argmax(w.image()[0]))
    f_col = w.f_lo_hz + col * (w.f_hi_hz - w.f_lo_hz) / (w.width - 1)
    assert (w.f_lo_hz, w.f_hi_hz) == (-1e6, 1e6) and f_col == pytest.approx(1e6 - 10 * 4e6 / 256)


def test_swept_band_in_columns_and_segments():
    w = Waterfall(rows=4, min_dbfs=-80.0, max_dbfs=0.0)
    spec = BlockSpectrum(0, np.full(129, 1e-4), 4e6, 1e6, False)   # -1 MHz .. +1 MHz, 129 columns
    w.add(spec, 1.0, NAN2)
    w.add(spec, 1.0, (-0.5e6, 1.0e6))
    w.add(spec, 1.0, (-0.5e6, 1.0e6))
    cols = w.band_columns()
    assert np.isnan(cols[3]).all() and np.isnan(cols[2]).all()       # the two oldest rows: no band, never filled
    assert cols[0] == pytest.approx([32.0, 96.0]) and cols[1] == pytest.approx([32.0, 96.0])
    # rows 0 and 1 share their edges: one segment per edge, from the top of row 0 to the bottom of row 1
    assert band_segments(cols) == [(32.0, -0.5, 32.0, 1.5), (96.0, -0.5, 96.0, 1.5)]


def test_axis_frame_id_round_trip_and_parameter_checks():
    fid = axis_frame_id('rfi_spectrum', -9.548e6, 9.548e6, -80.0, 0.0)
    assert parse_axis_frame_id(fid) == ('rfi_spectrum', -9.548e6, 9.548e6, -80.0, 0.0)
    with pytest.raises(ValueError):
        parse_axis_frame_id('map')
    with pytest.raises(ValueError, match='spectrum_max_dbfs'):
        WaterfallParams(spectrum_min_dbfs=0.0, spectrum_max_dbfs=-10.0)
    with pytest.raises(ValueError, match='spectrum_frame_id'):
        WaterfallParams(spectrum_frame_id='a;b')


def test_the_node_help_names_every_topic_it_draws():
    for topic, type_name in TOPICS:
        assert f'/{topic} ({type_name.replace("/msg/", "/")})' in NODE_TOPICS


# ---------------------------------------------------------------------------------------------- node
class Rig(NodeRig):
    """The monitor with a publisher of IF blocks; the drawn topics collected only if ``drawn``."""

    def __init__(self, drawn: bool, **params) -> None:
        outputs: dict = {'/rfi/jammer_state': JammerState}
        if drawn:
            outputs.update({'/' + WATERFALL_TOPIC: Image, '/' + SWEPT_BAND_TOPIC: ImageMarker})
        base = {'max_cpu_load': 0.0, 'input_timeout_s': 0.0, 'noise_bandwidth_hz': 2.0e6, **params}
        super().__init__(lambda context, ov: RfiMonitorNode(context=context, parameter_overrides=ov),
                         inputs={'/rfi/if_samples': (IfSamples, DATA_QOS)}, outputs=outputs, params=base,
                         name='spectrum_topics_test_io')
        self.sent = 0

    def send(self, msg: IfSamples) -> None:
        self.pubs['/rfi/if_samples'].publish(msg)
        self.sent += 1
        self.settle_until(lambda: self.node.counts['blocks_received'] == self.sent)


@pytest.fixture
def rig_factory():
    with testing.rig_factory(Rig) as make:
        yield make


def blocks(jammer, n: int, seed: int, block_s: float = 1e-3) -> list[IfSamples]:
    fe = FrontEndConfig(noise_bandwidth_hz=2.0e6)          # real, 38.192 MS/s, IF 9.548 MHz, 2 bits
    sim = IfSimulator(fe, (jammer,) if jammer is not None else (), seed=seed)
    size = round(block_s * fe.sample_rate_hz)
    out = []
    for k in range(n):
        blk = sim.generate(size)
        m = IfSamples(sample_rate_hz=blk.sample_rate_hz, intermediate_frequency_hz=blk.intermediate_frequency_hz,
                      center_frequency_hz=L1_HZ, is_complex=blk.is_complex, first_sample_index=k * size,
                      scale=float(blk.scale), bits_per_sample=blk.bits, sample_format=IfSamples.INT8)
        m.header.stamp = ns_to_stamp(START_NS + round(k * block_s * 1e9))
        m.header.frame_id = 'spectrum_test_front_end'
        m.samples = blk.counts.astype('<i1').tobytes()
        out.append(m)
    return out


def test_nothing_is_drawn_while_nobody_subscribes(rig_factory, monkeypatch):
    rig = rig_factory(drawn=False, spectrum_rate_hz=1000.0)
    calls = []
    monkeypatch.setattr(rig.node.spectrum.waterfall, 'add', lambda *a: calls.append(a) or True)
    for m in blocks(CwJammer(frequency_hz=-1.3e6, js_db=40.0), 4, seed=5):
        rig.send(m)
    assert len(rig.out['/rfi/jammer_state']) == 4              # the estimates are published ...
    assert calls == [] and rig.node.spectrum.published == 0    # ... and no row was even made
    assert not rig.node.spectrum.active and rig.node.counts['spectrum_errors'] == 0


def test_waterfall_shows_a_cw_where_the_monitor_found_it(rig_factory):
    f_hz = -1.3e6
    rig = rig_factory(drawn=True, spectrum_rate_hz=1000.0, spectrum_rows=8)   # a row per 1 ms block
    msgs = blocks(CwJammer(frequency_hz=f_hz, js_db=40.0), 6, seed=5)
    for m in msgs:
        rig.send(m)
    images = rig.out['/' + WATERFALL_TOPIC]
    bands = rig.out['/' + SWEPT_BAND_TOPIC]
    assert len(images) == len(bands) == len(msgs) == rig.node.spectrum.published
    img = images[-1]
    assert (img.height, img.width, img.encoding, img.step, img.is_bigendian) == (8, 129, 'mono8', 129, 0)
    assert len(img.data) == img.height * img.width and img.header.stamp == msgs[-1].header.stamp
    name, f_lo, f_hi, d_lo, d_hi = parse_axis_frame_id(img.header.frame_id)
    assert (name, d_lo, d_hi) == ('rfi_spectrum', -80.0, 0.0)
    assert f_lo == pytest.approx(-9.548e6) and f_hi == pytest.approx(19.096e6 - 9.548e6)
    pix = np.frombuffer(bytes(img.data), dtype=np.uint8).reshape(8, 129)
    assert not pix[len(msgs):].any() and pix[:len(msgs)].any()   # rows not yet filled are black
    col = int(np.argmax(pix[0]))
    f_col = f_lo + col * (f_hi - f_lo) / (img.width - 1)
    state = rig.out['/rfi/jammer_state'][-1]
    assert state.type == JammerState.CW
    assert abs(f_col - f_hz) <= 19.096e6 / 256 and abs(f_col - state.frequency_hz) <= 19.096e6 / 256
    assert bands[-1].type == ImageMarker.LINE_LIST and bands[-1].points == []   # a CW sweeps no band


def test_swept_band_follows_the_chirp(rig_factory):
    jammer = ChirpJammer(js_db=40.0)
    rig = rig_factory(drawn=True, spectrum_rate_hz=1000.0, spectrum_rows=16)
    msgs = blocks(None, 5, seed=3) + blocks(jammer, 8, seed=4)
    for m in msgs:
        rig.send(m)
    states = rig.out['/rfi/jammer_state']
    chirps = [s for s in states[-8:] if s.type == JammerState.CHIRP and math.isfinite(s.sweep_bandwidth_hz)]
    assert chirps, [s.type for s in states]
    band = rig.out['/' + SWEPT_BAND_TOPIC][-1]
    img = rig.out['/' + WATERFALL_TOPIC][-1]
    _, f_lo, f_hi, _, _ = parse_axis_frame_id(band.header.frame_id)
    assert band.header.stamp == img.header.stamp and len(band.points) % 2 == 0 and band.points
    xs = sorted({round(p.x, 3) for p in band.points})
    s = states[-1]
    expect = [(f - f_lo) * (img.width - 1) / (f_hi - f_lo)
              for f in (s.sweep_start_frequency_hz, s.sweep_start_frequency_hz + s.sweep_bandwidth_hz)]
    # the top row's edges are the last state's band; every point lies on the image
    top = sorted(p.x for p in band.points if p.y == -0.5)
    assert top == pytest.approx(sorted(np.clip(expect, -0.5, img.width - 0.5)), abs=1e-6)
    assert all(-0.5 <= x <= img.width - 0.5 for x in xs)
    assert all(-0.5 <= p.y <= img.height - 0.5 for p in band.points)
