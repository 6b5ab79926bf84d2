"""Results files of the benchmark scripts: what a script prints is also written to
``benchmarks/results/<name>.md``, stamped with the commit, the date and the machine, so that a
figure quoted in the docs can be traced to the run that measured it (issue 28: figures pasted into
the README drifted from the code).

Use in a script::

    from _results import recorded

    @recorded("bench_forms")
    def main(argv=None):
        print(...)              # goes to stdout and to benchmarks/results/bench_forms.md

or ``with recording("bench_scale", argv) as path:`` around the part of ``main`` to record.

``RFVERIFY_BENCH_RESULTS`` names another directory (the tests point it at a temporary one);
set to the empty string, nothing is written.  The file is replaced atomically at the end of a
run that finished; a run that raised writes nothing (a partial table is not a result).
"""

from __future__ import annotations

import contextlib
import datetime
import functools
import io
import os
import platform
import subprocess
import sys
from pathlib import Path

RESULTS_DIR = Path(__file__).resolve().parent / "results"
"""Where results files go by default (committed with the repository)."""


def _git(*args: str) -> str:
    try:
        out = subprocess.run(["git", *args], cwd=Path(__file__).resolve().parent, capture_output=True,
                             text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return ""
    return out.stdout.strip() if out.returncode == 0 else ""


def _cpu() -> str:
    """The CPU model from /proc/cpuinfo where there is one, else platform's guess."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def stamp() -> dict:
    """Commit (with ``+dirty`` when tracked files differ from it), UTC date and time, machine
    (CPU model, cores this process may use, OS, Python, numpy and rfverify versions)."""
    import numpy

    try:
        import rfverify

        version = rfverify.__version__
    except ImportError:
        version = "not importable"
    commit = _git("rev-parse", "--short=12", "HEAD") or "unknown (not a git checkout)"
    if commit[0] != "u" and _git("status", "--porcelain", "--untracked-files=no"):
        commit += "+dirty"
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return {
        "commit": commit,
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "machine": f"{_cpu()}, {cores} cores, {platform.system()} {platform.release()}",
        "software": f"Python {platform.python_version()}, numpy {numpy.__version__}, rfverify {version}",
    }


def results_path(name: str) -> Path | None:
    """The file ``name``'s results go to (None: not written)."""
    where = os.environ.get("RFVERIFY_BENCH_RESULTS")
    if where == "":
        return None
    return (Path(where) if where else RESULTS_DIR) / f"{name}.md"


class _Tee(io.TextIOBase):
    def __init__(self, *streams):
        self.streams = streams

    def write(self, text):
        for s in self.streams:
            s.write(text)
        return len(text)

    def flush(self):
        for s in self.streams:
            s.flush()


def recorded(name: str):
    """Decorate a script's ``main(argv=None)``: everything it prints is also written, stamped, to
    the results file of ``name`` (:func:`recording`); its return value is passed on."""
    def decorate(main):
        @functools.wraps(main)
        def run(argv=None):
            with recording(name, argv):
                return main(argv)
        return run
    return decorate


@contextlib.contextmanager
def recording(name: str, argv=None):
    """Copy stdout to the results file of ``name`` (see the module docstring); yields its path."""
    path = results_path(name)
    buf = io.StringIO()
    command = " ".join(["python", f"benchmarks/{name}.py", *(sys.argv[1:] if argv is None else argv)])
    # thread counts change the timings: the command is stamped with the ones set
    threads = " ".join(f"{k}={os.environ[k]}" for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS",
                                                        "NUMBA_NUM_THREADS") if k in os.environ)
    command = f"{threads} {command}" if threads else command
    with contextlib.redirect_stdout(_Tee(sys.stdout, buf)):
        yield path
    if path is None:
        return
    s = stamp()
    text = (f"# {name}\n\n"
            f"- command: `{command}`\n- commit: {s['commit']}\n- date: {s['date']}\n"
            f"- machine: {s['machine']}\n- software: {s['software']}\n\n"
            "Written by the script itself (benchmarks/_results.py); rerun the command to refresh it.\n\n"
            f"```\n{buf.getvalue().rstrip()}\n```\n")
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)
    print(f"(results written to {path})", file=sys.stderr)
