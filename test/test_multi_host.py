"""Several hosts, one suite (issue 11, item 6): the nodes on one host, the replay on another.

Two network namespaces joined by a veth pair stand in for two hosts on a LAN: "nodes"
(10.200.0.1/24) runs rfi_monitor, uwb_gnss_fusion and imm_carrier as separate processes, "replay"
(10.200.0.2/24) runs `run --transport processes --external-nodes` (play feeding the bag's window,
and the recorder). Each namespace has only its loopback and its end of the link, so everything
between the two sides crosses the link: Fast DDS with its shared memory transport off
(FASTDDS_BUILTIN_TRANSPORTS=UDPv4; the two sides share /dev/shm here, unlike two hosts) and
discovery by multicast over the link (ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET, one multicast route on
the link). The outputs must equal those of the direct transport (the suite in one process, no
middleware), as in test_run_processes.py, with no message lost: every input published to a matched
subscriber, acknowledged, and counted by its node.

Needs root and `ip netns` (CI runs as root); skipped with the reason otherwise. Namespace and link
names are unique per run; the finaliser stops the node processes and deletes both namespaces
(which removes the link) whatever happened.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import uuid

import pytest
from test_run_processes import BAG, PARAMS, WINDOW, assert_outputs_equal, outputs

from rfi_node_common import testing

pytestmark = pytest.mark.usefixtures('warm_kernels')   # the nodes load their kernels from the cache (conftest.py)

NODES_ADDRESS = '10.200.0.1/24'
REPLAY_ADDRESS = '10.200.0.2/24'
INPUTS = {'rfi_monitor': ('/rfi/if_samples',),
          'gnss_integrity': ('/gnss/measurements', '/uwb/ranges', '/gnss/receiver_interference',
                             '/gnss/receiver_spectrum', '/rfi/jammer_state'),
          'uwb_gnss_fusion': ('/gnss/measurements', '/uwb/ranges', '/rfi/jammer_state', '/gnss/integrity'),
          'imm_carrier': ('/gnss/correlators',)}
EXECUTABLES = {'rfi_monitor': ('rfi_monitor', 'rfi_monitor_node'),
               'gnss_integrity': ('gnss_integrity', 'gnss_integrity_node'),
               'uwb_gnss_fusion': ('uwb_gnss_fusion', 'fusion_node'),
               'imm_carrier': ('imm_carrier', 'imm_carrier_node')}


def ip(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(['ip', *args], capture_output=True, text=True, timeout=30)


def network_env() -> dict[str, str]:
    """The environment of every process on either "host": DDS over UDP only, discovery on the subnet."""
    env = dict(os.environ)
    env.update(ROS_AUTOMATIC_DISCOVERY_RANGE='SUBNET', FASTDDS_BUILTIN_TRANSPORTS='UDPv4',
               ROS_DOMAIN_ID=env.get('ROS_DOMAIN_ID', '0'))
    env.pop('ROS_STATIC_PEERS', None)
    env.pop('ROS_DISCOVERY_SERVER', None)
    env.pop('FASTRTPS_DEFAULT_PROFILES_FILE', None)
    return env


class Hosts:
    """Two network namespaces joined by a veth pair; ``close()`` deletes them."""

    def __init__(self) -> None:
        tag = uuid.uuid4().hex[:8]
        self.nodes, self.replay = f'rfin{tag}', f'rfir{tag}'
        self.links = {self.nodes: f'rfvn{tag}', self.replay: f'rfvr{tag}'}  # <= 15 characters
        self.created: list[str] = []

    def up(self) -> str | None:
        """Create both namespaces and the link; return why not (None: done)."""
        for ns in (self.nodes, self.replay):
            done = ip('netns', 'add', ns)
            if done.returncode != 0:
                return f'ip netns add failed: {done.stderr.strip()}'
            self.created.append(ns)
        steps = [('link', 'add', self.links[self.nodes], 'type', 'veth', 'peer', 'name', self.links[self.replay])]
        steps += [('link', 'set', self.links[ns], 'netns', ns) for ns in (self.nodes, self.replay)]
        for ns, address in ((self.nodes, NODES_ADDRESS), (self.replay, REPLAY_ADDRESS)):
            link = self.links[ns]
            steps += [('-n', ns, 'addr', 'add', address, 'dev', link), ('-n', ns, 'link', 'set', link, 'up'),
                      ('-n', ns, 'link', 'set', 'lo', 'up'),
                      # multicast (DDS discovery) leaves through the link, as on a LAN
                      ('-n', ns, 'route', 'add', '224.0.0.0/4', 'dev', link)]
        for step in steps:
            done = ip(*step)
            if done.returncode != 0:
                return f'ip {" ".join(step)} failed: {done.stderr.strip()}'
        return None

    def link_bytes(self, ns: str) -> int:
        """Bytes received on ``ns``'s end of the link."""
        done = ip('-n', ns, '-s', '-j', 'link', 'show', self.links[ns])
        return int(json.loads(done.stdout)[0]['stats64']['rx']['bytes'])

    def close(self) -> None:
        for ns in self.created:
            ip('netns', 'del', ns)  # also removes its end of the link, and so the pair
        if ip('link', 'show', self.links[self.nodes]).returncode == 0:  # a link that never moved
            ip('link', 'del', self.links[self.nodes])


def node_command(name: str) -> list[str]:
    from ament_index_python.packages import get_package_prefix

    package, exe = EXECUTABLES[name]
    command = [os.path.join(get_package_prefix(package), 'lib', package, exe), '--ros-args',
               '--params-file', str(PARAMS)]
    if name == 'imm_carrier':
        command += ['-p', 'method:=both']  # what run gives it
    for topic in INPUTS[name]:  # reliable inputs: play waits for them instead of losing messages
        command += ['-p', f'qos_overrides.{topic}.subscription.reliability:=reliable']
    return command


@pytest.fixture(scope='module')
def hosts():
    if os.geteuid() != 0:
        pytest.skip('needs root to create network namespaces (ip netns); CI runs this as root')
    if shutil.which('ip') is None:
        pytest.skip('no `ip` command (iproute2) to create network namespaces')
    pair = Hosts()
    try:
        why = pair.up()
        if why is not None:
            pytest.skip(f'cannot create two network namespaces joined by a veth pair here: {why}')
        yield pair
    finally:
        pair.close()


@pytest.fixture(scope='module')
def runs(hosts, tmp_path_factory):
    tmp = tmp_path_factory.mktemp('multi_host')
    env = network_env()
    logs = tmp / 'nodes'
    logs.mkdir()
    nodes: dict[str, subprocess.Popen] = {}
    try:
        for name in EXECUTABLES:
            with open(logs / f'{name}.log', 'w') as log:
                nodes[name] = subprocess.Popen(['ip', 'netns', 'exec', hosts.nodes, *node_command(name)],
                                               stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT, env=env)
        # while the nodes start (imports, numba caches): the reference, the suite in one process with
        # no middleware (it reads the same install tree, so its outputs do not depend on this overlap)
        # (both runs bounded by progress, the CPU they spend, not by a fixed 150 s: testing.communicate)
        direct = testing.run_process(
            [sys.executable, '-m', 'rfi_experiments.run', str(BAG), '--out', str(tmp / 'direct'), '--params-file',
             str(PARAMS), '--transport', 'direct', *WINDOW, '--no-progress', '--no-report', '--record-outputs',
             str(tmp / 'direct' / 'outputs')], 'the direct replay did not end', text=True)
        assert direct.returncode == 0, direct.stderr
        before = hosts.link_bytes(hosts.nodes)
        proc = subprocess.Popen(
            ['ip', 'netns', 'exec', hosts.replay, sys.executable, '-m', 'rfi_experiments.run', str(BAG),
             '--out', str(tmp / 'replay'), '--transport', 'processes', '--external-nodes', *WINDOW, '--no-progress',
             '--no-report', '--timeout', '90', '--record-outputs', str(tmp / 'replay' / 'outputs')],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
        # on a stall SIGINT: run stops play before it exits
        out, err = testing.communicate(proc, 'the replay across the link did not end', stop_signal=signal.SIGINT)
        replay = subprocess.CompletedProcess(proc.args, proc.returncode, out, err)
        carried = hosts.link_bytes(hosts.nodes) - before
        alive = {name: proc.poll() is None for name, proc in nodes.items()}
    finally:
        for proc in nodes.values():
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
        for proc in nodes.values():
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
    node_logs = '\n'.join(f'--- {n}\n' + (logs / f'{n}.log').read_text()[-1500:] for n in EXECUTABLES)
    assert replay.returncode == 0, replay.stderr + node_logs
    assert all(alive.values()), (alive, node_logs)
    return tmp, replay, carried


def test_outputs_across_the_link_equal_the_direct_replay(runs):
    tmp, _, _ = runs
    got = {t: v for t, v in outputs(tmp / 'replay' / 'outputs').items() if not t.endswith(' STALE')}
    # field for field but for the fusion's counters of arrivals, which are bounded: see test_run_processes.ARRIVAL_TIMED
    assert_outputs_equal(got, outputs(tmp / 'direct' / 'outputs'))


def test_no_message_lost_and_everything_crossed_the_link(runs):
    tmp, replay, carried = runs
    play = (tmp / 'replay' / 'logs' / 'play.log').read_text()
    rows = {line.split()[0]: line.split()[2:] for line in play.splitlines() if line.startswith('/')}
    assert set(rows) == {'/gnss/correlators', '/gnss/measurements', '/rfi/if_samples', '/uwb/ranges'}
    for topic, (published, subscribers, to_nobody) in rows.items():
        expected_subscribers = '2' if topic in ('/gnss/measurements', '/uwb/ranges') else '1'  # + gnss_integrity
        assert int(published) > 0 and (subscribers, to_nobody) == (expected_subscribers, '0'), (topic, play)
    assert 'not acknowledged' not in replay.stderr and 'warning' not in replay.stdout
    got = outputs(tmp / 'replay' / 'outputs')
    for name in EXECUTABLES:  # no node counted an input message lost
        _, status = got[f'/diagnostics[{name}]'][-1]
        lost = {kv[0][1]: kv[1][1] for kv in dict(status)['values'] if kv[0][1].endswith(('.lost', '.middleware_lost'))}
        assert lost and not any(int(v) for v in lost.values()), (name, lost)
    # every input reached the nodes' "host" through the link: it received more than their payload
    # (189 kB; 500 kB measured, with discovery and the recorder's acknowledgements)
    payload = sum(len(m.raw) for m in _window_messages(sorted(rows)))
    assert payload > 0 and carried > payload, (carried, payload)


def _window_messages(topics):
    from rfi_experiments.bag_io import BagReader

    with BagReader(BAG) as reader:
        start = reader.start_ns + round(float(WINDOW[1]) * 1e9)
        stop = start + round(float(WINDOW[3]) * 1e9)
        return list(reader.messages(topics, start_ns=start, stop_ns=stop))
