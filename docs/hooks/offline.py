"""MkDocs hook: the site carries everything its pages load, so that it reads offline.

* MathJax 3.2 (TeX input, SVG output, every TeX extension in one file: no fonts and no later
  downloads) from the ``django-static-mathjax`` wheel, an unmodified copy of MathJax's own
  ``es5/`` build, at ``assets/mathjax/`` with its licence. ``mkdocs.yml`` loads it after
  ``js/mathjax-config.js``.
* The stylesheet of the code blocks, which Pygments highlights at build time
  (``pymdownx.highlight``), at ``css/pygments.css``: the theme's highlight.js would come from a CDN.

Nothing is fetched at build time; the files come from installed packages (the ``docs`` extra).
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, distribution
from pathlib import Path

from mkdocs.structure.files import File, Files
from pygments.formatters import HtmlFormatter

MATHJAX_DISTRIBUTION = "django-static-mathjax"
MATHJAX_SOURCE = "mathjax/static/mathjax"
MATHJAX_FILES = {"es5/tex-svg-full.js": "assets/mathjax/tex-svg-full.js", "LICENSE": "assets/mathjax/LICENSE"}
PYGMENTS_CSS = "css/pygments.css"
PYGMENTS_STYLE = "default"


def mathjax_dir() -> Path:
    """MathJax's folder inside the installed ``django-static-mathjax``."""
    try:
        root = Path(str(distribution(MATHJAX_DISTRIBUTION).locate_file(MATHJAX_SOURCE)))
    except PackageNotFoundError:
        raise RuntimeError(
            f"the documentation bundles MathJax from the package {MATHJAX_DISTRIBUTION!r}, which is not installed: "
            "pip install the 'docs' extra (make docs does)"
        ) from None
    missing = [name for name in MATHJAX_FILES if not (root / name).is_file()]
    if missing:
        raise RuntimeError(f"{MATHJAX_DISTRIBUTION}: expected {missing} under {root}")
    return root


def on_files(files: Files, config) -> Files:  # noqa: ANN001 - MkDocs hook signature
    root = mathjax_dir()
    for source, target in MATHJAX_FILES.items():
        files.append(File.generated(config, target, abs_src_path=str(root / source)))
    css = HtmlFormatter(style=PYGMENTS_STYLE).get_style_defs(".highlight")
    files.append(File.generated(config, PYGMENTS_CSS, content=css))
    return files
