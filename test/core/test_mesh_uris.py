"""The one mesh-URI resolver (manip_kin.core.mesh_uris): collision geometry, the physics model and
its renders find their meshes through it (moved here from test_collision and test_physics_plant)."""

from __future__ import annotations

from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st
from robot_data_files import PANDA, example_robot_data_urdf

from manip_kin.core.mesh_uris import require_mesh_file, resolve_mesh_uri, search_directories


@pytest.fixture
def arm_mesh(tmp_path):
    mesh = tmp_path / "pkgs" / "my_arm" / "meshes" / "link.stl"
    mesh.parent.mkdir(parents=True)
    mesh.write_bytes(b"solid x\nendsolid x\n")
    return mesh


def test_mesh_uris_resolve_through_the_search_path_file_uris_and_relative_paths(tmp_path, arm_mesh):
    mesh = arm_mesh
    search = f"{tmp_path / 'elsewhere'}:{tmp_path / 'pkgs'}"
    assert resolve_mesh_uri("package://my_arm/meshes/link.stl", search) == mesh
    assert resolve_mesh_uri("package://my_arm/meshes/none.stl", search) is None
    assert resolve_mesh_uri("package://other_arm/meshes/link.stl", search) is None
    assert resolve_mesh_uri(f"file://{mesh}") == mesh
    assert resolve_mesh_uri("meshes/link.stl", base_dir=mesh.parents[1]) == mesh
    assert resolve_mesh_uri("https://example.invalid/link.stl", search) is None  # nothing is fetched


def test_mesh_uris_resolve_through_search_path_ament_index_file_and_relative(monkeypatch, tmp_path):
    urdf = example_robot_data_urdf(PANDA)
    share = str(urdf.parents[4])  # <share>/example-robot-data/robots/panda_description/urdf/panda.urdf
    uri = "package://example-robot-data/robots/panda_description/meshes/collision/link3.stl"
    expected = urdf.parents[1] / "meshes" / "collision" / "link3.stl"
    assert require_mesh_file(uri, f"{tmp_path}:{share}").samefile(expected)
    monkeypatch.setenv("AMENT_PREFIX_PATH", str(urdf.parents[5]))  # <prefix>/share/example-robot-data/...
    assert require_mesh_file(uri).samefile(expected)
    assert require_mesh_file(f"file://{expected}").samefile(expected)
    assert require_mesh_file("../meshes/collision/link3.stl", base_dir=urdf.parent).samefile(expected)
    monkeypatch.delenv("AMENT_PREFIX_PATH")
    with pytest.raises(FileNotFoundError, match="not in the ament index"):
        require_mesh_file(uri, str(tmp_path))


def test_a_missing_mesh_is_refused_saying_where_it_was_looked_for(tmp_path, arm_mesh, monkeypatch):
    monkeypatch.delenv("AMENT_PREFIX_PATH", raising=False)
    search = f"{tmp_path / 'elsewhere'}:{tmp_path / 'pkgs'}"
    with pytest.raises(FileNotFoundError) as raised:
        require_mesh_file(" package://my_arm/none.stl", search)
    assert str(raised.value) == (
        f" package://my_arm/none.stl: not found (looked in {tmp_path}/elsewhere/my_arm/none.stl, "
        f"{tmp_path}/pkgs/my_arm/none.stl; package 'my_arm' is not in the ament index (AMENT_PREFIX_PATH)); "
        "set mesh_search_path"
    )
    with pytest.raises(FileNotFoundError, match=r"looked in no mesh_search_path directory"):
        require_mesh_file("package://my_arm/meshes/link.stl")
    with pytest.raises(FileNotFoundError, match=f"no such file {tmp_path}/none.stl"):
        require_mesh_file("none.stl", base_dir=tmp_path)
    with pytest.raises(FileNotFoundError, match=r"^file:///nowhere/x.stl: no such file /nowhere/x.stl$"):
        require_mesh_file("file:///nowhere/x.stl")
    with pytest.raises(FileNotFoundError, match="not fetched"):
        require_mesh_file("https://example.invalid/link.stl")
    for malformed in ("package://my_arm", "package:///meshes/link.stl"):
        with pytest.raises(FileNotFoundError, match="valid: package://<package>/<path in it>"):
            require_mesh_file(malformed, search)


def test_search_directories_expand_the_home_and_skip_blank_entries(tmp_path, arm_mesh, monkeypatch):
    monkeypatch.setenv("HOME", str(tmp_path))
    assert search_directories(" :~/pkgs::/abs") == [tmp_path / "pkgs", Path("/abs")]
    assert resolve_mesh_uri("package://my_arm/meshes/link.stl", "~/pkgs") == arm_mesh
    monkeypatch.chdir(arm_mesh.parents[1])
    assert resolve_mesh_uri("meshes/link.stl") == arm_mesh  # no document: the working directory


@given(st.text(max_size=30))
def test_resolve_is_require_without_the_error(uri):
    try:
        expected = require_mesh_file(uri, "/nonexistent-dir")
    except FileNotFoundError as error:
        assert str(error).startswith(f"{uri}: ")  # names the URI as it was given
        expected = None
    assert resolve_mesh_uri(uri, "/nonexistent-dir") == expected
