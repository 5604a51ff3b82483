"""The report as one self-contained web page: ``index.md`` rendered to ``index.html``.

:func:`markdown_to_html` renders the Markdown subset that the reports use (ATX headings,
paragraphs, pipe tables, ``-`` lists, fenced code, images, links, ``**bold**``, ``*emphasis*``
and ``code`` spans) into an HTML page that needs nothing else: each local image is embedded as a
``data:`` URI, the style sheet is inline, there is no script and no reference outside the file.
The layout is responsive: a viewport meta, a bounded text width, figures scaled to the screen
and wide tables scrolling inside their own box, so the page reads on a phone as on a desktop.

An image on a line of its own becomes a ``<figure>`` whose caption is its alt text. A link to a
Markdown file next to the page (the report's ``replay.md``) is rendered too, with
:func:`write_html`, and the link points at the rendered page. Text the subset does not know is
kept as paragraph text, escaped: nothing of the Markdown is dropped.
"""

from __future__ import annotations

import base64
import html
import re
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

MIME_TYPES = {'.png': 'image/png', '.svg': 'image/svg+xml', '.jpg': 'image/jpeg', '.jpeg': 'image/jpeg',
              '.gif': 'image/gif', '.webp': 'image/webp'}
"""Image types that can be embedded, by file extension."""

STYLE = """
:root { color-scheme: light; }
* { box-sizing: border-box; }
body { margin: 0 auto; max-width: 64rem; padding: 0.75rem 1rem 3rem;
       font: 16px/1.5 system-ui, -apple-system, "Segoe UI", Roboto, "Helvetica Neue", Arial, sans-serif;
       color: #1b1f24; background: #fff; overflow-wrap: break-word; }
h1 { font-size: 1.6rem; line-height: 1.25; margin: 0.5rem 0 1rem; }
h2 { font-size: 1.3rem; margin: 2rem 0 0.75rem; padding-bottom: 0.25rem; border-bottom: 1px solid #d0d7de; }
h3 { font-size: 1.1rem; margin: 1.5rem 0 0.5rem; }
p, ul, ol { margin: 0 0 0.9rem; }
a { color: #0550ae; }
code { font: 0.9em/1.4 ui-monospace, SFMono-Regular, Menlo, Consolas, monospace; background: #f3f4f6;
       padding: 0.1em 0.3em; border-radius: 4px; }
pre { overflow-x: auto; background: #f3f4f6; padding: 0.75rem; border-radius: 6px; }
pre code { padding: 0; background: none; }
.table { overflow-x: auto; margin: 0 0 1rem; -webkit-overflow-scrolling: touch; }
table { border-collapse: collapse; font-size: 0.9rem; font-variant-numeric: tabular-nums; }
th, td { border: 1px solid #d0d7de; padding: 0.3rem 0.55rem; text-align: left; vertical-align: top; }
th { background: #f6f8fa; }
tbody tr:nth-child(even) { background: #fafbfc; }
figure { margin: 1rem 0 1.5rem; }
img { display: block; max-width: 100%; height: auto; }
figcaption { font-size: 0.9rem; color: #57606a; margin-top: 0.4rem; }
@media (max-width: 40rem) { body { padding: 0.5rem 0.6rem 2rem; font-size: 15px; }
                            h1 { font-size: 1.35rem; } table { font-size: 0.8rem; } }
"""
"""The page's style sheet (inline in every page)."""

_TABLE_SEPARATOR = re.compile(r'^\s*\|?\s*:?-+:?\s*(\|\s*:?-+:?\s*)*\|?\s*$')
_HEADING = re.compile(r'^(#{1,6})\s+(.*?)\s*#*\s*$')
_IMAGE_LINE = re.compile(r'^!\[([^\]]*)\]\(([^)\s]+)\)$')
_FENCE = re.compile(r'^(```|~~~)')
_LIST_ITEM = re.compile(r'^\s*[-*+]\s+(.*)$')
_INLINE = re.compile(r'(?P<code>`[^`]+`)|(?P<image>!\[(?P<alt>[^\]]*)\]\((?P<src>[^)\s]+)\))'
                     r'|(?P<link>\[(?P<label>[^\]]+)\]\((?P<href>[^)\s]+)\))'
                     r'|(?P<bold>\*\*[^*]+\*\*)|(?P<em>(?<![\w*])\*[^*\s][^*]*\*(?!\w))')
_ESCAPABLE = re.compile(r'\\([\\`*_{}\[\]()#+\-.!|])')


@dataclass
class _Context:
    """What the rendering of one page needs and collects."""

    base_dir: Path
    linked_pages: list[Path] = field(default_factory=list)
    heading_ids: set[str] = field(default_factory=set)


FIGURE_DPI = 110
"""Resolution of the report's PNG figures, dots per inch."""


def save_figure(fig: Any, plt: Any, path: Path, title: str, alt: str = '') -> list[str]:
    """Title, lay out, write and close one matplotlib figure of a report; the Markdown lines that show it.

    Args:
        fig: the figure; closed here (``plt.close``).
        plt: ``matplotlib.pyplot``.
        path: the PNG to write (FIGURE_DPI); the Markdown links its name, beside ``index.md``.
        title: the figure's title, also its alt text (the page's caption) unless ``alt`` is given.
        alt: a longer alt text.

    Returns:
        ``['', '![alt](name)', '']``, to append to the report's lines.
    """
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=FIGURE_DPI)
    plt.close(fig)
    return ['', f'![{alt or title}]({path.name})', '']


def _image_uri(src: str, ctx: _Context) -> tuple[str, tuple[int, int] | None]:
    """``src`` as a data: URI and its pixel size (PNG only, else None).

    Raises:
        ValueError: ``src`` is not a file next to the page, or not an image type that can be embedded.
    """
    if re.match(r'^[a-z][a-z0-9+.-]*:', src, re.IGNORECASE) or src.startswith('/'):
        raise ValueError(f'image {src!r} is not a file next to the report: the page must be self-contained')
    path = ctx.base_dir / src
    mime = MIME_TYPES.get(path.suffix.lower())
    if mime is None:
        raise ValueError(f'image {src!r}: cannot embed a {path.suffix!r} file (known: {", ".join(MIME_TYPES)})')
    try:
        data = path.read_bytes()
    except OSError as err:
        raise ValueError(f'image {src!r} of the report cannot be read: {err}') from err
    size = None
    if mime == 'image/png' and data[:8] == b'\x89PNG\r\n\x1a\n' and len(data) >= 24:
        size = struct.unpack('>II', data[16:24])
    return f'data:{mime};base64,{base64.b64encode(data).decode("ascii")}', size


def _img_tag(alt: str, src: str, ctx: _Context) -> str:
    uri, size = _image_uri(src, ctx)
    dims = f' width="{size[0]}" height="{size[1]}"' if size else ''
    return f'<img src="{uri}" alt="{html.escape(alt)}"{dims} data-source="{html.escape(src)}">'


def _link_target(href: str, ctx: _Context) -> str:
    """The href to write: a Markdown page next to this one is rendered and linked as .html."""
    if href.endswith('.md') and not re.match(r'^[a-z][a-z0-9+.-]*:', href, re.IGNORECASE) \
            and '/' not in href and (ctx.base_dir / href).is_file():
        page = ctx.base_dir / href
        if page not in ctx.linked_pages:
            ctx.linked_pages.append(page)
        return href[:-3] + '.html'
    return href


def _inline(text: str, ctx: _Context) -> str:
    """Inline Markdown (code, images, links, bold, emphasis, backslash escapes) as escaped HTML."""
    out: list[str] = []
    pos = 0
    for match in _INLINE.finditer(text):
        out.append(_plain(text[pos:match.start()]))
        token = match.group(0)
        if match.group('code'):
            out.append(f'<code>{html.escape(token[1:-1])}</code>')
        elif match.group('image'):
            out.append(_img_tag(match.group('alt'), match.group('src'), ctx))
        elif match.group('link'):
            href = _link_target(match.group('href'), ctx)
            out.append(f'<a href="{html.escape(href)}">{_inline(match.group("label"), ctx)}</a>')
        elif match.group('bold'):
            out.append(f'<strong>{_inline(token[2:-2], ctx)}</strong>')
        else:
            out.append(f'<em>{_inline(token[1:-1], ctx)}</em>')
        pos = match.end()
    out.append(_plain(text[pos:]))
    return ''.join(out)


def _plain(text: str) -> str:
    return html.escape(_ESCAPABLE.sub(r'\1', text), quote=False)


def _cells(row: str) -> list[str]:
    """The cells of a pipe-table row; ``\\|`` is a literal bar inside a cell."""
    row = row.strip()
    if row.startswith('|'):
        row = row[1:]
    if row.endswith('|') and not row.endswith('\\|'):
        row = row[:-1]
    return [cell.strip().replace('\\|', '|') for cell in re.split(r'(?<!\\)\|', row)]


def _heading_id(text: str, ctx: _Context) -> str:
    base = re.sub(r'[^a-z0-9]+', '-', text.lower()).strip('-') or 'section'
    slug, n = base, 1
    while slug in ctx.heading_ids:
        n += 1
        slug = f'{base}-{n}'
    ctx.heading_ids.add(slug)
    return slug


def _is_table_start(lines: list[str], i: int) -> bool:
    return (i + 1 < len(lines) and '|' in lines[i] and bool(_TABLE_SEPARATOR.match(lines[i + 1]))
            and '-' in lines[i + 1])


def _render_blocks(markdown: str, ctx: _Context) -> list[str]:
    lines = markdown.splitlines()
    out: list[str] = []
    paragraph: list[str] = []

    def flush() -> None:
        if paragraph:
            out.append(f'<p>{_inline(" ".join(s.strip() for s in paragraph), ctx)}</p>')
            paragraph.clear()

    i = 0
    while i < len(lines):
        line = lines[i]
        stripped = line.strip()
        if not stripped:
            flush()
            i += 1
        elif _FENCE.match(stripped):
            flush()
            fence = stripped[:3]
            j = i + 1
            while j < len(lines) and not lines[j].strip().startswith(fence):
                j += 1
            out.append('<pre><code>' + html.escape('\n'.join(lines[i + 1:j])) + '</code></pre>')
            i = j + 1
        elif heading := _HEADING.match(stripped):
            flush()
            level, text = len(heading.group(1)), heading.group(2)
            out.append(f'<h{level} id="{_heading_id(text, ctx)}">{_inline(text, ctx)}</h{level}>')
            i += 1
        elif _is_table_start(lines, i):
            flush()
            head = _cells(lines[i])
            rows = []
            i += 2
            while i < len(lines) and lines[i].strip() and '|' in lines[i]:
                rows.append(_cells(lines[i]))
                i += 1
            cells_head = ''.join(f'<th>{_inline(c, ctx)}</th>' for c in head)
            body = ''.join('<tr>' + ''.join(f'<td>{_inline(c, ctx)}</td>' for c in row) + '</tr>' for row in rows)
            out.append(f'<div class="table"><table><thead><tr>{cells_head}</tr></thead>'
                       f'<tbody>{body}</tbody></table></div>')
        elif image := _IMAGE_LINE.match(stripped):
            flush()
            alt, src = image.groups()
            caption = f'<figcaption>{_inline(alt, ctx)}</figcaption>' if alt else ''
            out.append(f'<figure>{_img_tag(alt, src, ctx)}{caption}</figure>')
            i += 1
        elif _LIST_ITEM.match(line):
            flush()
            items = []
            while i < len(lines) and (item := _LIST_ITEM.match(lines[i])):
                text = [item.group(1)]
                i += 1
                while i < len(lines) and lines[i].startswith('  ') and lines[i].strip() \
                        and not _LIST_ITEM.match(lines[i]):
                    text.append(lines[i].strip())
                    i += 1
                items.append(f'<li>{_inline(" ".join(text), ctx)}</li>')
            out.append('<ul>' + ''.join(items) + '</ul>')
        else:
            paragraph.append(line)
            i += 1
    flush()
    return out


def markdown_to_html(markdown: str, base_dir: str | Path, *, title: str | None = None) -> tuple[str, list[Path]]:
    """One self-contained HTML page from the report's Markdown.

    Args:
        markdown: the page's Markdown (the subset in the module docstring).
        base_dir: the folder the Markdown's relative image and link targets are in.
        title: the page title (default: the first heading's text).

    Returns:
        The HTML page, and the Markdown files next to it that it links to (to be rendered too).

    Raises:
        ValueError: an image is not a readable file next to the page, or of a type that cannot be
            embedded.
    """
    ctx = _Context(Path(base_dir))
    body = '\n'.join(_render_blocks(markdown, ctx))
    if title is None:
        first = next((m.group(2) for s in markdown.splitlines() if (m := _HEADING.match(s.strip()))), 'Report')
        title = re.sub(r'[`*]', '', first)
    page = ('<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
            '<meta name="viewport" content="width=device-width, initial-scale=1">\n'
            f'<title>{html.escape(title)}</title>\n<style>{STYLE}</style>\n</head>\n<body>\n<main>\n'
            f'{body}\n</main>\n</body>\n</html>\n')
    return page, ctx.linked_pages


def write_html(markdown_path: str | Path) -> list[Path]:
    """Write ``X.html`` beside ``X.md``, and the pages next to it that it links to.

    Returns:
        The HTML files written, ``X.html`` first.

    Raises:
        ValueError: as :func:`markdown_to_html`.
    """
    todo, written, seen = [Path(markdown_path)], [], set()
    while todo:
        source = todo.pop(0)
        if source.resolve() in seen:
            continue
        seen.add(source.resolve())
        page, linked = markdown_to_html(source.read_text(encoding='utf-8'), source.parent)
        target = source.with_suffix('.html')
        target.write_text(page, encoding='utf-8')
        written.append(target)
        todo += linked
    return written
