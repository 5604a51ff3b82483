"""The report's Markdown rendered as one self-contained web page (rfi_experiments.report_html).

Each construct the reports use is rendered into the HTML a browser needs, every image is
embedded byte for byte, nothing refers outside the file, and what cannot be embedded is an
error that names the image.
"""

from __future__ import annotations

import base64
import struct
import zlib
from html.parser import HTMLParser
from pathlib import Path

import pytest

from rfi_experiments.report_html import markdown_to_html, write_html


def tiny_png(width: int, height: int) -> bytes:
    """A valid grey PNG of the given size (8-bit greyscale, no filter)."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack('>I', len(data)) + kind + data + struct.pack('>I', zlib.crc32(kind + data))
    raw = b''.join(b'\0' + bytes([128]) * width for _ in range(height))
    return (b'\x89PNG\r\n\x1a\n' + chunk(b'IHDR', struct.pack('>IIBBBBB', width, height, 8, 0, 0, 0, 0))
            + chunk(b'IDAT', zlib.compress(raw)) + chunk(b'IEND', b''))


class Page(HTMLParser):
    """Tags, attributes and text of a page, as the tests look at them."""

    def __init__(self, text: str) -> None:
        super().__init__()
        self.tags: list[tuple[str, dict[str, str | None]]] = []
        self.tables: list[list[list[str]]] = []
        self.headings: list[tuple[str, str]] = []
        self.captions: list[str] = []
        self._text: list[str] | None = None
        self._stack: list[str] = []
        self.feed(text)

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.tags.append((tag, dict(attrs)))
        if tag == 'table':
            self.tables.append([])
        elif tag == 'tr':
            self.tables[-1].append([])
        if tag in ('td', 'th', 'h1', 'h2', 'h3', 'figcaption'):
            self._text, self._stack = [], [*self._stack, tag]

    def handle_endtag(self, tag: str) -> None:
        if self._stack and tag == self._stack[-1] and self._text is not None:
            text = ''.join(self._text).strip()
            if tag in ('td', 'th'):
                self.tables[-1][-1].append(text)
            elif tag == 'figcaption':
                self.captions.append(text)
            else:
                self.headings.append((tag, text))
            self._stack.pop()
            self._text = None

    def handle_data(self, data: str) -> None:
        if self._text is not None:
            self._text.append(data)

    def all(self, tag: str) -> list[dict[str, str | None]]:
        return [attrs for t, attrs in self.tags if t == tag]


REPORT_MD = """# Jamming experiment: `default`

12 input messages replayed (direct). Counts and diagnostics: [replay.md](replay.md).

**Warning**: the fusion dropped 3 late messages.

## Headline figures

| figure | this run | paper / goal | note |
|---|---|---|---|
| sweep period error (median) | 0.120 % | 1 % (issue goal) | 5 chirp blocks |
| a \\| bar and a `code <b>` span | 3 < 4 & 5 > 2 | | *emphasis* |

## Jammer (rfi_monitor)

| true \\ reported | NONE | CW |
|---|---|---|
| NONE | 10 | 0 |

Figure: the frequency at each block end,
on two lines of the Markdown.

![Jammer frequency track & J/S](jammer.png)

- one item
- two items, the second
  wrapped

```
raw <text> | kept
```
"""


@pytest.fixture
def report_dir(tmp_path: Path) -> Path:
    (tmp_path / 'jammer.png').write_bytes(tiny_png(30, 20))
    (tmp_path / 'replay.md').write_text('# Replay\n\n| topic | messages |\n|---|---|\n| /gnss/measurements | 12 |\n')
    (tmp_path / 'index.md').write_text(REPORT_MD)
    return tmp_path


def test_every_construct_is_rendered(report_dir):
    page_html, linked = markdown_to_html(REPORT_MD, report_dir)
    page = Page(page_html)
    assert page.headings == [('h1', 'Jamming experiment: default'), ('h2', 'Headline figures'),
                             ('h2', 'Jammer (rfi_monitor)')]
    assert page.tables == [
        [['figure', 'this run', 'paper / goal', 'note'],
         ['sweep period error (median)', '0.120 %', '1 % (issue goal)', '5 chirp blocks'],
         ['a | bar and a code <b> span', '3 < 4 & 5 > 2', '', 'emphasis']],
        [['true \\ reported', 'NONE', 'CW'], ['NONE', '10', '0']]]
    assert '<code>code &lt;b&gt;</code>' in page_html and '<em>emphasis</em>' in page_html
    assert '<strong>Warning</strong>: the fusion dropped 3 late messages.' in page_html
    assert '<p>Figure: the frequency at each block end, on two lines of the Markdown.</p>' in page_html
    assert '<ul><li>one item</li><li>two items, the second wrapped</li></ul>' in page_html
    assert '<pre><code>raw &lt;text&gt; | kept</code></pre>' in page_html
    assert page.all('a') == [{'href': 'replay.html'}] and linked == [report_dir / 'replay.md']


def test_images_are_embedded_byte_for_byte_as_figures(report_dir):
    page = Page(markdown_to_html(REPORT_MD, report_dir)[0])
    (img,) = page.all('img')
    assert img['src'].startswith('data:image/png;base64,')
    assert base64.b64decode(img['src'].split(',', 1)[1]) == (report_dir / 'jammer.png').read_bytes()
    assert (img['alt'], img['width'], img['height']) == ('Jammer frequency track & J/S', '30', '20')
    assert page.captions == ['Jammer frequency track & J/S']


def test_the_page_is_self_contained_and_responsive(report_dir):
    page_html = markdown_to_html(REPORT_MD, report_dir)[0]
    page = Page(page_html)
    assert not page.all('script') and not page.all('link') and not page.all('iframe')
    refs = [a.get('src') or a.get('href') for t, a in page.tags if a.get('src') or a.get('href')]
    assert refs and all(r.startswith('data:') or r == 'replay.html' for r in refs)
    assert 'url(' not in page_html and '@import' not in page_html
    assert {'name': 'viewport', 'content': 'width=device-width, initial-scale=1'} in page.all('meta')
    assert 'max-width: 100%' in page_html and 'overflow-x: auto' in page_html  # figures scale, tables scroll
    assert page.all('title') and '<title>Jamming experiment: default</title>' in page_html


def test_write_html_renders_the_linked_page_too(report_dir):
    written = write_html(report_dir / 'index.md')
    assert written == [report_dir / 'index.html', report_dir / 'replay.html']
    replay = Page((report_dir / 'replay.html').read_text())
    assert replay.tables == [[['topic', 'messages'], ['/gnss/measurements', '12']]]


def test_a_link_to_a_missing_page_or_elsewhere_is_kept(tmp_path):
    page_html, linked = markdown_to_html('[a](other.md) [b](https://example.org/x.md) [c](#top)', tmp_path)
    assert [a['href'] for a in Page(page_html).all('a')] == ['other.md', 'https://example.org/x.md', '#top']
    assert linked == []


@pytest.mark.parametrize(('markdown', 'message'), [
    ('![f](missing.png)', "image 'missing.png' of the report cannot be read"),
    ('![f](https://example.org/f.png)', 'is not a file next to the report'),
    ('![f](/etc/f.png)', 'is not a file next to the report'),
    ('text ![f](f.tiff) inline', "cannot embed a '.tiff' file"),
])
def test_an_image_that_cannot_be_embedded_is_an_error_naming_it(tmp_path, markdown, message):
    (tmp_path / 'f.tiff').write_bytes(b'II*\0')
    with pytest.raises(ValueError, match=message.replace('(', r'\(').replace('.', r'\.')):
        markdown_to_html(markdown, tmp_path)


def test_heading_ids_are_unique(tmp_path):
    page = Page(markdown_to_html('## Carrier\n\n## Carrier\n\n### J/S, dB\n', tmp_path)[0])
    assert [a['id'] for t, a in page.tags if t in ('h2', 'h3')] == ['carrier', 'carrier-2', 'j-s-db']
