"""`pip install <checkout>` into a bare venv (no Blender): the package
`meshadjust` with its core, NumPy as the only dependency, the console script."""

import os
import shutil
import socket
import subprocess
import sys
import textwrap

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
#: what a checkout holds besides the package (venvs, caches, outputs)
NOT_SOURCE = (".git", ".venv*", ".hypothesis", ".pytest_cache", "__pycache__", "*.pyc", "build",
              "dist", "out", "bench_results", "*.egg-info")


def _pypi_reachable():
    try:
        socket.create_connection(("pypi.org", 443), timeout=5).close()
        return True
    except OSError:
        return False


def _venv_bin(venv, name):
    return os.path.join(venv, "Scripts" if os.name == "nt" else "bin", name)


@pytest.fixture(scope="module")
def bare_venv(tmp_path_factory):
    """A fresh venv with only the checkout installed (and what it pulls in)."""
    if not _pypi_reachable():
        pytest.skip("offline: pip install needs PyPI (setuptools to build, NumPy to install)")
    tmp = tmp_path_factory.mktemp("install")
    # a copy, so the build's build/ and *.egg-info/ stay out of the checkout
    src = tmp / "meshadjust-src"
    shutil.copytree(ROOT, src, ignore=shutil.ignore_patterns(*NOT_SOURCE))
    venv = str(tmp / "venv")
    subprocess.run([sys.executable, "-m", "venv", venv], check=True, timeout=300)
    env = dict(os.environ, PIP_DISABLE_PIP_VERSION_CHECK="1")
    proc = subprocess.run([_venv_bin(venv, "python"), "-m", "pip", "install", "--quiet", str(src)],
                          capture_output=True, text=True, env=env, timeout=900)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return venv


def test_the_package_installs_with_numpy_only(bare_venv):
    code = textwrap.dedent("""
        import importlib.metadata as md, json, sys
        from meshadjust import core
        import meshadjust
        V = [[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]]
        F = [[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]]
        Vs, Fs = core.subdivide(core.simplify(V, F, target_faces=4).V, F, levels=1)
        files = sorted(str(f) for f in md.files("meshadjust"))
        print(json.dumps({"faces": len(Fs), "bpy": "bpy" in sys.modules,
                          "file": meshadjust.__file__, "files": files,
                          "requires": md.requires("meshadjust"),
                          "dists": sorted(d.metadata["Name"].lower() for d in md.distributions())}))
    """)
    proc = subprocess.run([_venv_bin(bare_venv, "python"), "-c", code], capture_output=True,
                          text=True, cwd=bare_venv, timeout=120)
    assert proc.returncode == 0, proc.stderr
    import json
    info = json.loads(proc.stdout)
    assert info["faces"] == 16 and not info["bpy"]
    assert "site-packages" in info["file"]
    tops = {f.split("/")[0] for f in info["files"] if not f.startswith("..")}
    assert tops == {"meshadjust", "meshadjust-0.1.0.dist-info"}
    assert any(f.endswith("bin/meshadjust-batch") for f in info["files"])
    pkg = {f for f in info["files"] if f.startswith("meshadjust/")}
    for needed in ("meshadjust/__init__.py", "meshadjust/core/simplify.py",
                   "meshadjust/core/io_mesh.py", "meshadjust/meshadjust_addon/api.py",
                   "meshadjust/cli/batch.py"):
        assert needed in pkg, needed
    assert not [f for f in pkg if "/tests/" in f or "/scripts/" in f or f.endswith("conftest.py")]
    assert [r.split(";")[0].replace(" ", "") for r in info["requires"]
            if "extra ==" not in r] == ["numpy>=1.26"]
    assert not {"bpy", "dask", "distributed"} & set(info["dists"])


def test_the_console_script_converts_obj_and_smf_without_blender(bare_venv, tmp_path):
    sys.path.insert(0, ROOT)
    import core
    from tests.mesh_factory import icosphere, out_files
    V, F = icosphere(3)
    core.write_obj(tmp_path / "ball.obj", V, F)
    core.write_smf(tmp_path / "ball2.smf", V * 2, F)
    exe = _venv_bin(bare_venv, "meshadjust-batch")
    proc = subprocess.run([exe, "--help"], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0 and "--dask" in proc.stdout
    # --jobs 2: the worker processes run `python -m meshadjust.cli.batch`
    proc = subprocess.run([exe, "ball.obj", "ball2.smf", "--faces", "100", "--jobs", "2",
                           "--out", "out"], capture_output=True, text=True, cwd=tmp_path,
                          timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "2 converted, 0 failed" in proc.stdout
    assert out_files(tmp_path / "out") == ["ball2_cage.smf", "ball_cage.obj"]
    proc = subprocess.run([exe, "ball.obj", "--faces", "100", "--format", "ply", "--out", "o2"],
                          capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert proc.returncode == 2 and "--format ply needs Blender (the bpy module" in proc.stderr


def test_the_dask_extra_runs_a_batch_on_a_local_cluster(bare_venv, tmp_path):
    """`pip install <checkout>[dask]`, then --dask local: the tasks' worker
    processes run `python -m meshadjust.cli.batch` from the installed package."""
    src = os.path.join(os.path.dirname(bare_venv), "meshadjust-src")
    proc = subprocess.run([_venv_bin(bare_venv, "python"), "-m", "pip", "install", "--quiet",
                           f"{src}[dask]"], capture_output=True, text=True, timeout=900,
                          env=dict(os.environ, PIP_DISABLE_PIP_VERSION_CHECK="1"))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    sys.path.insert(0, ROOT)
    import core
    from tests.mesh_factory import icosphere, out_files
    V, F = icosphere(3)
    core.write_smf(tmp_path / "ball.smf", V, F)
    (tmp_path / "bad.obj").write_text("v 0 0 0\nf 1 2 3\n")
    proc = subprocess.run([_venv_bin(bare_venv, "meshadjust-batch"), ".", "--faces", "100",
                           "--dask", "local", "--jobs", "2", "--out", "out"],
                          capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert proc.returncode == 1, proc.stdout + proc.stderr
    assert "1 converted, 1 failed" in proc.stdout and "refers to a missing vertex" in proc.stdout
    assert out_files(tmp_path / "out") == ["ball_cage.smf"]
