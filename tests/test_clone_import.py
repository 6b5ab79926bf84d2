"""A script run from the folder that holds a clone named ``rfverify`` imports the clone's folder
first (the current folder leads sys.path); the clone's root ``__init__.py`` then loads the
package beside it instead of leaving an empty namespace package (issue 28 item 5)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.skipif(not (ROOT / "__init__.py").is_file(), reason="needs the repository checkout")
def test_a_script_beside_a_clone_named_rfverify_gets_the_package(tmp_path):
    (tmp_path / "rfverify").symlink_to(ROOT, target_is_directory=True)
    script = ("import rfverify, rfverify.solver\n"
              "print(rfverify.__file__)\n"
              "print(rfverify.load('bundled:cube').n_contacts, rfverify.solver.__file__)\n")
    out = subprocess.run([sys.executable, "-c", script], cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    first, second = out.stdout.splitlines()
    assert first == str(tmp_path / "rfverify" / "rfverify" / "__init__.py")
    assert second.startswith("2 ") and second.endswith(str(Path("rfverify", "rfverify", "solver", "__init__.py")))


def test_under_any_other_name_the_root_file_does_nothing():
    import runpy

    names = runpy.run_path(str(ROOT / "__init__.py"), run_name="not_rfverify")
    assert "load" not in names and "__path__" not in names
