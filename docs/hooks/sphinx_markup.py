"""Griffe extension: the Sphinx markup of sorofem's docstrings becomes Markdown.

The docstrings are NumPy style with three pieces of reStructuredText that ``help()`` shows as
they are and Sphinx renders, but Markdown (which mkdocstrings renders docstrings with) does not:

* cross-reference roles (``:func:`solve_static```, ``:class:`~sorofem.Trajectory```) become
  Markdown cross-references, ``[`title`][canonical.path]``, that mkdocs-autorefs turns into links
  to the object's API entry;
* literal blocks (a paragraph ending in ``::``, then an indented block) become fenced code blocks
  (``text::`` -> ``text:``; a lone ``::`` goes);
* definition lists (a term, then its indented definition) outside the standard NumPy sections
  become Markdown definition lists (the ``def_list`` extension in mkdocs.yml).

Once Griffe has loaded the whole package, every docstring is rewritten and parsed in memory; the
source stays as it is. Configured in ``mkdocs.yml`` under the Python handler's ``extensions``.

A role's target is looked up as Sphinx looks it up: in the object whose docstring it is (a
class's members), then in its parents up to the package, then as an absolute path. The title is
the target as written, or its last part after ``~``; functions and methods get ``()``. A target
outside the package (``ValueError``, ``matplotlib.figure.Figure``) or one that no page shows
becomes a code span. A page shows what its ``::: identifier`` lines name and, below each, the
public members with a docstring (``filters: ["!^_"]``, ``show_if_no_docstring: false``). A
role naming something of the package that does not exist is logged as a warning, which fails
``mkdocs build --strict``: a typo in a role should not ship.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import griffe

DOCS = Path(__file__).resolve().parents[1]
AUTODOC = re.compile(r"^::: ([\w.]+)\s*$", re.M)

# :role:`target`, :role:`~target`, :role:`title <target>`; the ``py:`` domain is optional.
ROLE = re.compile(r":(?:py:)?(?P<role>class|func|meth|attr|mod|data|exc|obj|const):`(?P<body>[^`]+)`")
EXPLICIT_TITLE = re.compile(r"^(?P<title>.+?)\s*<(?P<target>[^<>]+)>$")
CALLABLE_ROLES = {"func", "meth"}
FENCE = "```"
DEFINITION_INDENT = "    "  # Markdown's definition body: ":   " on the first line, four spaces after


class SphinxMarkup(griffe.Extension):
    """Rewrite the docstrings' Sphinx roles, literal blocks and definition lists into Markdown."""

    def on_package(self, *, pkg: griffe.Module, **kwargs: Any) -> None:
        shown = shown_paths(pkg)
        for obj in _walk(pkg):
            docstring = obj.docstring
            if docstring is None:
                continue
            docstring.value = ROLE.sub(lambda m, o=obj: _reference(m, o, pkg, shown), docstring.value)
            docstring.__dict__.pop("parsed", None)  # a cached parse of the old text
            for section in docstring.parsed:  # parsed once more, then edited in the cache
                _convert_section(section)


# ---------------------------------------------------------------------------
# Cross-reference roles


def shown_paths(pkg: griffe.Module) -> set[str]:
    """Canonical paths of the objects of ``pkg`` that the documentation pages show."""
    shown: set[str] = set()
    for page in DOCS.rglob("*.md"):
        for identifier in AUTODOC.findall(page.read_text(encoding="utf-8")):
            root = _resolve(identifier, pkg, pkg)
            if root is not None:
                shown.update(obj.path for obj in _walk(root, documented_only=True))
    return shown


def _walk(obj: griffe.Object, documented_only: bool = False) -> Iterator[griffe.Object]:
    """``obj`` and the objects defined under it (not aliases: their target has the docstring);
    with ``documented_only``, only public ones with a docstring, not submodules, as the pages render."""
    yield obj
    for name, member in obj.members.items():
        if member.is_alias:
            continue
        if documented_only and (name.startswith("_") or member.is_module or not member.has_docstring):
            continue
        yield from _walk(member, documented_only)


def _reference(match: re.Match[str], owner: griffe.Object, pkg: griffe.Module, shown: set[str]) -> str:
    role, body = match["role"], match["body"].strip()
    explicit = EXPLICIT_TITLE.match(body)
    if explicit:
        title, target = explicit["title"], explicit["target"].strip()
    else:
        target = body.lstrip("~")
        title = target.rsplit(".", 1)[-1] if body.startswith("~") else target
        if role in CALLABLE_ROLES:
            title += "()"
    found = _resolve(target, owner, pkg)
    if found is None:
        if target == pkg.name or target.startswith(pkg.name + "."):
            griffe.logger.warning(f"{owner.path}: {match[0]}: {target} is not in the package")
        return f"`{title}`"
    if found.path not in shown:
        return f"`{title}`"
    return f"[`{title}`][{found.path}]"


def _resolve(target: str, owner: griffe.Object, pkg: griffe.Module) -> griffe.Object | None:
    """The object ``target`` names, seen from ``owner``'s docstring, with aliases followed."""
    if target == pkg.name:
        return pkg
    scope: griffe.Object | None = owner if (owner.is_class or owner.is_module) else owner.parent
    candidates: list[tuple[griffe.Object, str]] = []
    while scope is not None:
        candidates.append((scope, target))
        scope = scope.parent
    if target.startswith(pkg.name + "."):
        candidates.append((pkg, target[len(pkg.name) + 1:]))
    for scope, path in candidates:
        try:
            found = scope[path]
        except (KeyError, ValueError, griffe.AliasResolutionError):
            continue  # not there, or looked up through an import from another package
        try:
            return found.final_target if found.is_alias else found
        except griffe.AliasResolutionError:
            return None  # an import from another package
    return None


# ---------------------------------------------------------------------------
# Literal blocks and definition lists


def _convert_section(section: griffe.DocstringSection) -> None:
    """Convert the free text of a parsed section in place: the whole text of a text or unknown
    (admonition) section, the descriptions of a list section (parameters, returns, ...)."""
    if isinstance(section.value, str):
        section.value = definition_lists(literal_blocks(section.value))
    elif isinstance(section.value, griffe.DocstringAdmonition):
        section.value.description = definition_lists(literal_blocks(section.value.description))
    elif section.kind is griffe.DocstringSectionKind.examples:
        section.value = [(kind, literal_blocks(text) if kind is griffe.DocstringSectionKind.text else text)
                         for kind, text in section.value]
    elif isinstance(section.value, list):
        for element in section.value:
            if isinstance(element, griffe.DocstringElement):
                element.description = literal_blocks(element.description)


def literal_blocks(text: str) -> str:
    """``text`` with each literal block as a fenced code block at the indentation of the paragraph
    that introduced it (so that it stays inside the list item or definition it belongs to)."""
    lines = text.split("\n")
    out: list[str] = []
    i = 0
    while i < len(lines):
        line = lines[i]
        indent = _indentation(line)
        start = _next_non_blank(lines, i + 1)
        if not line.rstrip().endswith("::") or start == len(lines) or _indentation(lines[start]) <= indent:
            out.append(line)
            i += 1
            continue
        end = _block_end(lines, start, indent)
        head = line.rstrip()[:-2]
        if head.strip():
            out += [head.rstrip() + ("" if head.endswith(" ") else ":"), ""]  # "text ::" -> "text"
        margin, cut = " " * indent, _indentation(lines[start])
        out.append(margin + FENCE + "text")
        out += [margin + block_line[cut:] if block_line.strip() else "" for block_line in lines[start:end]]
        out.append(margin + FENCE)
        i = end
    return "\n".join(out)


def definition_lists(text: str) -> str:
    """``text`` with each unindented line that is followed at once by an indented block (a
    reStructuredText definition list item) as a Markdown definition list item. Fenced blocks and
    doctest lines are left as they are."""
    lines = text.split("\n")
    out: list[str] = []
    i, in_fence = 0, False
    while i < len(lines):
        line = lines[i]
        if line.lstrip().startswith(FENCE):
            in_fence = not in_fence
        is_term = (
            not in_fence and line.strip() and _indentation(line) == 0 and not line.startswith((">>>", "..."))
            and i + 1 < len(lines) and lines[i + 1].strip() and _indentation(lines[i + 1]) > 0
        )
        if not is_term:
            out.append(line)
            i += 1
            continue
        end = _block_end(lines, i + 1, 0)
        cut = min(_indentation(b) for b in lines[i + 1:end] if b.strip())
        body = [b[cut:] if b.strip() else "" for b in lines[i + 1:end]]
        out += ["", line, ":" + DEFINITION_INDENT[1:] + body[0]]
        out += [DEFINITION_INDENT + b if b else "" for b in body[1:]]
        i = end
    return "\n".join(out)


def _indentation(line: str) -> int:
    return len(line) - len(line.lstrip(" "))


def _next_non_blank(lines: list[str], i: int) -> int:
    while i < len(lines) and not lines[i].strip():
        i += 1
    return i


def _block_end(lines: list[str], start: int, indent: int) -> int:
    """End (exclusive) of the block from ``start`` of lines indented deeper than ``indent``,
    blank lines inside it included, trailing ones not."""
    end = start
    while end < len(lines) and (not lines[end].strip() or _indentation(lines[end]) > indent):
        end += 1
    while end > start and not lines[end - 1].strip():
        end -= 1
    return end
