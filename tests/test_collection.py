"""The suite collects without the optional extras (#75): PyTorch, bm3d, colour-hdri and numba-cuda hidden from a
child pytest, every test file still collects (their tests skip where they need one)."""

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

HIDDEN = ("torch", "bm3d", "colour_hdri", "numba_cuda")


@pytest.mark.slow
def test_every_test_file_collects_with_the_optional_extras_hidden(tmp_path):
    (tmp_path / "sitecustomize.py").write_text(textwrap.dedent(f"""
        import sys

        class _Hidden:
            def find_spec(self, name, path=None, target=None):
                if name.split(".")[0] in {HIDDEN!r}:
                    raise ModuleNotFoundError(f"No module named {{name!r}} (hidden by the test)", name=name)
                return None

        sys.meta_path.insert(0, _Hidden())
    """))
    root = Path(__file__).resolve().parent.parent
    env = {"PYTHONPATH": str(tmp_path), "PATH": "/usr/bin:/bin", "HOME": str(tmp_path)}
    import os

    env.update({k: v for k, v in os.environ.items() if k.startswith(("NUMBA_", "CMOSNOISE_"))})
    r = subprocess.run([sys.executable, "-m", "pytest", "--collect-only", "-q", "-p", "no:cacheprovider", "-n", "0",
                        "tests"], cwd=root, env=env, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-2000:]
    assert "error" not in r.stdout.splitlines()[-1].lower(), r.stdout[-2000:]
    probe = subprocess.run([sys.executable, "-c", "import torch"], env=env, capture_output=True, text=True)
    assert probe.returncode != 0 and "hidden by the test" in probe.stderr  # the extras really were hidden
