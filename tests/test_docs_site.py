"""The documentation site builds and reads as intended, offline.

Builds the site with ``mkdocs build --strict`` (warnings are errors: a role naming nothing, a
broken link) into a temporary folder, then reads every page's HTML: no Sphinx role is left raw,
no TeX is left outside the elements MathJax typesets, every page with maths loads the MathJax
the site bundles, and no page loads a script, stylesheet or font from another host. Needs the
``docs`` extra: marker ``docs``, run by ``make docs`` (and so by CI), not by ``make test``.
"""

from __future__ import annotations

import re
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path

import pytest

pytestmark = pytest.mark.docs

ROOT = Path(__file__).resolve().parent.parent
ROLE = re.compile(r":(?:py:)?(?:class|func|meth|attr|mod|data|exc|obj|const):(?:`|<code>)")
# TeX left for the reader: \( \) \[ \] delimiters, $...$ and $$...$$, or a TeX command.
RAW_TEX = re.compile(r"\\[()\[\]]|\$\$|\$[^$\s][^$]*\$|\\(?:frac|mathbf|boldsymbol|begin|partial|sum|nabla)\b")
EXTERNAL = re.compile(r"^(?:[a-z][a-z0-9+.-]*:)?//", re.I)
MATHJAX = "assets/mathjax/tex-svg-full.js"


class PageText(HTMLParser):
    """A page's visible prose (no code, scripts or MathJax input) and the resources it loads."""

    SKIPPED = {"pre", "code", "script", "style", "kbd", "samp"}
    VOID = {"area", "base", "br", "col", "embed", "hr", "img", "input", "link", "meta", "source", "track", "wbr"}

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.prose: list[str] = []
        self.resources: list[tuple[str, str]] = []
        self.maths = 0
        self._stack: list[bool] = []  # per open element: whether its text is skipped

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        attributes = dict(attrs)
        if tag == "script" and attributes.get("src"):
            self.resources.append(("script", attributes["src"]))
        if tag == "link" and attributes.get("href") and "stylesheet" in (attributes.get("rel") or ""):
            self.resources.append(("stylesheet", attributes["href"]))
        if tag in ("img", "iframe", "source") and attributes.get("src"):
            self.resources.append((tag, attributes["src"]))
        if tag in self.VOID:
            return
        arithmatex = "arithmatex" in (attributes.get("class") or "").split()
        self.maths += arithmatex
        inherited = bool(self._stack and self._stack[-1])
        self._stack.append(inherited or tag in self.SKIPPED or arithmatex)

    def handle_endtag(self, tag: str) -> None:
        if tag not in self.VOID and self._stack:
            self._stack.pop()

    def handle_data(self, data: str) -> None:
        if not (self._stack and self._stack[-1]):
            self.prose.append(data)


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("site")
    build = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--config-file", str(ROOT / "mkdocs.yml"),
         "--site-dir", str(out)],
        cwd=ROOT, capture_output=True, text=True, timeout=600,
    )
    assert build.returncode == 0, f"mkdocs build --strict failed:\n{build.stdout}\n{build.stderr}"
    return out


def _pages(site: Path) -> dict[str, tuple[str, PageText]]:
    pages = {}
    for path in sorted(site.rglob("*.html")):
        html = path.read_text(encoding="utf-8")
        text = PageText()
        text.feed(html)
        pages[path.relative_to(site).as_posix()] = (html, text)
    return pages


@pytest.fixture(scope="module")
def pages(site: Path) -> dict[str, tuple[str, PageText]]:
    found = _pages(site)
    assert {"index.html", "theory/index.html", "api/viewer/index.html"} <= set(found)
    return found


def test_no_raw_sphinx_role(pages: dict[str, tuple[str, PageText]]) -> None:
    raw = {name: ROLE.findall(html) for name, (html, _) in pages.items() if ROLE.search(html)}
    assert not raw, f"Sphinx roles shown raw: {raw}"


ROLE_LINK = re.compile(r'<a class="autorefs autorefs-internal"[^>]*href="(?P<href>[^"]*)"[^>]*><code>(?P<text>[^<]*)</code></a>')


def test_roles_became_links(site: Path, pages: dict[str, tuple[str, PageText]]) -> None:
    """Roles to the objects most docstrings mention are links (a role's link is a code span inside
    the link; a type annotation's is the other way round), and every link lands on an anchor."""
    links = [(page, m["href"], m["text"]) for page, (html, _) in pages.items() if page.startswith("api/")
             for m in ROLE_LINK.finditer(html)]
    assert len(links) > 100
    for name in ("solve_static", "simulate", "Trajectory", "Cable", "Mesh"):
        hits = [href for _, href, text in links
                if text.removesuffix("()").rsplit(".", 1)[-1] == name and href.endswith("." + name)]
        assert hits, f"no role links to {name}"
    for page, href, text in links:
        path, _, anchor = href.partition("#")
        target = (site / page).parent / path / "index.html" if path else site / page
        assert f'id="{anchor}"' in target.resolve().read_text(encoding="utf-8"), f"{page}: {text} -> {href}"


def test_literal_blocks_and_definition_lists_render(pages: dict[str, tuple[str, PageText]]) -> None:
    """No reStructuredText ``::`` or stray fence is left, and the definition lists of the API pages
    (sorofem.io's "Formats": a ``.tet`` entry with a literal block) are lists with code inside."""
    api = {page: html for page, (html, _) in pages.items() if page.startswith("api/")}
    for page, html in api.items():
        assert "::</p>" not in html and "```" not in html, page
    definitions = [d for html in api.values() for d in re.findall(r"<dl>.*?</dl>", html, flags=re.S)]
    assert any('<div class="highlight"><pre>' in d for d in definitions)


def test_no_tex_left_unrendered(pages: dict[str, tuple[str, PageText]]) -> None:
    left = {}
    for name, (_, text) in pages.items():
        hits = RAW_TEX.findall("".join(text.prose))
        if hits:
            left[name] = hits[:5]
    assert not left, f"TeX outside the maths MathJax typesets: {left}"
    assert pages["theory/index.html"][1].maths > 20  # the check above looked at a page full of maths


def test_pages_with_maths_load_the_bundled_mathjax(site: Path, pages: dict[str, tuple[str, PageText]]) -> None:
    assert (site / MATHJAX).stat().st_size > 1_000_000  # the whole of tex-svg-full.js, not a stub
    assert (site / "assets/mathjax/LICENSE").is_file()
    with_maths = [name for name, (_, text) in pages.items() if text.maths]
    assert "theory/index.html" in with_maths
    for name in with_maths:
        scripts = [src for kind, src in pages[name][1].resources if kind == "script"]
        local = [(site / name).parent.joinpath(src).resolve() for src in scripts]
        assert (site / MATHJAX).resolve() in local, f"{name} does not load {MATHJAX}: {scripts}"
        config = scripts.index(next(s for s in scripts if s.endswith("js/mathjax-config.js")))
        assert config < scripts.index(next(s for s in scripts if s.endswith(MATHJAX))), name


def test_nothing_is_loaded_from_another_host(site: Path, pages: dict[str, tuple[str, PageText]]) -> None:
    external = {name: [r for r in text.resources if EXTERNAL.match(r[1])] for name, (_, text) in pages.items()}
    external = {name: found for name, found in external.items() if found}
    assert not external, f"pages loading resources from other hosts: {external}"
    for page, (_, text) in pages.items():
        for kind, src in text.resources:
            path = src.split("?")[0]
            # 404.html links from the site's root, the others relative to themselves.
            target = (site / path.lstrip("/")) if path.startswith("/") else (site / page).parent / path
            assert target.resolve().is_file(), f"{page}: {kind} {src} is not in the site"
    for css in site.rglob("*.css"):
        imported = re.findall(r"(?:@import\s+|url\()\s*['\"]?((?:[a-z]+:)?//[^'\")\s]+)", css.read_text(errors="replace"))
        assert not imported, f"{css.relative_to(site)} loads {imported}"
