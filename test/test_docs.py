"""The documentation is a door, not a maze (issue 28, item 5).

- No page in docs/ (nor the README) holds a path of the machine it was written on (``/work/...``,
  ``/home/...``, ``/tmp/...``): a page is read and regenerated elsewhere. The benchmarks print paths
  through ``benchmarks/doc_paths.py``, which drops the prefix.
- Every relative link of the README and of docs/ points at a file that exists, and every anchor
  (``page.md#heading``) at a heading of that page: content moved between pages keeps its links.
- Every page of docs/ is reachable from docs/README.md (the index), and the README stays short.
"""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / 'docs'
README = ROOT / 'README.md'
README_MAX_LINES = 250
TEXT_SUFFIXES = {'.md', '.txt', '.csv', '.json', '.yaml', '.yml', '.svg', '.html'}

MACHINE_PATH = re.compile(r'(?<![\w.~-])/(?:work|home|tmp|root|Users|mnt|scratch|var/tmp)/[^\s`\'")\]]*')
"""An absolute path under a folder that is one machine's own: users' homes, scratch, temporary files."""

_LINK = re.compile(r'\[[^\]]*\]\(([^)\s]+)\)')


def doc_files() -> list[Path]:
    return sorted(p for p in DOCS.rglob('*') if p.is_file() and p.suffix in TEXT_SUFFIXES)


def machine_paths(text: str) -> list[str]:
    return [f'line {text.count(chr(10), 0, m.start()) + 1}: {m.group(0)}' for m in MACHINE_PATH.finditer(text)]


def anchor(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r'[^\w\- ]', '', heading.lstrip('#').strip().lower())
    return text.replace(' ', '-')


def anchors(page: Path) -> set[str]:
    return {anchor(line) for line in page.read_text().splitlines() if line.startswith('#')}


def broken_links(page: Path) -> list[str]:
    broken = []
    for target in _LINK.findall(page.read_text()):
        if re.match(r'^[a-z]+:', target):  # https:, mailto:
            continue
        path_part, _, fragment = target.partition('#')
        dest = (page.parent / path_part).resolve() if path_part else page
        if not dest.exists():
            broken.append(f'{target} (no {dest.relative_to(ROOT) if dest.is_relative_to(ROOT) else dest})')
        elif fragment and dest.suffix == '.md' and fragment not in anchors(dest):
            broken.append(f'{target} (no heading "{fragment}" in {dest.relative_to(ROOT)})')
    return broken


def test_no_machine_path_in_docs():
    found = {str(p.relative_to(ROOT)): machine_paths(p.read_text()) for p in [README, *doc_files()]}
    found = {k: v for k, v in found.items() if v}
    assert not found, ('paths of one machine in the docs (print them relative to the checkout, e.g. '
                       'with benchmarks/doc_paths.py, and fix the script that wrote them):\n'
                       + '\n'.join(f'  {page}: {", ".join(hits)}' for page, hits in found.items()))


def test_every_relative_link_resolves():
    broken = {str(p.relative_to(ROOT)): broken_links(p) for p in [README, *DOCS.rglob('*.md')]}
    broken = {k: v for k, v in broken.items() if v}
    assert not broken, 'broken links:\n' + '\n'.join(f'  {page}: {", ".join(v)}' for page, v in broken.items())


def test_every_page_is_reachable_from_the_index():
    index = DOCS / 'README.md'
    reached, todo = {index.resolve()}, [index]
    while todo:
        page = todo.pop()
        for target in _LINK.findall(page.read_text()):
            dest = (page.parent / target.partition('#')[0]).resolve()
            if dest.suffix == '.md' and dest.is_file() and dest.is_relative_to(DOCS) and dest not in reached:
                reached.add(dest)
                todo.append(dest)
    orphans = sorted(str(p.relative_to(ROOT)) for p in DOCS.rglob('*.md') if p.resolve() not in reached)
    assert not orphans, f'pages no link from docs/README.md leads to (add them to the index): {orphans}'


def test_the_readme_is_a_door():
    lines = README.read_text().splitlines()
    assert len(lines) <= README_MAX_LINES, (f'README.md has {len(lines)} lines, at most {README_MAX_LINES}: '
                                            'move the detail to docs/ and link it')
    text = README.read_text()
    for command in ('make demo', 'make test'):
        assert command in text
    assert '(docs/README.md)' in text and '(docs/architecture.md)' in text


def test_the_checks_see_what_they_look_for():
    assert machine_paths('x `/work/main/src/a.py` y\nz /home/me/f and /tmp/x.txt') == [
        'line 1: /work/main/src/a.py', 'line 2: /home/me/f', 'line 2: /tmp/x.txt']
    assert machine_paths('/opt/ros/jazzy/setup.bash, ../shared/data, ~/.venvs/x, src/work/a') == []
    assert anchor('## UWB anchors: what the filter cannot guess') == 'uwb-anchors-what-the-filter-cannot-guess'
    assert anchor('## Frames: the solution in `map` for robot_localization') == \
        'frames-the-solution-in-map-for-robot_localization'
