"""The JSON Schema of scene files: generated from the validator's own definitions, committed as
docs/scene.schema.json, accepted by every scene we ship or test, and `sorofem schema`.

Validation against the schema uses the `jsonschema` package when it is installed; a small
built-in validator of the keywords the generator emits checks the same without it.
"""

from __future__ import annotations

import ast
import copy
import json
import math
import re
import tomllib
from pathlib import Path
from typing import Any

import pytest
from ci import missing_in_ci

import sorofem as sf
from sorofem import scene as scene_module
from sorofem.cli import main

ROOT = Path(__file__).resolve().parent.parent
COMMITTED = ROOT / "docs" / "scene.schema.json"
REGENERATE = "make generate"

#: A scene that uses every table of the schema (each selection in its table form).
FULL_SCENE = """\
[mesh]
box = { size = [0.1, 0.02, 0.02], cells = [4, 1, 1], origin = [0, 0, 0] }
scale = 1.0
axes = ["x", "y", "z"]

[material]
youngs_modulus = 66e3
poisson_ratio = 0.45
density = 1080

[[material.region]]
name = "tip"
box = { min = [0.075, -1, -1], max = [1, 1, 1] }
youngs_modulus = 132e3

[[material.region]]
cells = [0, 1]
shear_modulus = 30e3
density = 1200

[formulation]
kind = "standard"
volumetric = "log"
pressure_mass = "consistent"

[[fixed]]
box = { min = [-1e-9, -1, -1], max = [1e-9, 1, 1] }
displacement = [0, 0, 0]

[loads]
gravity = [0, 0, -9.81]
forces = [{ box = { min = [0.099, -1, -1], max = [1, 1, 1] }, force = [0, 0, -0.01] }]

[solver]
tolerance = 1e-8
max_iterations = 50
load_steps = 1

[[cable]]
start = [0, 0.01, 0.01]
direction = [1, 0, 0]
length = 0.1
divisions = 4
stiffness = 1e4
actuation = 1.0
transition = 1e-3
anchor_first = false
snap_tolerance = 0.0
outside = "error"
free_node_mass = 0.0

[[obstacle]]
plane = { point = [0, 0, -0.01], normal = [0, 0, 1] }
friction = 0.3
path = [[0.0, 0, 0, 0], [0.02, 0, 0, -0.001]]

[[obstacle]]
sphere = { center = [0.05, 0.01, 0.05], radius = 0.02 }

[[obstacle]]
box = { min = [0.11, -0.01, -0.01], max = [0.13, 0.03, 0.03] }

[contact]
dhat = 1e-4
friction_slip = 1e-5
friction_velocity = 1e-3

[dynamics]
dt = 0.01
steps = 2
mass_damping = 0.0
stiffness_damping = 0.0
save_every = 1
initial = "rest"
actuation = [[[0.0, 1.0], [0.02, 0.9]]]

[target]
nodes = [19]
positions = [[0.1, 0.02, 0.01]]

[estimate]
params = ["shear_modulus:tip", "lame_lambda"]
x0 = [40e3, 0.2e6]
bounds = [[1e3, 1e6], [1e3, 1e8]]
method = "least-squares"
starts = 0

[control]
cables = [0]
bounds = [[0.5, 1.0]]
method = "l-bfgs-b"

[output]
directory = "results/full"
summary = true
vtu = true
png = true
cables = true
pvd = true
color_by = "von_mises"
"""

#: Scenes whose mistakes the schema itself catches (structure, types, ranges, allowed values).
STRUCTURALLY_BAD = [
    ("[material]\ncolour = 'red'", "unknown key"),
    ("poisson_ratio = 0.45", "poisson_ratio = 0.5"),
    ("poisson_ratio = 0.45", 'poisson_ratio = "0.45"'),
    ("poisson_ratio = 0.45\n", ""),
    ("youngs_modulus = 66e3\n", "youngs_modulus = 66e3\nshear_modulus = 1e4\n"),
    ('kind = "standard"', 'kind = "hybrid"'),
    ("cells = [4, 1, 1]", "cells = [4, 1]"),
    ("cells = [4, 1, 1]", "cells = [4, 0, 1]"),
    ('axes = ["x", "y", "z"]', 'axes = ["x", "y", "w"]'),
    ("scale = 1.0", "scale = 0"),
    ("box = { size", 'file = "beam.vtu"\nbox = { size'),
    ("displacement = [0, 0, 0]", "displacement = [0, 0]"),
    ("tolerance = 1e-8", "tolerance = 0"),
    ("max_iterations = 50", "max_iterations = 2.5"),
    ("stiffness = 1e4", "stiffness = 0"),
    ("divisions = 4\n", ""),
    ("length = 0.1", "length = 0.1\npoints = [[0, 0, 0], [1, 0, 0]]"),
    ("transition = 1e-3", "transition = 2.0"),
    ('outside = "error"', 'outside = "drop"'),
    ("[0.02, 0.9]", "[0.02]"),
    ("nodes = [19]", "nodes = [19]\nscale = 2"),
    ("nodes = [19]", "nodes = [19]\npoints = [[0, 0, 0]]"),
    ('"lame_lambda"]', '"bogus"]'),
    ('"shear_modulus:tip"', '"gravity:tip"'),
    ('method = "least-squares"', 'method = "magic"'),
    ("cells = [0, 1]", "cells = [0, 1]\nbox = { min = [0, 0, 0], max = [1, 1, 1] }"),
    ("cells = [0, 1]", "cells = []"),
    ("shear_modulus = 30e3", "shear_modulus = 30e3\npoisson_ratio = 0.3"),
    ('name = "tip"', 'name = "my tip"'),
    ("[[fixed]]", "[fixed]"),
    ("friction = 0.3", "friction = -0.3"),
    ("plane = { point", "sphere = { center = [0, 0, -1], radius = 0.1 }\nplane = { point"),
    ("dhat = 1e-4", "dhat = 0"),
    ('color_by = "von_mises"', 'color_by = "stress"'),
    ("png = true", "png = 1"),
    ('directory = "results/full"', "directory = 3"),
    ("[output]\nformat = 'vtk'", "unknown key"),
]


def _bad(old: str, new: str) -> str:
    if new == "unknown key":  # old is "[table]\nkey = value": add the key to the table
        table, line = old.split("\n")
        return FULL_SCENE.replace(table + "\n", old + "\n", 1)
    assert old in FULL_SCENE, old
    return FULL_SCENE.replace(old, new, 1)


# ---------------------------------------------------------------------------
# Where scene texts are: examples, docs, the scene docstring, the tests' own scenes


def _toml_blocks(markdown: str) -> list[str]:
    """Literal ```toml blocks that are whole scenes (not includes, not fragments)."""
    blocks = re.findall(r"```toml\n(.*?)```", markdown, flags=re.S)
    return [b for b in blocks if "--8<--" not in b and all(
        re.search(rf"^{re.escape(header)}", b, flags=re.M) for header in ("[mesh]", "[material]", "[[fixed]]"))]


def _test_scene_texts() -> dict[str, str]:
    """Module-level string constants of tests/*.py that are whole scenes."""
    found = {}
    for file in sorted((ROOT / "tests").glob("*.py")):
        for node in ast.parse(file.read_text(encoding="utf-8")).body:
            if isinstance(node, ast.Assign) and isinstance(node.value, ast.Constant) and isinstance(node.value.value, str):
                text = node.value.value
                if re.search(r"^\[mesh\]", text, flags=re.M):
                    found[f"{file.name}:{node.targets[0].id}"] = text  # type: ignore[attr-defined]
    return found


def _docstring_schema() -> str:
    match = re.search(r"Schema\n-+\n::\n\n(.*?)\n\S", scene_module.__doc__ or "", flags=re.S)
    assert match, "no Schema block in sorofem.scene's docstring"
    return "\n".join(line[4:] for line in match.group(1).splitlines())


def _all_scenes() -> dict[str, str]:
    scenes = {str(p.relative_to(ROOT)): p.read_text(encoding="utf-8")
              for folder in ("examples", "docs") for p in sorted((ROOT / folder).rglob("*.toml"))}
    for page in [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]:
        for i, block in enumerate(_toml_blocks(page.read_text(encoding="utf-8"))):
            scenes[f"{page.relative_to(ROOT)} (toml block {i})"] = block
    scenes["sorofem.scene docstring"] = _docstring_schema()
    scenes.update(_test_scene_texts())
    return scenes


SCENES = _all_scenes()


def test_scene_sources_are_found():
    names = " ".join(SCENES)
    for expected in ("examples/scenes/cantilever.toml", "conftest.py:BOX_SCENE", "test_cables.py:CABLE_SCENE",
                     "test_scene_schema.py:FULL_SCENE", "docs/scene.md", "README.md", "docstring"):
        assert expected in names, expected


def test_full_scene_is_valid():
    scene = sf.Scene.from_toml(FULL_SCENE, ROOT / "full.toml")
    assert set(scene.regions) == {"tip"} and scene.dynamics is not None and scene.control is not None
    assert scene.output["directory"] == ROOT / "results" / "full" and scene.output["color_by"] == "von_mises"


# ---------------------------------------------------------------------------
# The committed file


def test_committed_schema_is_current():
    assert COMMITTED.is_file(), f"{COMMITTED} is missing: run `{REGENERATE}`"
    assert COMMITTED.read_text(encoding="utf-8") == scene_module.schema_text(), (
        f"docs/scene.schema.json differs from sorofem.scene.json_schema(): regenerate it with `{REGENERATE}`"
    )


def test_generated_copies_are_current():
    """README.md's key table and the annotated example in sorofem.scene's docstring are generated
    from the same spec as the schema (sorofem.scene.generate)."""
    from sorofem.scene import generate

    stale = [str(path.relative_to(ROOT)) for path, text in generate.render(ROOT).items()
             if path.read_text(encoding="utf-8") != text]
    assert not stale, f"generated from the scene spec but stale: {stale}; regenerate them with `{REGENERATE}`"


def test_schema_header():
    schema = scene_module.json_schema()
    assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    assert schema["type"] == "object" and schema["additionalProperties"] is False
    # [[fixed]] is optional: a body may rest on [[obstacle]] entries instead (checked on load).
    assert set(schema["required"]) == {"mesh", "material"}
    json.dumps(schema, allow_nan=False)  # plain JSON


# ---------------------------------------------------------------------------
# The schema lists exactly the keys the validator accepts


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, list):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    return "{ " + ", ".join(f"{k} = {_toml_value(v)}" for k, v in value.items()) + " }"


def _dump(data: dict[str, Any]) -> str:
    """TOML of a dict, every table inline (enough for scenes)."""
    return "".join(f"{k} = {_toml_value(v)}\n" for k, v in data.items())


def _object_paths(schema: dict[str, Any], path: str = "") -> dict[str, set[str]]:
    """Dotted path (``cable[0]`` for array items) -> property names, for every object of the schema."""
    out = {}
    if "properties" in schema:
        out[path] = set(schema["properties"])
        for name, sub in schema["properties"].items():
            out.update(_object_paths(sub, f"{path}.{name}" if path else name))
    if isinstance(schema.get("items"), dict):
        out.update(_object_paths(schema["items"], f"{path}[0]"))
    return out


def _at(data: Any, path: str) -> Any:
    """The table at a schema path; ``[0]`` stands for the first entry of an array of tables that
    has the rest of the path (an [[obstacle]] entry holds one of plane, sphere, box or mesh)."""
    parts = [p for p in re.split(r"\.|(\[\d+\])", path) if p]
    if not parts:
        return data
    head, rest = parts[0], ".".join(parts[1:]).replace(".[", "[")
    if head.startswith("["):
        for item in data:
            try:
                return _at(item, rest)
            except KeyError:
                continue
        raise KeyError(path)
    return _at(data[head], rest)


def test_schema_lists_exactly_the_keys_the_validator_accepts(tmp_path):
    """At every table of the schema, an unknown key is rejected by the validator, which names the
    key and lists as allowed exactly the schema's properties there."""
    paths = _object_paths(scene_module.json_schema())
    assert {"", "mesh", "mesh.box", "material", "material.region[0]", "material.region[0].box", "fixed[0]",
            "fixed[0].box", "loads.forces[0]", "loads.forces[0].box", "cable[0]", "dynamics", "target",
            "estimate", "control", "output", "obstacle[0].plane", "obstacle[0].sphere", "obstacle[0].box",
            "obstacle[0].mesh", "contact"} <= set(paths)
    full = tomllib.loads(FULL_SCENE)
    # A mesh obstacle needs its file: a tetrahedron beside the scene, apart from the beam.
    (tmp_path / "tetra.obj").write_text("v 0.2 0 0\nv 0.3 0 0\nv 0.2 0.1 0\nv 0.2 0 0.1\n"
                                        "f 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n")
    full["obstacle"].append({"mesh": {"file": "tetra.obj", "scale": 1.0, "one_sided": False}})
    sf.Scene.from_toml(_dump(full), tmp_path / "s.toml")  # the inline rewrite is valid as it is
    for path, properties in paths.items():
        data = copy.deepcopy(full)
        if path.startswith("target.contact_force"):  # [target] is on positions, or on a force
            data["target"] = {"contact_force": {"obstacle": 0, "force": 0.1}}
        _at(data, path)["not_a_key"] = 1
        with pytest.raises(sf.SceneError) as info:
            sf.Scene.from_toml(_dump(data), tmp_path / "s.toml")
        key = f"{path}.not_a_key" if path else "not_a_key"
        assert re.sub(r"\[\d+\]", "[0]", info.value.key) == key, (path, str(info.value))
        allowed = re.search(r"\(allowed: (.*)\)$", info.value.message).group(1).split(", ")
        assert set(allowed) == properties, path


# ---------------------------------------------------------------------------
# A small validator of the JSON Schema keywords the generator emits (no dependency)

_KNOWN = {"$schema", "title", "description", "default", "type", "properties", "required", "additionalProperties",
          "items", "prefixItems", "minItems", "maxItems", "enum", "pattern", "minimum", "exclusiveMinimum",
          "maximum", "exclusiveMaximum", "anyOf", "allOf", "not"}
_TYPES = {
    "object": lambda v: isinstance(v, dict),
    "array": lambda v: isinstance(v, list),
    "string": lambda v: isinstance(v, str),
    "boolean": lambda v: isinstance(v, bool),
    "integer": lambda v: isinstance(v, int) and not isinstance(v, bool),
    "number": lambda v: isinstance(v, (int, float)) and not isinstance(v, bool),
}


def _keywords(schema: Any) -> set[str]:
    if isinstance(schema, list):
        return set().union(*(_keywords(s) for s in schema)) if schema else set()
    if not isinstance(schema, dict):
        return set()
    out = set(schema)
    for name, sub in schema.items():
        if name == "properties":
            out |= set().union(*(_keywords(s) for s in sub.values()))
        elif name in ("items", "not", "anyOf", "allOf", "prefixItems"):
            out |= _keywords(sub)
    return out


def _errors(schema: dict[str, Any], value: Any, path: str = "$") -> list[str]:
    """Draft 2020-12 semantics for the keywords in _KNOWN."""
    errors: list[str] = []
    kind = schema.get("type")
    if kind is not None and not _TYPES[kind](value):
        return [f"{path}: not of type {kind}"]
    if "enum" in schema and value not in schema["enum"]:
        errors.append(f"{path}: {value!r} not in enum")
    if "pattern" in schema and isinstance(value, str) and not re.search(schema["pattern"], value):
        errors.append(f"{path}: {value!r} does not match {schema['pattern']}")
    if _TYPES["number"](value):
        for name, ok in (("minimum", lambda a, b: a >= b), ("exclusiveMinimum", lambda a, b: a > b),
                         ("maximum", lambda a, b: a <= b), ("exclusiveMaximum", lambda a, b: a < b)):
            if name in schema and not ok(value, schema[name]):
                errors.append(f"{path}: {value} violates {name} {schema[name]}")
    if isinstance(value, dict):
        props = schema.get("properties", {})
        for name in schema.get("required", []):
            if name not in value:
                errors.append(f"{path}: {name!r} is required")
        for name, item in value.items():
            if name in props:
                errors += _errors(props[name], item, f"{path}.{name}")
            elif schema.get("additionalProperties") is False:
                errors.append(f"{path}: additional property {name!r}")
    if isinstance(value, list):
        if len(value) < schema.get("minItems", 0) or len(value) > schema.get("maxItems", math.inf):
            errors.append(f"{path}: {len(value)} items")
        prefix = schema.get("prefixItems", [])
        for i, item in enumerate(value):
            sub = prefix[i] if i < len(prefix) else schema.get("items")
            if sub is not None:
                errors += _errors(sub, item, f"{path}[{i}]")
    if "anyOf" in schema and not any(not _errors(s, value, path) for s in schema["anyOf"]):
        errors.append(f"{path}: matches none of anyOf")
    for sub in schema.get("allOf", []):
        errors += _errors(sub, value, path)
    if "not" in schema and not _errors(schema["not"], value, path):
        errors.append(f"{path}: matches a 'not' schema")
    return errors


def test_builtin_validator_knows_every_keyword_the_schema_uses():
    unknown = _keywords(scene_module.json_schema()) - _KNOWN
    assert not unknown, f"teach _errors() these keywords: {sorted(unknown)}"


@pytest.mark.parametrize("name", sorted(SCENES))
def test_every_scene_is_valid_under_the_schema(name):
    errors = _errors(scene_module.json_schema(), tomllib.loads(SCENES[name]))
    assert not errors, f"{name}: {errors}"


@pytest.mark.parametrize("old, new", STRUCTURALLY_BAD, ids=[n[:40] for _, n in STRUCTURALLY_BAD])
def test_schema_and_validator_reject_structural_mistakes(tmp_path, old, new):
    text = _bad(old, new)
    assert _errors(scene_module.json_schema(), tomllib.loads(text)), "the schema accepts it"
    with pytest.raises(sf.SceneError):
        sf.Scene.from_toml(text, tmp_path / "s.toml")


# ---------------------------------------------------------------------------
# The same with the jsonschema package (a test dependency: `make test` installs it)


def test_jsonschema_package_agrees():
    try:
        import jsonschema
    except ImportError:
        missing_in_ci("the jsonschema package is not installed (pip install jsonschema, or `make test`)")
    schema = scene_module.json_schema()
    jsonschema.Draft202012Validator.check_schema(schema)
    validator = jsonschema.Draft202012Validator(schema)
    for name, text in SCENES.items():
        errors = [f"{'/'.join(map(str, e.absolute_path))}: {e.message}" for e in validator.iter_errors(tomllib.loads(text))]
        assert not errors, f"{name}: {errors}"
    for old, new in STRUCTURALLY_BAD:
        assert not validator.is_valid(tomllib.loads(_bad(old, new))), new


# ---------------------------------------------------------------------------
# sorofem schema


def test_cli_schema_prints_the_schema(capsys):
    assert main(["schema"]) == 0
    captured = capsys.readouterr()
    assert json.loads(captured.out) == scene_module.json_schema() and captured.err == ""


def test_cli_schema_out_never_overwrites_without_force(tmp_path, capsys):
    out = tmp_path / "sub" / "scene.schema.json"
    assert main(["schema", "--out", str(out)]) == 0
    assert out.read_text(encoding="utf-8") == scene_module.schema_text()
    assert str(out) in capsys.readouterr().out
    out.write_text("mine", encoding="utf-8")
    assert main(["schema", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: --out:") and "exists" in err[0] and "--force" in err[0]
    assert out.read_text(encoding="utf-8") == "mine"
    assert main(["schema", "--out", str(out), "--force"]) == 0
    assert out.read_text(encoding="utf-8") == scene_module.schema_text()


@pytest.mark.parametrize("argv, words", [
    (["schema", "--force"], ["--force", "--out"]),
    (["schema", "--out", "{tmp}"], ["--out", "folder"]),
    (["schema", "--bogus"], ["unrecognized arguments"]),
])
def test_cli_schema_bad_arguments_exit_2(tmp_path, capsys, argv, words):
    assert main([a.replace("{tmp}", str(tmp_path)) for a in argv]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: "), err
    for word in words:
        assert word in err[0]


# ---------------------------------------------------------------------------
# The README's table of every key (also the docs' "Every key") keeps up with the schema


def test_readme_key_table_lists_every_key():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    table = text[text.index("Every key:"):text.index("Validation is strict")]
    schema = scene_module.json_schema()
    missing = [f"[{name}]" for name in schema["properties"] if f"`[{name}]`" not in table and f"`[[{name}]]`" not in table]
    for path, properties in _object_paths(schema).items():
        # Sections and array entries; the tables inside them (box = {min, max}) are described inline.
        if path == "" or ("." in path.replace("[0]", "") and not path.endswith("[0]")):
            continue
        dotted = path.replace("[0]", "[i]")
        for name in properties:
            forms = (f"`{dotted}.{name}`", f"`[[{dotted}.{name}]]`", f"`.{name}`", f"{name} = ")
            if not any(form in table for form in forms):
                missing.append(f"{dotted}.{name}")
    assert not missing, f"README.md's 'Every key' table does not mention: {missing}"
