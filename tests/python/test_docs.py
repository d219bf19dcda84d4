# Every Python snippet of docs/python.md runs, in order, in one namespace (as a reader would paste
# them), and the README's import line works as written.
import os
import pathlib
import re
import subprocess

import pytest

from conftest import REPO, require


def snippets(path):
    return re.findall(r"^```python\n(.*?)^```$", path.read_text(), flags=re.S | re.M)


def test_python_md_snippets_run(tmp_path, monkeypatch):
    blocks = snippets(REPO / "docs" / "python.md")
    assert len(blocks) >= 4
    for module in ("skimage", "meshio", "vtk"):
        require(module)
    monkeypatch.chdir(tmp_path)
    namespace = {}
    for i, block in enumerate(blocks):
        try:
            exec(compile(block, f"docs/python.md snippet {i + 1}", "exec"), namespace)
        except Exception as e:
            pytest.fail(f"docs/python.md snippet {i + 1} raised {type(e).__name__}: {e}\n{block}")
    # What the snippets say they make.
    assert (tmp_path / "surface.ply").stat().st_size > 1000
    assert (tmp_path / "surface.vtu").stat().st_size > 1000
    for name in ("ellipsoid.ply", "gyroid.ply", "gyroid.obj", "gyroid.stl"):
        assert (tmp_path / name).stat().st_size > 1000, name
    # The out-of-core file is the in-core run's.
    import isotile
    isotile.extract("field:gyroid:96", output=tmp_path / "in_core.ply", stats=False)
    assert (tmp_path / "in_core.ply").read_bytes() == (tmp_path / "gyroid.ply").read_bytes()


def test_readme_import_line():
    readme = (REPO / "README.md").read_text()
    lines = [l for l in readme.splitlines() if l.startswith("PYTHONPATH=build/python ")]
    assert len(lines) == 1, lines
    # The line names build/python; this build's package may be elsewhere (ctest's PYTHONPATH).
    package = os.environ["PYTHONPATH"].split(os.pathsep)[0]
    line = lines[0].replace("PYTHONPATH=build/python ", f"PYTHONPATH={package} ", 1)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    r = subprocess.run(["bash", "-c", line], cwd=REPO, env=env, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "marching_cubes" in r.stdout
