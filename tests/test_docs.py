"""The documentation's Python code blocks run, and what the site includes exists.

The site itself is built by `make docs` (`mkdocs build --strict`, in `.ci/run`), not here: the
test suite must not need mkdocs. Every ```python block of a page runs, in order, in one
namespace per page and a temporary working folder; a block right after a line
``<!-- not run: REASON -->`` is skipped.
"""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

import pytest

import sorofem as sf

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
BLOCK = re.compile(r"(<!-- not run:[^>]*-->\s*\n)?```python\n(.*?)\n```", re.S)
PAGES = sorted(p.relative_to(DOCS).as_posix() for p in DOCS.rglob("*.md") if "```python" in p.read_text())


def _hooks():
    spec = importlib.util.spec_from_file_location("docs_includes", DOCS / "hooks" / "includes.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_pages_with_code_are_found() -> None:
    assert {"getting-started.md", "tutorials/simulate.md", "tutorials/actuate.md",
            "tutorials/calibrate.md", "tutorials/control.md"} <= set(PAGES)


@pytest.mark.parametrize("page", PAGES)
def test_code_blocks_run(page: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr("matplotlib.pyplot.show", lambda *a, **k: None, raising=False)
    namespace: dict[str, object] = {"__name__": f"docs:{page}"}
    ran = 0
    for i, match in enumerate(BLOCK.finditer((DOCS / page).read_text(encoding="utf-8"))):
        if match.group(1):
            continue
        code = compile(match.group(2), f"{page} (python block {i})", "exec")
        exec(code, namespace)  # noqa: S102 - the documentation's own examples
        ran += 1
    assert ran > 0


def test_nav_pages_exist() -> None:
    nav = re.findall(r":\s*([\w\-/]+\.md)\s*$", (ROOT / "mkdocs.yml").read_text(), flags=re.M)
    assert len(nav) > 10
    missing = [p for p in nav if not (DOCS / p).is_file()]
    assert not missing, f"pages in mkdocs.yml nav but not in docs/: {missing}"


def test_public_api_has_reference_pages() -> None:
    """Every public name of `sorofem` is rendered on some API page (directly or via its module)."""
    api = "\n".join(p.read_text() for p in (DOCS / "api").glob("*.md"))
    documented = set(re.findall(r"^::: (sorofem[\w.]*)$", api, flags=re.M))
    for name in sf.__all__:
        if name.startswith("__"):
            continue
        obj = getattr(sf, name)
        module = getattr(obj, "__module__", None) or getattr(obj, "__name__", "")
        assert {f"sorofem.{name}", f"{module}.{name}", module} & documented, (
            f"sorofem.{name} ({module}) is on no page under docs/api/"
        )


def test_scene_schema_include_is_complete() -> None:
    from sorofem import scene

    schema = _hooks().scene_schema()
    for key in scene.TOP_KEYS:
        assert re.search(rf"^\[\[?{key}\]\]?", schema.replace("```toml\n", ""), flags=re.M), key


def test_readme_scene_keys_include() -> None:
    text = _hooks().readme_scene_keys()
    assert text.startswith("| key |") and "`solver.load_steps`" in text
    assert "](examples/" not in text  # repository links became code spans


def test_benchmarks_page_includes_the_file() -> None:
    assert '--8<-- "BENCHMARKS.md"' in (DOCS / "benchmarks.md").read_text()
    assert (ROOT / "BENCHMARKS.md").is_file()
