"""Write generated text into a marked block of a hand-written markdown file.

A block is the text between ``<!-- begin NAME -->`` and ``<!-- end NAME -->``; the prose
around it stays as written, the numbers inside come from the script that names the block.
"""

from __future__ import annotations

import re
from pathlib import Path


def replace_block(path: str | Path, name: str, text: str) -> None:
    """Replace block ``name`` of ``path`` with ``text`` (the block must exist)."""
    path = Path(path)
    doc = path.read_text()
    begin, end = f"<!-- begin {name} -->", f"<!-- end {name} -->"
    pattern = re.compile(re.escape(begin) + r".*?" + re.escape(end), re.S)
    if not pattern.search(doc):
        raise SystemExit(f"{path}: no block {begin} ... {end}")
    path.write_text(pattern.sub(lambda _: f"{begin}\n{text.strip()}\n{end}", doc))
