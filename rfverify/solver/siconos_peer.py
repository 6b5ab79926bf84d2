"""The Siconos peer: the paper's own GRFC3D_IPM (Siconos numerics, C), run on the same problem.

The library and a small driver (``benchmarks/peers/siconos/driver.c``) are built by
``benchmarks/peers/siconos/build.sh`` into a prefix; rfverify finds the driver at
``$RFVERIFY_SICONOS/bin/rfverify-siconos-driver`` or, with the variable unset, in the build
script's default cache (``${XDG_CACHE_HOME:-~/.cache}/rfverify/siconos-*``, newest first).

Each solve runs the driver in a child process on a binary copy of the problem's M (symmetrised,
as every rfverify solver uses it), H, f, w, μ, μr — not through Siconos's FCLIB reader — so that a
crash of GRFC3D_IPM (a zero pivot in its LDLᵀ is not checked, and the next triangular solve
segfaults) is a recorded failure (``NumericalError``, "siconos crashed (signal 11) …"), never
the death of the caller, and ``Settings.time_limit`` kills it (``MaxTime``).

GRFC3D_IPM works in scaled variables r_s = P⁻¹r, u_s = P u with P = diag(1, μ, μ, μr, μr) per
contact and returns them so (the conversion back is commented out in its source); the driver
returns v, u = P⁻¹u_s, r = P r_s.  The answer (v, u, r) — Siconos's own u, not Hᵀv + w — is judged
by rfverify's criterion (:mod:`rfverify.model.measures`) exactly like Algorithm 1's and Clarabel's;
Siconos's own verdict is kept in ``extras``: ``siconos_status`` ("Solved" when its info is 0,
i.e. it met tol on its own scaled measure), ``siconos_info``, ``siconos_residual`` (its
max(pinfeas, dinfeas, min(uᵀr, projection error)) in its scaled variables),
``siconos_projerr``, ``siconos_seconds`` (its solve alone), and the scaled ``u_s``, ``r_s``.
Only Siconos's defaults besides ``tol`` and ``max_iter`` are used (JQinv linear system,
Cholesky, convex case); GRFC3D_IPM needs μ > 0 and μr > 0 on every contact (it divides by them).
"""

from __future__ import annotations

import glob
import math
import os
import signal
import struct
import subprocess
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..model.measures import measures
from ..model.problem import Problem
from .result import Settings, SolveResult, Status

ENV_PREFIX = "RFVERIFY_SICONOS"
"""Environment variable naming the prefix ``build.sh`` installed into."""

DRIVER = Path("bin") / "rfverify-siconos-driver"
BUILD_FIX = ("bash benchmarks/peers/siconos/build.sh (builds it from ../shared/peers/siconos, or --siconos SRC), "
             f"then {ENV_PREFIX}=<the prefix it prints>")


def default_prefixes() -> list[Path]:
    """The build script's default cache prefixes that hold a driver, newest first."""
    cache = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "rfverify"
    found = [Path(p).parent.parent for p in glob.glob(str(cache / "siconos-*" / DRIVER))]
    return sorted(found, key=lambda p: (p / DRIVER).stat().st_mtime, reverse=True)


def driver_path() -> Path | None:
    """The driver executable rfverify will run, or None when there is none."""
    prefix = os.environ.get(ENV_PREFIX)
    if prefix:
        exe = Path(prefix) / DRIVER
        return exe if exe.is_file() and os.access(exe, os.X_OK) else None
    found = default_prefixes()
    return found[0] / DRIVER if found else None


def build_id() -> str:
    """What identifies the driver rfverify would run: ``build.sh``'s stamp of its sources, patches,
    options and driver source (``<prefix>/.rfverify-driver-stamp``), "none" without a driver,
    "unstamped" for a driver not built by ``build.sh``."""
    exe = driver_path()
    if exe is None:
        return "none"
    stamp = exe.parent.parent / ".rfverify-driver-stamp"
    return stamp.read_text().strip() if stamp.is_file() else "unstamped"


def unavailable() -> str | None:
    """Why the ``siconos`` method cannot run here (no driver found), or None when it can.
    Phrased like :func:`rfverify.solver.result.method_unavailable` ("…; fix: …")."""
    if driver_path() is not None:
        return None
    prefix = os.environ.get(ENV_PREFIX)
    where = (f"{ENV_PREFIX}={prefix} has no executable {DRIVER}" if prefix
             else f"{ENV_PREFIX} is not set and the default cache holds no build")
    return f"'siconos' needs the Siconos peer driver ({where}); fix: {BUILD_FIX}"


# ---------------------------------------------------------------------- exchange format
def _write_arrays(fh, matrices, vectors) -> None:
    """CSC matrices (int64 column pointers, int64 row indices, float64 values) then float64 vectors."""
    for A in matrices:
        fh.write(np.ascontiguousarray(A.indptr, dtype="<i8").tobytes())
        fh.write(np.ascontiguousarray(A.indices, dtype="<i8").tobytes())
        fh.write(np.ascontiguousarray(A.data, dtype="<f8").tobytes())
    for x in vectors:
        fh.write(np.ascontiguousarray(x, dtype="<f8").tobytes())


def _write_exchange(path, magic: bytes, problem: Problem, H, tol: float, max_iter: int, vectors) -> None:
    """One input of the driver (format in driver.c): magic, sizes, tol, M_sym and H as CSC, then
    ``vectors`` as float64."""
    M = problem.M_sym.tocsc()
    M.sort_indices()
    H.sort_indices()
    with open(path, "wb") as fh:
        fh.write(magic)
        fh.write(struct.pack("<5qd", problem.n_dofs, problem.n_contacts, M.nnz, H.nnz, int(max_iter), float(tol)))
        _write_arrays(fh, (M, H), vectors)


def write_input(path, problem: Problem, tol: float, max_iter: int) -> None:
    """The driver's input (format in driver.c): sizes, tol, M_sym and H as CSC, f, w, μ, μr."""
    _write_exchange(path, b"RFVSIC01", problem, problem.H.tocsc(), tol, max_iter,
                    (problem.f, problem.w, problem.mu, problem.mu_r))


def _read_exchange(path, magic: bytes, n_meta: int, lengths) -> tuple:
    """One answer of the driver: (info, iterations, the ``n_meta`` doubles, the arrays of
    ``lengths``), its size and magic checked."""
    raw = Path(path).read_bytes()
    head = 8 + 16 + 8 * n_meta
    size = head + 8 * int(sum(lengths))
    if len(raw) != size or raw[:8] != magic:
        raise RuntimeError(f"the Siconos driver's output {path} is malformed ({len(raw)} bytes, expected {size})")
    info, nit = struct.unpack_from("<2q", raw, 8)
    meta = struct.unpack_from(f"<{n_meta}d", raw, 24)
    arrays = np.frombuffer(raw, dtype="<f8", offset=head).astype(np.float64)
    bounds = np.cumsum([0, *lengths])
    return int(info), int(nit), meta, [arrays[bounds[k]:bounds[k + 1]] for k in range(len(lengths))]


def read_output(path, m: int, n: int) -> dict:
    """The driver's answer: info, iterations, its residual, projection error, seconds, and
    v (m,), u, r (5n,) in the original variables, u_s, r_s (5n,) as GRFC3D_IPM returned them."""
    nd = 5 * n
    info, nit, (residual, projerr, seconds), (v, u, r, u_s, r_s) = _read_exchange(
        path, b"RFVSOL01", 3, (m, nd, nd, nd, nd))
    return {"info": info, "nit": nit, "residual": residual, "projerr": projerr, "seconds": seconds,
            "v": v, "u": u, "r": r, "u_s": u_s, "r_s": r_s}


# ---------------------------------------------------------------------- the peer
def solve_siconos(problem: Problem, settings: Settings) -> SolveResult:
    """Run GRFC3D_IPM on ``problem`` at ``settings.tol`` / ``settings.max_iter`` in a child
    process and judge its answer by rfverify's criterion (module docstring).  Raises
    RuntimeError naming the fix when no driver is found (``solve`` checks that first)."""
    t0 = time.perf_counter()
    exe = driver_path()
    if exe is None:
        raise RuntimeError(unavailable())
    m, n = problem.n_dofs, problem.n_contacts
    bad = np.flatnonzero(~((problem.mu > 0) & (problem.mu_r > 0)))
    if bad.size:
        return _no_answer(problem, settings, t0, Status.INVALID_INPUT,
                          f"GRFC3D_IPM needs μ > 0 and μr > 0 on every contact (its change of variables divides "
                          f"by them); contact {bad[0]} has μ = {problem.mu[bad[0]]:g}, μr = {problem.mu_r[bad[0]]:g}"
                          f" ({bad.size} such contacts)", {"siconos_status": "NotRun"})
    with tempfile.TemporaryDirectory(prefix="rfverify-siconos-") as tmp:
        inp, out = Path(tmp) / "problem.bin", Path(tmp) / "answer.bin"
        write_input(inp, problem, settings.tol, settings.max_iter)
        t_setup = time.perf_counter() - t0
        failure = run_driver(exe, inp, out, settings.time_limit, settings.verbose, "GRFC3D_IPM")
        if failure is not None:
            return _no_answer(problem, settings, t0, *failure)
        ans = read_output(out, m, n)
    v, u, r = ans["v"], ans["u"], ans["r"]
    judged = measures(problem, v, u, r, "longdouble")
    merit = judged.max
    # The paper's pinfeas in the original variables (Siconos measures it scaled): ‖u − Hᵀv − w‖₂ relative.
    Hv = problem.H.T @ v
    pinfeas = float(np.linalg.norm(u - Hv - problem.w)
                    / max(np.linalg.norm(u), np.linalg.norm(Hv), np.linalg.norm(problem.w), np.finfo(float).tiny))
    info, nit = ans["info"], ans["nit"]
    own = "Solved" if info == 0 else f"NotConverged (info {info})"
    if merit <= settings.tol:
        status = Status.SOLVED
    elif merit <= settings.almost_factor * settings.tol:
        status = Status.ALMOST_SOLVED
    elif info == 0:
        status = Status.INSUFFICIENT_PROGRESS  # it claims tol on its own measure; ours says no
    elif nit >= settings.max_iter:
        status = Status.MAX_ITERATIONS
    else:
        status = Status.NUMERICAL_ERROR
    message = (f"Siconos GRFC3D_IPM info {info} ({'met tol on its own scaled measure' if info == 0 else 'not converged'}"
               f", its residual {ans['residual']:.2e}, {nit} iterations); rfverify criterion {merit:.2e} "
               f"({'≤' if merit <= settings.tol else '>'} tol = {settings.tol:g}, worst: {judged.worst()})")
    total = time.perf_counter() - t0
    return SolveResult(
        v=v, u=u, r=r, status=status, message=message, nit=nit, measures=judged, pinfeas=pinfeas, dinfeas=float(judged.paper_dinfeas), mu=float(judged.paper_mu), trace={},
        timings={"total": total, "setup": t_setup, "siconos_solve": float(ans["seconds"])},
        method="siconos", settings=settings,
        extras={"siconos_status": own, "siconos_info": info, "siconos_residual": float(ans["residual"]),
                "siconos_projerr": float(ans["projerr"]), "siconos_seconds": float(ans["seconds"]),
                "u_s": ans["u_s"], "r_s": ans["r_s"], "driver": str(exe)},
    )


def run_driver(exe, inp, out, time_limit, verbose: bool, solver: str):
    """Run the driver on ``inp`` in a child process; None when it wrote ``out``, else
    (Status, message, extras) of the failure: killed at ``time_limit`` (MaxTime), crashed by a
    signal (``solver``'s unchecked zero pivot: NumericalError), or a driver error."""
    cmd = [str(exe), str(inp), str(out)] + (["--verbose"] if verbose else [])
    try:
        # Siconos prints to stdout: shown with verbose, else kept out of the caller's output.
        proc = subprocess.run(cmd, stdout=None if verbose else subprocess.DEVNULL,
                              stderr=subprocess.PIPE, timeout=time_limit, check=False)
    except subprocess.TimeoutExpired:
        return (Status.MAX_TIME, f"siconos exceeded the time limit of {time_limit:g} s (killed); no answer",
                {"siconos_status": "MaxTime"})
    stderr = " ".join(proc.stderr.decode(errors="replace").split())[-400:]
    if proc.returncode < 0:
        sig = -proc.returncode
        try:
            name = signal.Signals(sig).name
        except ValueError:
            name = "unknown signal"
        return (Status.NUMERICAL_ERROR, f"siconos crashed (signal {sig}) ({name}) in {solver}; no answer"
                + (f"; stderr: {stderr}" if stderr else ""),
                {"siconos_status": f"Crashed (signal {sig})", "siconos_signal": sig})
    if proc.returncode != 0:
        return (Status.NUMERICAL_ERROR, f"the Siconos driver failed (exit {proc.returncode}): {stderr or 'no message'}",
                {"siconos_status": f"DriverError (exit {proc.returncode})"})
    return None


def _no_answer(problem: Problem, settings: Settings, t0: float, status: Status, message: str,
               extras: dict) -> SolveResult:
    """A run that returned nothing (crash, time limit, refused input): the zero point
    (v = 0, u = w, r = 0), judged so that its criterion is on record, with ``status``."""
    v = np.zeros(problem.n_dofs)
    r = np.zeros(5 * problem.n_contacts)
    u = np.array(problem.w, dtype=np.float64)
    judged = measures(problem, v, u, r, "longdouble")
    return SolveResult(
        v=v, u=u, r=r, status=status, message=message, nit=0, measures=judged, pinfeas=float("nan"),
        dinfeas=float(judged.paper_dinfeas), mu=float(judged.paper_mu), trace={},
        timings={"total": time.perf_counter() - t0}, method="siconos", settings=settings,
        extras={"no_answer": True, **extras})


# ---------------------------------------------------------------------- GFC3D_IPM (issue 51)
GFC3D_SOLVER = "GFC3D_IPM"
"""Siconos's 3-D global Coulomb interior-point solver (``numerics/src/FrictionContact/gfc3d_ipm.c``):
with its defaults it updates De Saxcé's shift inside its iterations (``w_N ← w_N + ‖(P u)_T‖``,
``SICONOS_FRICTION_3D_IPM_IPARAM_UPDATE_S_INTERNAL``), so it answers the physical problem."""


@dataclass
class Gfc3dAnswer:
    """What GFC3D_IPM returned for a problem (:func:`solve_gfc3d`), in rfverify's layout.

    ``v`` (m,); ``r`` (5n,) with its 3-D reaction in (N, T1, T2) and zero rolling parts;
    ``u_siconos`` (5n,) its own velocity — the modified one, u + μ‖u_T‖e_N of its last iterate,
    rolling parts Hᵀv + w; ``info`` its info (0: met ``tol`` on its own measure, -1: not run),
    ``nit``, ``residual`` (its own), ``seconds`` (its solve alone); ``failure`` "" when it
    answered, else why not (then v, r are zero); ``status`` "Solved" / "NotConverged (info K)"
    / the failure's kind."""

    v: np.ndarray
    r: np.ndarray
    u_siconos: np.ndarray
    info: int
    nit: int
    residual: float
    seconds: float
    status: str
    failure: str = ""
    extras: dict = field(default_factory=dict)

    @property
    def answered(self) -> bool:
        return not self.failure


def _slots3(n: int) -> np.ndarray:
    """Positions of (N, T1, T2) of each contact in the 5-per-contact layout."""
    return (5 * np.arange(n)[:, None] + np.arange(3)[None, :]).ravel()


def gfc3d_refusal(problem: Problem) -> str:
    """Why GFC3D_IPM cannot take ``problem`` ("" when it can): it is a 3-D solver (μr = 0 on
    every contact, so the rolling reaction is zero and u_R is free), and its change of variables
    divides by μ."""
    rolling = np.flatnonzero(problem.mu_r != 0)
    if rolling.size:
        return (f"a rolling problem (μr = {problem.mu_r[rolling[0]]:g} on contact {rolling[0]}, {rolling.size} such "
                f"contacts): GFC3D_IPM solves 3-D Coulomb friction only")
    bad = np.flatnonzero(~(problem.mu > 0))
    if bad.size:
        return (f"GFC3D_IPM needs μ > 0 on every contact (its change of variables divides by it); contact "
                f"{bad[0]} has μ = {problem.mu[bad[0]]:g} ({bad.size} such contacts)")
    return ""


def write_input_gfc3d(path, problem: Problem, tol: float, max_iter: int) -> None:
    """The driver's GFC3D input (format in driver.c): M_sym, the (N, T1, T2) columns of H, f, w, μ."""
    keep = _slots3(problem.n_contacts)
    _write_exchange(path, b"RFVGFC01", problem, problem.H.tocsc()[:, keep], tol, max_iter,
                    (problem.f, np.asarray(problem.w)[keep], problem.mu))


def read_output_gfc3d(path, m: int, n: int) -> dict:
    """The driver's GFC3D answer: info, iterations, its residual, seconds, v (m,), u, r (3n,)."""
    nd = 3 * n
    info, nit, (residual, seconds), (v, u, r) = _read_exchange(path, b"RFVGSO01", 2, (m, nd, nd))
    return {"info": info, "nit": nit, "residual": residual, "seconds": seconds, "v": v, "u": u, "r": r}


def solve_gfc3d(problem: Problem, tol: float = 1e-10, max_iter: int = 100, time_limit: float | None = None,
                verbose: bool = False) -> Gfc3dAnswer:
    """Run Siconos's GFC3D_IPM on the 3-D problem ``problem`` (μr = 0 everywhere: see
    :func:`gfc3d_refusal`) in a child process, at its own tolerance ``tol`` and ``max_iter``
    (Siconos's defaults besides: De Saxcé's shift updated internally, 2×2 NT-scaled system, no
    rescaling).  A crash, the time limit or a refusal is an answer with ``failure`` set, never
    an exception; RuntimeError only when no driver is found."""
    exe = driver_path()
    if exe is None:
        raise RuntimeError(unavailable())
    m, n = problem.n_dofs, problem.n_contacts
    zero_v, zero_r = np.zeros(m), np.zeros(5 * n)

    def failed(status: str, message: str, extras=None) -> Gfc3dAnswer:
        return Gfc3dAnswer(zero_v, zero_r, np.full(5 * n, np.nan), -1, 0, math.nan, math.nan, status, message,
                           dict(extras or {}))

    refusal = gfc3d_refusal(problem)
    if refusal:
        return failed("NotRun", refusal)
    with tempfile.TemporaryDirectory(prefix="rfverify-gfc3d-") as tmp:
        inp, out = Path(tmp) / "problem.bin", Path(tmp) / "answer.bin"
        write_input_gfc3d(inp, problem, tol, max_iter)
        failure = run_driver(exe, inp, out, time_limit, verbose, GFC3D_SOLVER)
        if failure is not None:
            status, message, extras = failure
            return failed(extras.get("siconos_status", str(status)), message, extras)
        ans = read_output_gfc3d(out, m, n)
    keep = _slots3(n)
    r = zero_r.copy()
    r[keep] = ans["r"]
    u = problem.H.T @ ans["v"] + np.asarray(problem.w)  # rolling parts: free when μr = 0
    u[keep] = ans["u"]
    info = ans["info"]
    status = "Solved" if info == 0 else f"NotConverged (info {info})"
    return Gfc3dAnswer(ans["v"], r, u, info, ans["nit"], float(ans["residual"]), float(ans["seconds"]), status,
                       extras={"driver": str(exe)})
