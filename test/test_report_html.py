"""The demo report as a web page: ``report/index.html`` holds what ``index.md`` holds, and a real
headless browser shows every figure of it, on a desktop and on a phone, with no error printed.

The report is the one ``make demo`` writes (``write_report``), on a 20 s window of bags/default
with outputs made from the bag's truth (the jammer state, and the truth position plus 5 cm as the
fusion's odometry), so that it has the jammer and positioning figures and their tables in seconds.
The browser tests need a Chromium-based browser on PATH (Debian: ``apt-get install chromium``;
``.ci/run`` installs it when it runs as root) and are skipped with that reason without one.
"""

from __future__ import annotations

import base64
import re
import struct
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from headless_browser import HeadlessBrowser, find_browser

from gnss_common.coordinates import ecef_to_enu_rotation, ecef_to_geodetic
from rfi_experiments.bag_io import BagReader
from rfi_experiments.play import window_ns
from rfi_experiments.report import write_report

ROOT = Path(__file__).resolve().parents[1]
BAG = ROOT / 'bags' / 'default'
WINDOW_S = (60.0, 80.0)
DESKTOP = {'width': 1280, 'height': 900}
PHONE = {'width': 390, 'height': 844, 'mobile': True}  # CSS pixels of a common phone in portrait

CHECK_PAGE = """(() => ({
  images: [...document.images].map(i => ({source: i.dataset.source || i.getAttribute('src').slice(0, 80),
                                          complete: i.complete, naturalWidth: i.naturalWidth,
                                          shownWidth: i.getBoundingClientRect().width})),
  tables: document.querySelectorAll('table').length,
  pageWidth: document.documentElement.scrollWidth,
  viewportWidth: window.innerWidth,
}))()"""
"""Evaluated in the loaded page: each image's load state and sizes, and whether the page is wider
than the screen (a horizontal scroll of the whole page)."""


class Html(HTMLParser):
    """The images, tables and headings of a page."""

    def __init__(self, text: str) -> None:
        super().__init__()
        self.images: list[dict[str, str | None]] = []
        self.tables: list[list[list[str]]] = []
        self.headings: list[str] = []
        self._text: list[str] | None = None
        self.feed(text)

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        if tag == 'img':
            self.images.append(dict(attrs))
        elif tag == 'table':
            self.tables.append([])
        elif tag == 'tr':
            self.tables[-1].append([])
        elif tag in ('td', 'th', 'h1', 'h2', 'h3'):
            self._text = []

    def handle_endtag(self, tag: str) -> None:
        if tag in ('td', 'th') and self._text is not None:
            self.tables[-1][-1].append(''.join(self._text).strip())
        elif tag in ('h1', 'h2', 'h3') and self._text is not None:
            self.headings.append(''.join(self._text).strip())
        self._text = None if tag in ('td', 'th', 'h1', 'h2', 'h3') else self._text

    def handle_data(self, data: str) -> None:
        if self._text is not None:
            self._text.append(data)


def markdown_plain(text: str) -> str:
    """Markdown inline text as the page shows it (the report's cells use code, bold and \\|)."""
    text = re.sub(r'\[([^\]]+)\]\([^)]+\)', r'\1', text)
    return text.replace('\\|', '|').replace('**', '').replace('`', '').strip()


def markdown_tables(markdown: str) -> list[list[list[str]]]:
    """The pipe tables of a Markdown text: rows of cell texts, the separator row left out."""
    tables: list[list[list[str]]] = []
    previous = ''
    for line in markdown.splitlines():
        if line.startswith('|'):
            if re.fullmatch(r'\|(\s*:?-+:?\s*\|)+', line.strip()):
                continue
            if not previous.startswith('|'):
                tables.append([])
            cells = re.split(r'(?<!\\)\|', line.strip()[1:-1])
            tables[-1].append([markdown_plain(c) for c in cells])
        previous = line
    return tables


def odometry_from_truth(start_ns: int, stop_ns: int) -> list:
    """The fusion's /fusion/odometry stand-in: the truth position of the window plus 5 cm east."""
    from nav_msgs.msg import Odometry

    with BagReader(BAG) as reader:
        truth = [m.decode() for m in reader.messages(['/truth/position'], start_ns=start_ns, stop_ns=stop_ns)]
    out = []
    for point in truth:
        p = np.array([point.point.x, point.point.y, point.point.z])
        lat, lon, _ = ecef_to_geodetic(p)
        q = p + ecef_to_enu_rotation(lat, lon).T @ np.array([0.05, 0.0, 0.0])
        msg = Odometry()
        msg.header.stamp = point.header.stamp
        msg.header.frame_id = 'earth'
        msg.pose.pose.position.x, msg.pose.pose.position.y, msg.pose.pose.position.z = (float(v) for v in q)
        out.append(msg)
    return out


@pytest.fixture(scope='module')
def report(tmp_path_factory) -> Path:
    """A report folder as ``run`` writes it: replay.md, then index.md, index.html and the figures."""
    out = tmp_path_factory.mktemp('report')
    with BagReader(BAG) as reader:
        start_ns, stop_ns = window_ns(reader.start_ns, WINDOW_S)
        jammer = [m.decode() for m in reader.messages(['/truth/jammer'], start_ns=start_ns, stop_ns=stop_ns)]
    (out / 'replay.md').write_text('# Replay of bags/default\n\n| topic | direction | messages |\n|---|---|---|\n'
                                   f'| /rfi/jammer_state | out | {len(jammer)} |\n')
    write_report(BAG, {'/rfi/jammer_state': jammer, '/fusion/odometry': odometry_from_truth(start_ns, stop_ns)},
                 out, window_ns=(start_ns, stop_ns), header='Counts and diagnostics: [replay.md](replay.md).')
    return out


@pytest.fixture(scope='module')
def browser():
    binary = find_browser()
    if binary is None:
        pytest.skip('no Chromium-based browser on PATH (chromium, chromium-browser, google-chrome): install '
                    "Debian's chromium (apt-get install chromium; .ci/run does so as root) to run the browser tests")
    with HeadlessBrowser(binary) as b:
        yield b


def png_width(data_uri: str) -> int:
    data = base64.b64decode(data_uri.split(',', 1)[1])
    assert data[:8] == b'\x89PNG\r\n\x1a\n'
    return struct.unpack('>I', data[16:20])[0]


def test_the_page_holds_every_heading_figure_and_table_of_the_markdown(report):
    markdown = (report / 'index.md').read_text()
    page = Html((report / 'index.html').read_text())
    figures = re.findall(r'^!\[([^\]]*)\]\(([^)]+)\)$', markdown, re.MULTILINE)
    assert [src for _, src in figures] == ['jammer.png', 'positioning.png']
    assert [(i['alt'], i['data-source']) for i in page.images] == figures
    for image, (_, src) in zip(page.images, figures, strict=True):
        assert base64.b64decode(image['src'].split(',', 1)[1]) == (report / src).read_bytes()
    tables = markdown_tables(markdown)
    assert len(tables) >= 4  # headline figures, jammer confusion matrix, positioning per phase and overall
    assert all(len(row) == len(table[0]) for table in tables for row in table)  # a | in a cell is escaped
    assert page.tables == tables
    assert page.headings == [markdown_plain(h) for h in re.findall(r'^#+ (.*)$', markdown, re.MULTILINE)]
    assert (report / 'replay.html').is_file() and 'href="replay.html"' in (report / 'index.html').read_text()


@pytest.mark.parametrize('screen', [DESKTOP, PHONE], ids=['desktop', 'phone'])
def test_every_figure_loads_with_no_error_in_a_headless_browser(browser, report, screen):
    result = browser.open(report / 'index.html', CHECK_PAGE, **screen)
    assert result.errors == []
    page = Html((report / 'index.html').read_text())
    assert len(result.value['images']) == len(page.images) == 2
    assert result.value['tables'] == len(page.tables)
    for shown, image in zip(result.value['images'], page.images, strict=True):
        assert shown['complete'] and shown['naturalWidth'] == png_width(image['src']) > 0, shown
        assert 0 < shown['shownWidth'] <= result.value['viewportWidth'], shown  # scaled to the screen
    assert result.value['pageWidth'] <= result.value['viewportWidth']  # no sideways scroll of the page


def test_the_linked_replay_page_opens_with_no_error(browser, report):
    result = browser.open(report / 'replay.html', 'document.querySelectorAll("td").length', **PHONE)
    assert result.errors == [] and result.value == 3


def test_the_browser_check_sees_a_broken_figure_and_a_console_error(tmp_path, browser):
    """The control: the checks above would fail on a page with a missing figure or a script error."""
    page = tmp_path / 'broken.html'
    page.write_text('<!DOCTYPE html><html><head><meta charset="utf-8"></head><body>'
                    '<img src="missing.png" alt="gone"><script>console.error("boom")</script></body></html>')
    result = browser.open(page, CHECK_PAGE, **DESKTOP)
    (image,) = result.value['images']
    assert image['complete'] and image['naturalWidth'] == 0
    assert any('console.error: boom' in e for e in result.errors)
    assert any('missing.png' in e for e in result.errors)
