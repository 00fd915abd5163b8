"""Issue 20, lost or corrupted work: outputs are written atomically (never half a file, never
through another hard link), a full disk or a file-size limit is a clean error naming the file,
history records are durable whole lines, and every run marks its files."""

from __future__ import annotations

import errno
import json
import os
import resource
import subprocess
import sys
from pathlib import Path

import meshio
import numpy as np
import pytest

import sorofem as sf
from sorofem import _files
from sorofem.cli import EXIT_INPUT, EXIT_OK, EXIT_OUTPUT, main
from tests.conftest import BOX_SCENE, REPO_ROOT

DYNAMIC_SCENE = BOX_SCENE.replace("[solver]", "[dynamics]\ndt = 0.01\nsteps = 4\n\n[solver]")


def leftovers(folder: Path) -> list[str]:
    """Temporary files a write left behind (there must be none)."""
    return sorted(p.name for p in folder.rglob(".*.tmp-*"))


def test_atomic_path_keeps_the_old_file_when_the_writer_fails(tmp_path):
    path = tmp_path / "data.txt"
    path.write_text("old")
    with pytest.raises(RuntimeError):
        with _files.atomic_path(path) as temporary:
            temporary.write_text("half of the new")
            raise RuntimeError("writer failed")
    assert path.read_text() == "old" and leftovers(tmp_path) == []


def test_writes_replace_a_hard_link_instead_of_writing_through_it(tmp_path, capsys):
    """Issue 20 item 14: DIR/summary.json hard-linked to the scene must not overwrite the scene."""
    scene = tmp_path / "scene.toml"
    scene.write_text(BOX_SCENE)
    out = tmp_path / "out"
    out.mkdir()
    for name in ("summary.json", "result.vtu", "shape.png"):
        os.link(scene, out / name)
    assert main(["run", str(scene), "--out", str(out), "--quiet"]) == EXIT_OK
    assert scene.read_text() == BOX_SCENE and os.stat(scene).st_nlink == 1
    assert json.loads((out / "summary.json").read_text())["complete"] is True


@pytest.mark.parametrize("code", [errno.ENOSPC, errno.EDQUOT, errno.EROFS])
def test_full_disk_is_a_clean_output_error_and_keeps_the_old_file(tmp_path, monkeypatch, code):
    path = tmp_path / "summary.json"
    path.write_text("{}")

    def full(fd):
        raise OSError(code, os.strerror(code))

    monkeypatch.setattr(_files.os, "fsync", full)
    with pytest.raises(sf.OutputError) as info:
        _files.write_text(path, "new")
    assert str(path) in str(info.value) and info.value.errno == code
    assert path.read_text() == "{}" and leftovers(tmp_path) == []


def test_full_disk_during_a_run_exits_4_naming_the_file(tmp_path, monkeypatch, capsys):
    scene = tmp_path / "scene.toml"
    scene.write_text(BOX_SCENE)
    real = _files.os.replace

    def replace(src, dst):
        if str(dst).endswith("result.vtu"):
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(src, dst)

    monkeypatch.setattr(_files.os, "replace", replace)
    assert main(["run", str(scene), "--out", str(tmp_path / "out"), "--quiet"]) == EXIT_OUTPUT
    err = capsys.readouterr().err
    assert "result.vtu" in err and "no space left" in err and "Traceback" not in err
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["complete"] is False and "no space left" in summary["status"]
    assert not (tmp_path / "out" / "result.vtu").exists() and leftovers(tmp_path) == []


def test_file_size_limit_exits_4_and_leaves_consistent_files(tmp_path):
    """EFBIG from RLIMIT_FSIZE (a tiny file-size limit) in a child process."""
    scene = tmp_path / "scene.toml"
    scene.write_text(BOX_SCENE.replace("cells = [4, 1, 1]", "cells = [12, 3, 3]"))
    out = tmp_path / "out"

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (6000, 6000))

    proc = subprocess.run(
        [sys.executable, "-m", "sorofem.cli", "run", str(scene), "--out", str(out), "--quiet"],
        capture_output=True, text=True, preexec_fn=limit, cwd=REPO_ROOT, timeout=120,
    )
    assert proc.returncode == EXIT_OUTPUT, proc.stderr
    assert "file-size limit" in proc.stderr and "Traceback" not in proc.stderr
    summary = json.loads((out / "summary.json").read_text())  # small enough to be written
    assert summary["complete"] is False
    assert not (out / "result.vtu").exists() and leftovers(tmp_path) == []


def test_an_output_name_that_is_a_folder_or_a_file_in_the_way(tmp_path, capsys):
    scene = tmp_path / "scene.toml"
    scene.write_text(BOX_SCENE)
    (tmp_path / "out" / "result.vtu").mkdir(parents=True)
    assert main(["run", str(scene), "--out", str(tmp_path / "out"), "--quiet"]) == EXIT_OUTPUT
    assert "result.vtu: it is a folder" in capsys.readouterr().err
    (tmp_path / "file").write_text("x")
    assert main(["run", str(scene), "--out", str(tmp_path / "file"), "--quiet"]) == EXIT_INPUT
    assert "not a folder" in capsys.readouterr().err


def test_append_line_cuts_a_failed_record_off(tmp_path, monkeypatch):
    path = tmp_path / "history.jsonl"
    _files.append_line(path, '{"a": 1}')

    def short_write(fd, data):
        os.ftruncate(fd, os.fstat(fd).st_size)  # nothing written yet
        real_write(fd, bytes(data[:5]))
        raise OSError(errno.ENOSPC, "No space left on device")

    real_write = os.write
    monkeypatch.setattr(_files.os, "write", short_write)
    with pytest.raises(sf.OutputError):
        _files.append_line(path, '{"b": 2}')
    assert path.read_text() == '{"a": 1}\n'


def test_torn_history_tail_is_reported_cut_and_resumed(tmp_path):
    """Issue 20 item 10: a crash mid-record leaves a torn last line; resume ignores it, says so,
    and the records it appends start on a line of their own."""
    mesh = sf.Mesh.box(size=(0.1, 0.02, 0.02), cells=(4, 1, 1))
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080))
    body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    goal = sf.solve_static(body, gravity=(0, 0, -9.81), tolerance=1e-12).positions
    tip = mesh.nodes_on_plane((0.1, 0, 0), (1, 0, 0))
    target = sf.Target.nodes(tip, goal[tip])
    path = tmp_path / "history.jsonl"
    full = sf.estimate(body, target, ["shear_modulus"], x0=[15e3], gravity=(0, 0, -9.81), history_path=path)
    lines = path.read_text().splitlines(keepends=True)
    assert len(lines) >= 4
    path.write_text("".join(lines[:3]) + lines[3][: len(lines[3]) // 2])  # killed while writing record 3
    with pytest.warns(sf.inverse.TornHistoryWarning, match="partial record"):
        resumed = sf.estimate(body, target, ["shear_modulus"], x0=[15e3], gravity=(0, 0, -9.81), history_path=path,
                              resume=True)
    assert resumed.params["shear_modulus"] == pytest.approx(full.params["shear_modulus"], rel=1e-8)
    records = [json.loads(line) for line in path.read_text().splitlines()]  # every line whole
    assert records[0]["kind"] == "header" and records[-1]["kind"] == "end"


def test_run_ids_mark_every_file_and_stale_outputs_are_reported(tmp_path, capsys):
    out = tmp_path / "out"
    scene = tmp_path / "scene.toml"
    scene.write_text(BOX_SCENE.replace("[solver]", "[[cable]]\nstart = [0, 0.01, 0.01]\ndirection = [1, 0, 0]\n"
                                       "length = 0.1\ndivisions = 4\nstiffness = 1e3\nactuation = 0.9\n\n[solver]"))
    assert main(["run", str(scene), "--out", str(out), "--quiet"]) == EXIT_OK
    first = json.loads((out / "summary.json").read_text())
    for name in ("result.vtu", "cables.vtu"):
        assert int(meshio.read(out / name).field_data["sorofem_run_id"][0]) == first["run_id"]
    # The same folder, a scene without cables: cables.vtu is the earlier run's.
    scene.write_text(BOX_SCENE)
    assert main(["run", str(scene), "--out", str(out), "--quiet"]) == EXIT_OK
    second = json.loads((out / "summary.json").read_text())
    assert second["run_id"] != first["run_id"] and second["stale_outputs"] == ["cables.vtu"]
    assert "cables.vtu" in capsys.readouterr().err
    assert int(meshio.read(out / "cables.vtu").field_data["sorofem_run_id"][0]) == first["run_id"]  # told apart


def test_a_second_dynamic_run_never_mixes_frames(tmp_path):
    out = tmp_path / "out"
    scene = tmp_path / "scene.toml"
    scene.write_text(DYNAMIC_SCENE.replace("steps = 4", "steps = 6"))
    assert main(["run", str(scene), "--out", str(out), "--quiet"]) == EXIT_OK
    scene.write_text(DYNAMIC_SCENE)
    assert main(["run", str(scene), "--out", str(out), "--quiet"]) == EXIT_OK
    summary = json.loads((out / "summary.json").read_text())
    frames = sorted((out / "trajectory").iterdir())
    assert len(frames) == 5 == summary["frames"]
    assert all(int(meshio.read(f).field_data["sorofem_run_id"][0]) == summary["run_id"] for f in frames)
    assert f'sorofem_run_id="{summary["run_id"]}"' in (out / "trajectory.pvd").read_text()


def test_no_output_file_holds_nan_or_infinity(tmp_path):
    out = tmp_path / "out"
    scene = tmp_path / "scene.toml"
    scene.write_text(BOX_SCENE)
    assert main(["run", str(scene), "--out", str(out), "--quiet"]) == EXIT_OK
    text = (out / "summary.json").read_text()
    assert "NaN" not in text and "Infinity" not in text
    result = meshio.read(out / "result.vtu")
    arrays = [result.points, *result.point_data.values(), *(a for v in result.cell_data.values() for a in v)]
    assert all(np.all(np.isfinite(a)) for a in arrays)


def test_write_result_refuses_non_finite_fields(tmp_path):
    mesh = sf.Mesh.box(size=(0.1, 0.02, 0.02), cells=(2, 1, 1))
    body = sf.Body(mesh, sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.45, density=1080))
    body.fix(mesh.nodes_on_plane((0, 0, 0), (1, 0, 0)))
    result = sf.solve_static(body, gravity=(0, 0, -9.81))
    result._fields["von_mises"] = np.full(mesh.n_tets, np.inf)
    with pytest.raises(sf.InputError, match="von_mises"):
        sf.io.write_result(tmp_path / "r.vtu", result)
    assert not (tmp_path / "r.vtu").exists()
