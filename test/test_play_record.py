"""`play` and `record` as users run them: across two processes over real DDS, and bad input."""

from __future__ import annotations

import os
import signal
import subprocess

import pytest
from ament_index_python.packages import get_package_prefix
from sample_bag import write_sample_bag

from rfi_experiments.bag_io import BagReader
from rfi_node_common import testing


def tool(name: str) -> str:
    return os.path.join(get_package_prefix('rfi_experiments'), 'lib', 'rfi_experiments', name)


@pytest.fixture(scope='module')
def sample_bag(tmp_path_factory):
    path = tmp_path_factory.mktemp('bags') / 'sample'
    return path, write_sample_bag(path, seconds=1.0)


@pytest.mark.parametrize('pace', [['--max'], ['--rate', '2.0']], ids=['max', 'rate2'])
def test_play_into_record_across_processes_is_complete_in_order_and_identical(sample_bag, tmp_path, pace):
    path, counts = sample_bag
    total = sum(counts.values())
    with BagReader(path) as reader:
        types = {t: info[0] for t, info in reader.topics.items()}
        expected = {t: [m.raw for m in reader.messages([t])] for t in types}
    out = tmp_path / 'recorded'
    recorder = subprocess.Popen(
        [tool('record'), str(out), '--topics', *types, '--max-messages', str(total), '--duration', '60',
         *[f'--type={t}={m}' for t, m in types.items()]],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    # bounded by progress (the CPU of play and of the recorder it feeds), not by a fixed time; the recorder ends
    # itself at its --max-messages, or at its --duration 60 s if a message were lost: a stall bound beyond that
    try:
        player = testing.run_process([tool('play'), str(path), *pace, '--wait-subscribers', '20', '--no-progress'],
                                     'play into record did not end', also=(recorder.pid,), text=True)
        rec_out, rec_err = testing.communicate(recorder, 'record did not end', stall_s=90.0,
                                               stop_signal=signal.SIGINT)
    finally:
        if recorder.poll() is None:
            recorder.kill()
            recorder.communicate()
    assert player.returncode == 0, player.stderr
    assert recorder.returncode == 0, rec_err
    for topic, n in counts.items():
        assert f'{topic}' in player.stdout and str(n) in player.stdout
    with BagReader(out) as reader:
        got = {t: [m.raw for m in reader.messages([t])] for t in reader.topics}
    # per topic: complete, in order, byte-identical (across topics, DDS gives no global order) up to the zero padding
    # that the middleware adds to a serialized message whose length is not a multiple of 4 (rclpy's serialisation,
    # which wrote the sample bag, adds none: a CorrelatorArray ends with a uint8 since Correlator.carrier_lock)
    assert got.keys() == expected.keys()
    for topic, sent in expected.items():
        assert len(got[topic]) == len(sent), topic
        for g, e in zip(got[topic], sent, strict=True):
            assert g[:len(e)] == e and len(g) == len(e) + (-len(e)) % 4 and not any(g[len(e):]), topic


def run_play(*args):
    return testing.run_process([tool('play'), *args, '--no-progress'], text=True)


def assert_one_line_error(done, *words):
    assert done.returncode == 2
    assert 'Traceback' not in done.stderr
    lines = [line for line in done.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, done.stderr
    for word in words:
        assert word in lines[0]


def test_play_missing_bag(tmp_path):
    assert_one_line_error(run_play(str(tmp_path / 'nope')), 'no such bag')


def test_play_corrupt_bag(tmp_path, sample_bag):
    path, _ = sample_bag
    broken = tmp_path / 'broken'
    broken.mkdir()
    (broken / 'metadata.yaml').write_text((path / 'metadata.yaml').read_text())
    mcap = next(path.glob('*.mcap'))
    (broken / mcap.name).write_bytes(mcap.read_bytes()[:200])
    done = run_play(str(broken), '--max')
    assert_one_line_error(done, 'broken')


def test_play_not_a_bag(tmp_path):
    (tmp_path / 'junk').mkdir()
    (tmp_path / 'junk' / 'metadata.yaml').write_text('not: [a bag')
    assert_one_line_error(run_play(str(tmp_path / 'junk')), 'not a readable bag')


def test_play_topic_filter_matching_nothing(sample_bag):
    path, _ = sample_bag
    assert_one_line_error(run_play(str(path), '--topics', '/no/such/topic'), 'matches nothing', '/no/such/topic')


def test_play_unknown_message_type(tmp_path):
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    store.register(get_types_from_msg('float64 x', 'other_pkg/msg/Thing'))
    path = tmp_path / 'foreign'
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection('/thing', 'other_pkg/msg/Thing', typestore=store)
        msg = store.types['other_pkg/msg/Thing'](x=1.0)
        writer.write(conn, 1, store.serialize_cdr(msg, 'other_pkg/msg/Thing'))
    assert_one_line_error(run_play(str(path)), 'unknown message type', 'other_pkg/msg/Thing')


def test_play_bad_rate(sample_bag):
    path, _ = sample_bag
    assert_one_line_error(run_play(str(path), '--rate', '0'), '--rate')
