"""One implementation of each computation, in the lowest package that needs it (issue 28, item 4).

Checked here where a name makes the rule checkable: the Earth's rotation during a signal's flight
(the Sagnac correction) lives in ``gnss_common`` (``earth_rotation.py``; inside gnss_common the
per-system rates of the broadcast ephemerides, the compiled mirror in ``multi_gnss_rows.py`` and the
test oracle's reverse rotation in ``synthetic_sky.py`` use the rate too), so no package above it uses
the Earth rotation rate itself. The CDR byte layouts live in
``rfi_node_common/cdr.py`` alone: no other module reads or writes the encapsulation header.
"""

from __future__ import annotations

import re
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / 'src'
EARTH_ROTATION = re.compile(r'\b\w*EARTH_ROTATION_RATE\w*\b')
CDR_HEADER = re.compile(r"""\\x00\\x01\\x00\\x00|b["']\\x00\\x01["']""")


def _modules():
    for path in sorted(SRC.glob('*/*/**/*.py')):
        if '/test/' not in path.as_posix():
            yield path


def test_only_gnss_common_uses_the_earth_rotation_rate():
    users = sorted(str(p.relative_to(SRC)) for p in _modules()
                   if not p.is_relative_to(SRC / 'gnss_common') and EARTH_ROTATION.search(p.read_text()))
    assert not users, ('modules above gnss_common that rotate the Earth themselves (use '
                       f'gnss_common.earth_rotation: sagnac_rotate, flight_rotation): {users}')


def test_only_the_codec_knows_the_cdr_encapsulation():
    users = sorted(str(p.relative_to(SRC)) for p in _modules()
                   if p != SRC / 'rfi_node_common' / 'rfi_node_common' / 'cdr.py' and CDR_HEADER.search(p.read_text()))
    assert not users, f'modules that read or write CDR bytes themselves (use rfi_node_common.cdr): {users}'


def test_the_patterns_match_what_they_look_for():
    assert EARTH_ROTATION.search('ang = EARTH_ROTATION_RATE_RADPS * tau')
    assert EARTH_ROTATION.search('w = GLONASS_EARTH_ROTATION_RATE_RADPS')
    assert not EARTH_ROTATION.search('from gnss_common.earth_rotation import flight_rotation')
    assert CDR_HEADER.search(r'CDR_LE = b"\x00\x01"') and CDR_HEADER.search(r'ENCAPSULATION = b"\x00\x01\x00\x00"')
