"""MkDocs hook: pages include text that is written once, where the code and README keep it.

* ``<!-- scene-schema: ... -->`` becomes the annotated schema of ``python/sorofem/scene/__init__.py``'s
  module docstring (its ``Schema`` section, generated from the scene spec), as a TOML block.
* ``<!-- readme-scene-keys: ... -->`` becomes README.md's table of every scene key and the
  paragraphs after it, up to "Validation is strict"; links to repository files become code spans.
"""

from __future__ import annotations

import ast
import re
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SCENE = ROOT / "python" / "sorofem" / "scene" / "__init__.py"
README = ROOT / "README.md"
SCHEMA_MARKER = re.compile(r"<!-- scene-schema:[^>]*-->")
KEYS_MARKER = re.compile(r"<!-- readme-scene-keys:[^>]*-->")
# [`text`](relative/path) or [text](relative/path), not http(s) or in-page anchors.
REPO_LINK = re.compile(r"\[`?([^\]`]+)`?\]\((?!https?:|#)([^)]+)\)")
README_ANCHORS = {
    "#formulations": "theory.md#mixed-formulation",
    "#from-a-surface-to-a-simulation": "getting-started.md#from-a-surface-to-a-simulation",
}


def scene_schema() -> str:
    """The ``::`` literal block after ``Schema`` in the module docstring, as a TOML fence."""
    doc = ast.get_docstring(ast.parse(SCENE.read_text(encoding="utf-8"))) or ""
    match = re.search(r"Schema\n-+\n::\n\n(.*?)\n\S", doc, flags=re.S)
    if match is None:
        raise ValueError(f"{SCENE}: no 'Schema' section with a '::' literal block in the module docstring")
    return "```toml\n" + textwrap.dedent(match.group(1)).rstrip() + "\n```"


def readme_scene_keys() -> str:
    """README.md from "Every key:" to "Validation is strict" (exclusive)."""
    text = README.read_text(encoding="utf-8")
    start, end = text.find("Every key:\n"), text.find("Validation is strict")
    if start < 0 or end < start:
        raise ValueError(f"{README}: expected 'Every key:' followed by 'Validation is strict' in 'Scene files'")
    # The table between its generator's markers (HTML comments, which the site does not need).
    section = re.sub(r"<!--.*?-->\n?", "", text[start + len("Every key:\n"):end]).strip()
    for anchor, target in README_ANCHORS.items():
        section = section.replace(f"]({anchor})", f"]({target})")
    return REPO_LINK.sub(lambda m: f"`{m.group(1)}`" if ".md" not in m.group(2) else m.group(0), section)


def on_page_markdown(markdown: str, page, config, files) -> str:  # noqa: ANN001 - MkDocs hook signature
    if SCHEMA_MARKER.search(markdown):
        markdown = SCHEMA_MARKER.sub(lambda _: scene_schema(), markdown)
    if KEYS_MARKER.search(markdown):
        markdown = KEYS_MARKER.sub(lambda _: readme_scene_keys(), markdown)
    return markdown
