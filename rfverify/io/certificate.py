"""The certificate group of a solution file: everything needed to recheck a proof.

Written by ``rfverify solve --digits K --out SOL.h5`` and ``rfverify certify ... --out``
beside the problem and its ``/solution``::

    /certificate                 attrs: format, version, rfverify_version, requested_digits,
                                        certified, verdict, arithmetic, theorem, point_source,
                                        problem (the statement the proof is about), equations
                                        ("symmetrised" or "stored"), problem_sha256 (digest of
                                        the problem's data, :func:`problem_digest`) and
                                        solution_sha256 (digest of the /solution datasets,
                                        :func:`solution_digest`): what this certificate is about
    /certificate/point           attrs: layout = "rolling5" (r 5 per contact, (N, T1, T2, R1, R2),
                                        also for a 3-D file: its problem embedded with R = 0, and
                                        the v of a lifted local problem)
    /certificate/point/v_hi, v_lo, r_hi, r_lo
                                 float64: the extended-precision point, exactly (v = v_hi + v_lo)
    /certificate/point/v_more, r_more
                                 float64 (k, m) and (k, 5n), only for a point of the
                                 multiple-precision tail: further terms, v = v_hi + v_lo + Σ v_more
    /certificate/point/v_decimal, r_decimal
                                 the same numbers as decimal strings (34 significant digits, or
                                 16 per float64 term when there are more terms); on reading
                                 they are recomputed from the float64 terms and a file whose
                                 strings denote other numbers is refused
    /certificate/quantities/<v|u|Hr|r>
                                 attrs: abs_bound, norm, own_scale, data_scale, data_scale_name,
                                        digits (NaN: none), mode, certified, note
    /certificate/terms           attrs: every intermediate norm of the proof (eps_M, gap_rTu,
                                        gMinvg_upper, lam_min_M_lower, ...)
    /certificate/stored_equations
                                 only for a proof of (M + Mᵀ)/2 of an unsymmetric M: attrs
                                 certified, valid, failure, eps_M, fewest_digits and digits_<q>,
                                 abs_bound_<q>: the same answer proven against M as stored

Every write of ``/solution`` removes or rewrites ``/certificate``
(:func:`rfverify.io.fclib.write_solution_in_place`), so a file never keeps a claim about a
solution it no longer holds; ``certify`` compares both digests with the problem it reads and the
``/solution`` the file holds, and says whether the stored certificate is about them (a
certificate copied beside another problem is "about another problem").  Certificates written
before the problem digest have ``solution_sha256`` only: their digest is of the old kind, and
``certify`` says that it covers the solution alone.

To recheck: ``rfverify certify PROBLEM --solution SOL.h5`` evaluates the bound again from the
stored point, in exact arithmetic, against the stored ``/solution``.
"""

from __future__ import annotations

import numpy as np

from ..errors import ProblemFileError

FORMAT = "rfverify-certificate"
VERSION = 1
POINT_LAYOUT = "rolling5"
"""The point is stored in rfverify's internal layout, 5 per contact, whatever the file's layout."""
THEOREM = ("For M_s = (M+M^T)/2 positive definite and the posed M (M_s, or M as stored), any v with "
           "u(v) = H^T v + w in K* and any r in K, with g = Mv - Hr - f: ||v - v*||_Ms <= (sqrt(g^T Ms^-1 g) "
           "+ sqrt(g^T Ms^-1 g + 4 r^T u(v)))/2 (monotonicity of the convex relaxation); per-component bounds "
           "by Cauchy-Schwarz in the M_s inner product, carried to the stored solution by the triangle "
           "inequality (DESIGN section 6).")
SOLUTION_NAMES = ("v", "u", "r")


PROBLEM_DIGEST = "rfverify-problem-sha256-v1"
"""The kind of :func:`problem_digest` (stored beside it as ``problem_digest``)."""


def problem_digest(problem) -> str:
    """SHA-256 of the data a certificate is about, as rfverify reads them (exactly, in its own
    layout: a 3-D file's problem embedded with zero rolling rows), in a defined byte order:

    ``PROBLEM_DIGEST``, then for a global problem the matrices M and H (as stored, not
    symmetrised) and the vectors f, w, μ, μr; for a local problem (``problem.local``) W and q
    and μ, μr (its lifting is a solver device, not data).  A matrix is its name, its shape and
    its canonical CSC form — repeated entries summed exactly (as read), explicit zeros dropped,
    row indices increasing within each column — as int64 column pointers, int64 row indices and
    float64 values; a vector is its name, its length and its float64 values.  Integers and
    floats are little-endian, −0.0 is written as +0.0 (the same number).  The storage a file
    used (triplet, CSC, CSR; one file or another) does not change the digest."""
    import hashlib

    import scipy.sparse as sp

    h = hashlib.sha256(PROBLEM_DIGEST.encode())

    def block(name: str, *arrays):
        h.update(b"\0" + name.encode() + b"\0")
        for a in arrays:
            h.update(np.ascontiguousarray(a).tobytes())

    def floats(x):
        return (np.asarray(x, dtype=np.float64) + 0.0).astype("<f8")  # −0.0 + 0.0 = +0.0

    def matrix(name: str, A):
        C = sp.csc_matrix(A, dtype=np.float64, copy=True)
        C.sum_duplicates()
        C.eliminate_zeros()
        C.sort_indices()
        block(name, np.array(C.shape, dtype="<i8"), C.indptr.astype("<i8"), C.indices.astype("<i8"),
              floats(C.data))

    def vector(name: str, x):
        x = floats(x).ravel()
        block(name, np.array([x.size], dtype="<i8"), x)

    if problem.local is not None:
        matrix("W", problem.local.W)
        vector("q", problem.local.q)
    else:
        matrix("M", problem.M)
        matrix("H", problem.H)
        vector("f", problem.f)
        vector("w", problem.w)
    vector("mu", problem.mu)
    vector("mu_r", problem.mu_r)
    return h.hexdigest()


def solution_digest(fh) -> str:
    """SHA-256 of the ``/solution`` datasets of an open FCLIB file, as stored (float64 bytes,
    little-endian, with their names; "" when there is no /solution group): what a
    certificate is about."""
    import hashlib

    import h5py

    grp = fh.get("solution")
    if not isinstance(grp, h5py.Group):
        return ""
    h = hashlib.sha256()
    for name in SOLUTION_NAMES:
        obj = grp.get(name)
        if isinstance(obj, h5py.Dataset):
            h.update(name.encode())
            h.update(np.ascontiguousarray(np.asarray(obj[()], dtype="<f8")).tobytes())
    return h.hexdigest()


def write_certificate(fh, certificate, problem) -> None:
    """Write ``certificate`` (a :class:`rfverify.Certificate`) about ``problem`` (the
    :class:`rfverify.Problem` it proves) into the open h5py file ``fh``, replacing any previous
    ``/certificate``; its digests bind it to the problem's data and to the ``/solution`` the file
    holds."""
    import h5py

    from .._version import __version__

    if "certificate" in fh:
        del fh["certificate"]
    grp = fh.create_group("certificate")
    proof = certificate.proof
    grp.attrs["format"] = FORMAT
    grp.attrs["version"] = VERSION
    grp.attrs["rfverify_version"] = __version__
    grp.attrs["requested_digits"] = certificate.requested
    grp.attrs["certified"] = bool(certificate.certified)
    grp.attrs["verdict"] = certificate.verdict
    grp.attrs["theorem"] = THEOREM if proof is None else proof.theorem  # global (§6.1) or local (§6.1b)
    grp.attrs["point_source"] = str(certificate.extra.get("point_source", ""))
    grp.attrs["problem_digest"] = PROBLEM_DIGEST
    grp.attrs["problem_sha256"] = problem_digest(problem)
    grp.attrs["solution_sha256"] = solution_digest(fh)
    if proof is not None:
        grp.attrs["arithmetic"] = proof.arithmetic
        grp.attrs["problem"] = proof.statement
        grp.attrs["equations"] = proof.equations
        st = proof.stored_equations
        if st is not None:
            sg = grp.create_group("stored_equations")
            sg.attrs["certified"] = bool(st.certified)
            sg.attrs["valid"] = bool(st.valid)
            sg.attrs["failure"] = st.failure
            sg.attrs["eps_M"] = st.eps_M
            few = st.fewest_digits()
            sg.attrs["fewest_digits"] = np.nan if few is None else few
            for name, q in st.quantities.items():
                sg.attrs[f"digits_{name}"] = np.nan if q.digits is None else q.digits
                sg.attrs[f"abs_bound_{name}"] = q.abs_bound
        terms = grp.create_group("terms")
        for k, v in proof.terms.items():
            terms.attrs[k] = np.nan if v is None else v
        qg = grp.create_group("quantities")
        for name, q in proof.quantities.items():
            g = qg.create_group(name)
            for k, v in q.as_dict().items():
                g.attrs[k] = np.nan if v is None else v
    point = certificate.point
    if point is not None:
        pg = grp.create_group("point")
        pg.attrs["layout"] = POINT_LAYOUT
        for k in ("v_hi", "v_lo", "r_hi", "r_lo"):
            pg.create_dataset(k, data=np.asarray(getattr(point, k), dtype=np.float64))
        for k in ("v_more", "r_more"):
            if getattr(point, k) is not None:
                pg.create_dataset(k, data=np.asarray(getattr(point, k), dtype=np.float64))
        for name in ("v", "r"):
            terms = {k: getattr(point, k) for k in (f"{name}_hi", f"{name}_lo", f"{name}_more")}
            pg.create_dataset(f"{name}_decimal", data=np.array(_point_decimals(terms, name),
                                                               dtype=h5py.string_dtype()))


def read_stored_certificate(path, problem=None) -> dict | None:
    """What ``/certificate`` of ``path`` claims, and whether it is about ``problem`` (the
    :class:`rfverify.Problem` being certified; None: not judged) and the ``/solution`` the file
    holds now: ``{"certified", "verdict", "problem", "equations", "solution_sha256",
    "current_sha256", "matches_solution", "problem_sha256", "current_problem_sha256",
    "matches_problem", "digest_kind"}``.  ``digest_kind`` is "problem and solution", "solution
    only" (a certificate written before the problem digest: ``matches_problem`` None, whatever
    the solution) or None (no digest at all: both None).  None when there is no certificate."""
    import h5py

    from ._hdf5 import damaged

    try:
        with h5py.File(path, "r") as fh:
            grp = fh.get("certificate")
            if not isinstance(grp, h5py.Group):
                return None
            attrs = {k: grp.attrs.get(k) for k in ("certified", "verdict", "problem", "equations", "theorem",
                                                    "solution_sha256", "problem_sha256", "problem_digest",
                                                    "requested_digits")}
            current = solution_digest(fh)
    except (OSError, KeyError, RuntimeError) as exc:
        raise damaged(path, "/certificate", "its /certificate cannot be read", exc) from None
    out = {k: (v.decode("utf-8", "replace") if isinstance(v, bytes) else v) for k, v in attrs.items()}
    out["certified"] = None if out["certified"] is None else bool(out["certified"])
    out["current_sha256"] = current
    stored = out["solution_sha256"]
    out["matches_solution"] = None if not stored else stored == current
    kind_known = bool(out["problem_sha256"]) and out["problem_digest"] == PROBLEM_DIGEST
    if kind_known:
        out["digest_kind"] = "problem and solution"
    elif out["problem_sha256"]:
        out["digest_kind"] = f"unknown ({out['problem_digest']})"
    else:
        out["digest_kind"] = "solution only" if stored else None
    out["current_problem_sha256"] = problem_digest(problem) if problem is not None and kind_known else None
    out["matches_problem"] = (None if out["current_problem_sha256"] is None
                              else out["problem_sha256"] == out["current_problem_sha256"])
    return out


def read_point(path):
    """The extended-precision point stored in ``path`` (a :class:`rfverify.proof.Point`), or None
    when the file has no ``/certificate/point``."""
    import h5py

    from ..proof import Point

    try:
        with h5py.File(path, "r") as fh:
            if "certificate" not in fh or "point" not in fh["certificate"]:
                return None
            grp = fh["certificate"]
            if grp.attrs.get("format") != FORMAT or int(grp.attrs.get("version", -1)) != VERSION:
                raise ProblemFileError(path, f"/certificate is not an {FORMAT} version {VERSION} group",
                                       location="/certificate",
                                       fix="write the certificate again with this rfverify version")
            pg = grp["point"]
            layout = pg.attrs.get("layout", POINT_LAYOUT)  # certificates before the attribute: rolling5
            if isinstance(layout, bytes):
                layout = layout.decode("utf-8", "replace")
            if layout != POINT_LAYOUT:
                raise ProblemFileError(path, f"point layout {layout!r} is not {POINT_LAYOUT!r}",
                                       location="/certificate/point",
                                       fix="write the certificate again with this rfverify version")
            arrays = {}
            for k in ("v_hi", "v_lo", "r_hi", "r_lo"):
                if k not in pg:
                    raise ProblemFileError(path, f"missing dataset {k}", location=f"/certificate/point/{k}",
                                           fix="write the certificate again")
                a = pg[k]
                if not isinstance(a, h5py.Dataset) or a.dtype.kind != "f" or a.ndim != 1:
                    raise ProblemFileError(path, f"{k} must be a 1-D float dataset",
                                           location=f"/certificate/point/{k}", fix="write the certificate again")
                arrays[k] = np.asarray(a[()], dtype=np.float64)
            for k, n in (("v_more", arrays["v_hi"].size), ("r_more", arrays["r_hi"].size)):
                if k not in pg:
                    continue
                a = pg[k]
                if not isinstance(a, h5py.Dataset) or a.dtype.kind != "f" or a.ndim != 2 or a.shape[1] != n:
                    raise ProblemFileError(path, f"{k} must be a 2-D float dataset with {n} columns",
                                           location=f"/certificate/point/{k}", fix="write the certificate again")
                arrays[k] = np.asarray(a[()], dtype=np.float64)
            if ("v_more" in arrays) != ("r_more" in arrays) or (
                    "v_more" in arrays and len(arrays["v_more"]) != len(arrays["r_more"])):
                raise ProblemFileError(path, "v_more and r_more must both be present, with as many terms",
                                       location="/certificate/point", fix="write the certificate again")
            decimals = {k: _read_decimals(pg, k, path) for k in ("v_decimal", "r_decimal") if k in pg}
    except ProblemFileError:
        raise
    except (OSError, KeyError, RuntimeError) as exc:
        from ._hdf5 import damaged

        raise damaged(path, "/certificate/point", "its /certificate/point cannot be read", exc) from None
    if arrays["v_hi"].shape != arrays["v_lo"].shape or arrays["r_hi"].shape != arrays["r_lo"].shape:
        raise ProblemFileError(path, "hi and lo parts of the point differ in size", location="/certificate/point",
                               fix="write the certificate again")
    if not all(np.all(np.isfinite(a)) for a in arrays.values()):
        raise ProblemFileError(path, "the point contains NaN or Inf", location="/certificate/point",
                               fix="write the certificate again")
    for key, stored in decimals.items():
        _check_decimals(path, key, stored, arrays)
    return Point(**arrays)


_FIX_DECIMALS = ("the file was changed after it was written: write the certificate again "
                 "(rfverify solve --digits K --out SOL.h5, or rfverify certify ... --out)")


def _point_decimals(terms: dict, name: str) -> list:
    """The decimal strings of ``name`` ("v" or "r") from its float64 terms ``{name}_hi``,
    ``{name}_lo`` and the rows of ``{name}_more`` (None: absent), as the writer stores them:
    34 significant digits, or 16 per term when there are more than two terms."""
    parts = [terms[f"{name}_hi"], terms[f"{name}_lo"]]
    more = terms.get(f"{name}_more")
    parts += [] if more is None else list(more)
    return _decimal_strings(parts, max(34, 16 * len(parts)))


def _read_decimals(pg, key: str, path) -> list:
    """``/certificate/point/<key>`` as a list of str, refused unless it is a 1-D string dataset."""
    import h5py

    a = pg[key]
    if not isinstance(a, h5py.Dataset) or a.ndim != 1 or h5py.check_string_dtype(a.dtype) is None:
        raise ProblemFileError(path, f"{key} must be a 1-D dataset of strings",
                               location=f"/certificate/point/{key}", fix=_FIX_DECIMALS)
    try:
        return [s.decode("utf-8") if isinstance(s, bytes) else str(s) for s in a[()].tolist()]
    except UnicodeDecodeError:
        raise ProblemFileError(path, f"{key} holds bytes that are not UTF-8 text",
                               location=f"/certificate/point/{key}", fix=_FIX_DECIMALS) from None


def _check_decimals(path, key: str, stored: list, arrays: dict) -> None:
    """Refuse decimal strings that disagree with the binary point the proof is about: they
    are recomputed from the float64 terms exactly as the writer computes them, and a string
    that differs is accepted only when it denotes the same decimal number (exact comparison)."""
    from decimal import Decimal, InvalidOperation

    name = key.split("_")[0]
    expected = _point_decimals(arrays, name)
    loc = f"/certificate/point/{key}"
    if len(stored) != len(expected):
        raise ProblemFileError(path, f"{key} holds {len(stored)} strings, the point has {len(expected)} "
                                     f"entries", location=loc, fix=_FIX_DECIMALS)
    terms = " + ".join(t for t in (f"{name}_hi", f"{name}_lo", f"{name}_more") if t in arrays)
    for k, (s, e) in enumerate(zip(stored, expected)):
        if s == e:
            continue
        try:
            same = Decimal(s) == Decimal(e)  # exact: the same number written differently passes
        except InvalidOperation:
            same = False
        if not same:
            raise ProblemFileError(path, f"{key}[{k}] is {s[:60]!r}, but the binary point ({terms}) "
                                         f"is {e} to these digits", location=loc, fix=_FIX_DECIMALS)


def _decimal_strings(parts, digits: int = 34) -> list:
    """Each number Σ parts[i][j] (float64 terms) as a decimal string of ``digits`` digits."""
    import mpmath

    out = []
    cols = [np.asarray(p, dtype=np.float64) for p in parts]
    with mpmath.workprec(max(240, 4 * digits)):
        for terms in zip(*cols):
            out.append(mpmath.nstr(mpmath.fsum(mpmath.mpf(float(t)) for t in terms), digits, strip_zeros=False))
    return out
