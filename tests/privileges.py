"""Permission tests that hold for root too.

Root is not denied by mode bits, so a test of "unreadable file" or "read-only directory"
would prove nothing there.  :func:`as_ordinary_user` runs its body with the effective uid of
``nobody`` when the tests run as root (the real uid stays 0, so it can be restored), and
:func:`world_traversable_dir` gives a directory that user can reach (pytest's ``tmp_path``
lies under a mode-0700 directory of root's).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from pathlib import Path

NOBODY = 65534


@contextlib.contextmanager
def as_ordinary_user():
    if os.geteuid() != 0:
        yield
        return
    os.seteuid(NOBODY)
    try:
        yield
    finally:
        os.seteuid(0)


@contextlib.contextmanager
def world_traversable_dir():
    path = Path(tempfile.mkdtemp(prefix="rfverify-perm-"))
    path.chmod(0o755)
    try:
        yield path
    finally:
        for p in path.rglob("*"):
            p.chmod(0o755 if p.is_dir() else 0o644)
        shutil.rmtree(path)
