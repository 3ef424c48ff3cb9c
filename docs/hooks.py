"""MkDocs hooks of the documentation site (named in mkdocs.yml ``hooks``; not a page).

- Documents that live beside the code they describe are published in the site as they are,
  without a copy in docs/: ``interfaces/mavlink/README.md`` (the ground link interface, which
  its code and tests cite by that path) becomes the page ``interfaces/mavlink.md``. Its
  relative links are re-aimed from its real folder to its place in the site; a link to a
  file that is not a page stays as written, so ``mkdocs build --strict`` reports it.
- ``events.md`` (the event catalogue) is written by its own generator; until that page
  exists a virtual placeholder, marked as such, keeps the navigation whole. Nothing is
  written to docs/.
"""
from __future__ import annotations

import os
import re
from pathlib import Path

from mkdocs.structure.files import File, InclusionLevel

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"

# site page -> the repository file it publishes
MOUNTED = {"interfaces/mavlink.md": ROOT / "interfaces" / "mavlink" / "README.md"}

EVENTS_PAGE = "events.md"
EVENTS_PLACEHOLDER = """# Event catalogue

!!! warning "Placeholder"
    This page is a placeholder made by the site's build (`docs/hooks.py`) because
    `docs/events.md` does not exist yet. The event catalogue is generated from the events'
    declarations by its own tool, which writes `docs/events.md`; once it is committed this
    placeholder is no longer used.

Until then: every event carries a source, a stable code, a severity (MAVLink `MAV_SEVERITY`)
and a text of at most 50 characters; see the `EVENT` record in
[records](reference/records.md#event) and the module documentation of each flight-software
function ([FDIR](fsw/fdir.md), [jet driver and modes](fsw/jetdriver-modes.md)).
"""

_LINK = re.compile(r"\]\((?!https?:|mailto:|#|/)([^)\s#]+)(#[^)\s]*)?\)")


def on_files(files, config, **kwargs):
    for src_uri, path in MOUNTED.items():
        files.append(File.generated(config, src_uri, abs_src_path=str(path), inclusion=InclusionLevel.INCLUDED))
    if files.get_file_from_path(EVENTS_PAGE) is None:
        files.append(File.generated(config, EVENTS_PAGE, content=EVENTS_PLACEHOLDER))
    return files


def on_page_markdown(markdown, page, config, files, **kwargs):
    real = MOUNTED.get(page.file.src_uri)
    if real is None:
        return markdown
    site_dir = (DOCS / page.file.src_uri).parent

    def reaim(m: re.Match) -> str:
        target = (real.parent / m.group(1)).resolve()
        if DOCS in target.parents:
            return f"]({os.path.relpath(target, site_dir)}{m.group(2) or ''})"
        return m.group(0)

    return _LINK.sub(reaim, markdown)
