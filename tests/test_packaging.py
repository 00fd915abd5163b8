"""What a user installs: the package's metadata, its declared dependencies and the wheel.

The metadata checks run with every ``make test``. The wheel check (marker ``wheel``, run by
``make test-wheel`` and CI) installs the wheel of ``make wheel`` into a fresh virtual environment
with no Rust toolchain on ``PATH``, pip allowed binary wheels only, and runs the ``sorofem``
command it installed on ``examples/scenes/cantilever.toml``.
"""

from __future__ import annotations

import ast
import json
import os
import re
import shutil
import subprocess
import sys
import tomllib
from importlib.metadata import packages_distributions
from pathlib import Path

import pytest
from packaging.requirements import Requirement

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "python" / "sorofem"
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
SCENE = ROOT / "examples" / "scenes" / "cantilever.toml"
RUST_TOOLS = ("cargo", "rustc", "rustup", "maturin")
# Import names whose distribution has another name (when it is not installed to ask).
DISTRIBUTION_OF = {"mpl_toolkits": "matplotlib", "skfem": "scikit-fem"}


def _requirements(extra: str | None = None) -> dict[str, Requirement]:
    listed = PYPROJECT["dependencies"] if extra is None else PYPROJECT["optional-dependencies"][extra]
    return {Requirement(r).name.lower(): Requirement(r) for r in listed}


def _third_party_imports() -> dict[str, set[str]]:
    """Top-level names of the modules the package imports (module- and function-level), other
    than the standard library and the package itself, each with the submodules importing it."""
    found: dict[str, set[str]] = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        module = path.relative_to(PACKAGE).parts[0].removesuffix(".py")
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            else:
                continue
            for name in names:
                top = name.split(".")[0]
                if top not in sys.stdlib_module_names and top != "sorofem":
                    found.setdefault(top, set()).add(module)
    return found


def _distribution(import_name: str) -> str:
    installed = packages_distributions().get(import_name)
    return (installed[0] if installed else DISTRIBUTION_OF.get(import_name, import_name)).lower()


def test_every_import_is_declared() -> None:
    """Each third-party module the package imports is a dependency, or belongs to the extra of
    the module that imports it (the viewer's trimesh was once used without being declared)."""
    runtime = _requirements()
    extras = {name: _requirements(name) for name in PYPROJECT["optional-dependencies"]}
    module_extra = {"viewer": "viewer", "meshing": "mesh", "static": "pyvista", "sweeps": "cluster"}
    missing = []
    for top, modules in _third_party_imports().items():
        distribution = _distribution(top)
        for module in modules:
            declared = set(runtime) | set(extras.get(module_extra.get(module, ""), {}))
            if distribution not in declared:
                missing.append(f"sorofem.{module} imports {top} ({distribution})")
    assert not missing, missing
    assert {"viser", "trimesh"} <= set(extras["viewer"])


def test_libraries_whose_details_the_code_uses_have_upper_bounds() -> None:
    """The viewer calls viser's scene and GUI API (changed between 1.0 and 1.1), the mesher
    pytetwild's; the documentation build uses Griffe's and mkdocstrings' extension points."""
    bounded = {**_requirements("viewer"), **_requirements("mesh"), **_requirements("docs")}
    for name, requirement in bounded.items():
        uppers = [spec for spec in requirement.specifier if spec.operator in ("<", "<=", "==", "~=")]
        assert uppers, f"{requirement}: no upper bound"


def test_metadata_for_an_index() -> None:
    urls = PYPROJECT["urls"]
    assert {"Homepage", "Source", "Issues", "Changelog"} <= set(urls)
    assert all(url.startswith("https://") for url in urls.values())
    classifiers = PYPROJECT["classifiers"]
    assert "License :: OSI Approved :: BSD License" in classifiers
    versions = {c.rsplit(" :: ", 1)[1] for c in classifiers if re.fullmatch(r"Programming Language :: Python :: 3\.\d+", c)}
    assert min(versions, key=lambda v: tuple(map(int, v.split(".")))) == PYPROJECT["requires-python"].lstrip(">=")
    # The abi3 wheel needs the stable ABI of the oldest version it claims.
    binding = (ROOT / "crates" / "sorofem-py" / "Cargo.toml").read_text(encoding="utf-8")
    assert f'"abi3-py{PYPROJECT["requires-python"].lstrip(">=").replace(".", "")}"' in binding


def test_changelog_follows_keep_a_changelog() -> None:
    text = (ROOT / "CHANGELOG.md").read_text(encoding="utf-8")
    headings = re.findall(r"^## \[([^\]]+)\](?: - (\d{4}-\d{2}-\d{2}))?$", text, flags=re.M)
    assert headings and headings[0] == ("Unreleased", "")
    version = re.search(r'^version = "([^"]+)"', (ROOT / "Cargo.toml").read_text(encoding="utf-8"), flags=re.M)[1]
    released = [v for v, date in headings[1:] if date]
    assert version in released, f"Cargo.toml's version {version} has no dated section in CHANGELOG.md"
    sections = set(re.findall(r"^### (\w+)$", text, flags=re.M))
    assert sections <= {"Added", "Changed", "Deprecated", "Removed", "Fixed", "Security"}, sections
    for name, _ in headings:
        assert re.search(rf"^\[{re.escape(name)}\]: https://", text, flags=re.M), f"no link for [{name}]"


def test_install_instructions_name_what_works() -> None:
    """sorofem is not on PyPI: ``pip install "sorofem[viewer]"`` fails. The README, the
    documentation pages, the package's hints (viewer, mesher) and the examples say what works
    (from a checkout, or a wheel of ``make wheel``)."""
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md")), *sorted((ROOT / "python").rglob("*.py")),
             *sorted((ROOT / "examples").rglob("*.py"))]
    from_index = re.compile(r"pip install\s+['\"]?sorofem\b")
    wrong = [f"{p.relative_to(ROOT)}: {m[0]}" for p in pages for m in from_index.finditer(p.read_text(encoding="utf-8"))]
    assert not wrong, wrong
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert 'pip install ".[viewer]"' in readme and "make wheel" in readme


# ---------------------------------------------------------------------------
# The wheel, installed where there is no Rust


def _path_without_rust(bin_dir: Path) -> str:
    kept = [d for d in os.environ.get("PATH", "").split(os.pathsep)
            if d and not any((Path(d) / tool).exists() for tool in RUST_TOOLS)]
    return os.pathsep.join([str(bin_dir), *kept])


@pytest.mark.wheel
def test_wheel_installs_and_runs_without_rust(tmp_path: Path) -> None:
    import sorofem as sf

    wheels = sorted((ROOT / "dist").glob("sorofem-*.whl"))
    assert len(wheels) == 1, f"expected the one wheel of `make wheel` in dist/, found {wheels}"
    wheel = wheels[0]
    assert re.search(r"-cp311-abi3-", wheel.name), wheel.name

    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=300)
    bin_dir = venv / "bin"
    env = {key: value for key, value in os.environ.items()
           if key not in ("VIRTUAL_ENV", "PYTHONPATH", "PYTHONHOME", "CARGO_HOME", "RUSTUP_HOME")}
    env.update(PATH=_path_without_rust(bin_dir), PIP_DISABLE_PIP_VERSION_CHECK="1")
    for tool in RUST_TOOLS:
        assert shutil.which(tool, path=env["PATH"]) is None, f"{tool} is still on PATH"

    def run(*args: str | Path) -> subprocess.CompletedProcess[str]:
        return subprocess.run([str(a) for a in args], cwd=tmp_path, env=env, capture_output=True, text=True,
                              timeout=600)

    # Binary wheels only: nothing may be compiled, so nothing can need the toolchain.
    install = run(bin_dir / "python", "-m", "pip", "install", "--quiet", "--only-binary=:all:", wheel)
    assert install.returncode == 0, install.stdout + install.stderr
    where = run(bin_dir / "python", "-c", "import sorofem._core as c; print(c.__file__)")
    assert where.returncode == 0, where.stderr
    assert Path(where.stdout.strip()).resolve().is_relative_to(venv.resolve()), where.stdout

    out = tmp_path / "out"
    solved = run(bin_dir / "sorofem", "run", SCENE, "--out", out, "--quiet")
    assert solved.returncode == 0, solved.stdout + solved.stderr
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    assert summary["converged"] is True and summary["n_tets"] == 192
    assert summary["residual_norm"] <= summary["solver_options"]["tolerance"]
    assert (out / "result.vtu").stat().st_size > 0
    # The same equilibrium as the build under test (same code, same machine).
    reference = sf.Scene.load(SCENE).solve()
    assert summary["newton_iterations"] == reference.report.iterations
    assert summary["max_displacement"] == pytest.approx(reference.max_displacement, rel=1e-12)
