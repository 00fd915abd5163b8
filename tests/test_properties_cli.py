"""Property-based: the command line with any arguments. ``sorofem`` answers every argument
list with a documented exit code (0; 2 with one ``error:`` line; 3; 4), never 1 (a traceback).
``view`` is left out: it serves until stopped."""

from __future__ import annotations

import contextlib
import io

from hypothesis import given, settings
from hypothesis import strategies as st

from sorofem.cli import main
from tests.conftest import BOX_SCENE
from tests.hostile import STRINGS

COMMANDS = ["run", "estimate", "control", "info", "convert", "schema", "--version", "-h", "", "fit-material"]
OPTIONS = ["--out", "--quiet", "--json", "--scale", "--force", "--history", "--resume", "--port", "--trajectory"]


@settings(max_examples=120)
@given(data=st.data())
def test_any_argument_list_gets_a_documented_exit_code(tmp_path_factory, data):
    folder = tmp_path_factory.mktemp("cli")
    scene = folder / "scene.toml"
    scene.write_text(BOX_SCENE)
    mesh = folder / "mesh.tet"
    mesh.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nt 0 1 2 3\n")
    tokens = st.one_of(
        st.sampled_from(OPTIONS), STRINGS, st.sampled_from([str(scene), str(mesh), str(folder), str(folder / "out"),
                                                           str(folder / "new.vtu"), "-1", "0", "1e308", "nan"]),
    )
    argv = [data.draw(st.sampled_from(COMMANDS), label="command"), *data.draw(st.lists(tokens, max_size=5))]
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = main([a for a in argv if a != ""])
    assert code in (0, 2, 3, 4), (code, err.getvalue())
    assert "Traceback" not in err.getvalue(), err.getvalue()
