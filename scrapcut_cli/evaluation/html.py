"""One self-contained HTML page from a report's markdown: tables, text and figures embedded.

``scrapcut eval --html FILE`` and ``scrapcut reproduce`` (``DIR/report.html``) write it, for
sharing where a folder of PNGs and a markdown file is awkward (mail, a ticket, a browser). The
markdown is the one the reports already render (GitHub-flavoured tables); each image link whose
target is in ``images`` becomes a ``data:image/png;base64`` URI, so the page needs no other file.
Raw HTML in the markdown is escaped, not passed through.
"""

from __future__ import annotations

import base64
import html
import re
from collections.abc import Mapping

_STYLE = """
body { font-family: system-ui, sans-serif; max-width: 1200px; margin: 2em auto; padding: 0 1em;
       color: #222; }
table { border-collapse: collapse; margin: 1em 0; font-size: 0.9em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; }
th { background: #f3f3f3; }
tr:nth-child(even) td { background: #fafafa; }
img { max-width: 100%; display: block; margin: 1em 0; }
code { background: #f3f3f3; padding: 0 0.2em; }
"""

_IMAGE = re.compile(r"!\[([^\]]*)\]\(([^)\s]+)\)")


def markdown_to_html(
    markdown: str, *, title: str, images: Mapping[str, bytes] | None = None
) -> str:
    """The page: ``markdown`` rendered (CommonMark + tables), images in ``images`` (link target
    → PNG bytes) embedded; a link to an image not given is left as it is."""
    from markdown_it import MarkdownIt

    images = images or {}

    def embed(match: re.Match[str]) -> str:
        data = images.get(match.group(2))
        if data is None:
            return match.group(0)
        encoded = base64.b64encode(data).decode("ascii")
        return f"![{match.group(1)}](data:image/png;base64,{encoded})"

    body = (
        MarkdownIt("commonmark", {"html": False})
        .enable("table")
        .render(_IMAGE.sub(embed, markdown))
    )
    return (
        '<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
        f"<title>{html.escape(title)}</title>\n<style>{_STYLE}</style>\n</head>\n<body>\n"
        f"{body}</body>\n</html>\n"
    )
