"""Issue 17, fuzzing: malformed FCLIB HDF5 files and Siconos .dat texts, made by mutating valid
ones (dtypes, shapes, values, indices, links, deletions, truncations), are either read (exit 0,
nothing on stderr) or refused with exit 2 and one stderr line naming the file and a fix —
never exit 3, never a traceback, and the input file is never changed.

``rfverify.cli.main`` runs in-process, so an example costs milliseconds.  Examples per test:
50 under the ``dev`` and ``ci`` profiles (``ci`` is derandomised); set
``RFVERIFY_FUZZ_EXAMPLES=5000`` for a long local run.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path

import h5py
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rfverify.cli import main
from rfverify.io import bundled_problems, write_fclib
from rfverify.model.problem import StoredSolution
from rfverify.scenes.random_problems import random_problem

EXAMPLES = int(os.environ.get("RFVERIFY_FUZZ_EXAMPLES", "0")) or min(settings.default.max_examples, 50)
# capsys is read out after every example, so sharing it between examples is safe.
FUZZ = settings(max_examples=EXAMPLES,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])


def _outcome(capsys, path: Path, extra=()):
    """Run ``info`` on ``path`` and check the contract; return the exit code."""
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    code = main(["info", str(path), *extra])
    out, err = capsys.readouterr()
    assert code in (0, 2), f"exit {code}: {err}"
    assert "Traceback" not in err and "internal error" not in err, err
    if code == 0:
        # Only odd optional metadata (info/*) may be reported: one DataWarning line each.
        assert all(line.startswith(f"rfverify info: warning: {path}: ") for line in err.splitlines()), err
        if "--json" in extra:
            json.loads(out, parse_constant=lambda c: pytest.fail(f"bare {c} in JSON"))
    else:
        assert out == ""
        assert err.count("\n") == 1 and err.endswith("\n"), err
        assert err.startswith("rfverify info: error: "), err
        assert str(path) in err and "fix:" in err, err
    assert hashlib.sha256(path.read_bytes()).hexdigest() == digest, "the input file changed"
    return code


# ---------------------------------------------------------------------- HDF5
def _base_files() -> dict:
    """Valid files in each storage, with /solution and /guesses (bytes, built once)."""
    out = {}
    p = random_problem(2, 3, seed=11)
    sol = StoredSolution(v=np.zeros(p.n_dofs), u=np.zeros(15), r=np.zeros(15))
    p = p.with_solution(sol)
    with tempfile.TemporaryDirectory() as d:
        for storage in ("triplet", "csc", "csr"):
            path = Path(d) / f"{storage}.hdf5"
            write_fclib(p, path, storage=storage)
            with h5py.File(path, "r+") as fh:
                gg = fh.create_group("guesses")
                gg["number_of_guesses"] = np.array([1], np.int32)
                g1 = gg.create_group("1")
                g1["v"] = np.ones(p.n_dofs)
            out[storage] = path.read_bytes()
    return out


BASE = _base_files()
SPECIAL = [np.nan, np.inf, -np.inf, -1.0, 0.0, 0.5, 1e308, -1e308, 5e-324, 2.0**31 - 1, -(2.0**31), 1e20]
DTYPES = ["f4", "f2", "i1", "i8", "u8", "c16", "?", "S8", "longdouble", "compound", "vlen-str"]


def _objects(fh) -> list[str]:
    names = []
    fh.visit(names.append)
    return sorted(names)


def _cast(data: np.ndarray, kind: str):
    data = np.atleast_1d(np.asarray(data))
    if kind == "compound":
        rec = np.zeros(data.size, dtype=[("a", "f8"), ("b", "i4")])
        rec["a"] = data.astype(np.float64, copy=False) if data.dtype.kind in "fiub" else 0
        return rec
    if kind == "vlen-str":
        return np.array([str(x) for x in data.tolist()], dtype=h5py.string_dtype())
    if kind == "S8":
        return np.array([str(x).encode()[:8] for x in data.tolist()], dtype="S8")
    if data.dtype.kind not in "fiub":
        return data
    with np.errstate(all="ignore"):
        return data.astype(kind)


@st.composite
def hdf5_mutation(draw, names):
    op = draw(st.sampled_from(["dtype", "shape", "value", "delete", "to_group", "to_dataset",
                               "soft_link", "dangling_link", "external_link", "attribute", "extra"]))
    target = draw(st.sampled_from(names))
    return (op, target, draw(st.integers(0, 2**31)), draw(st.sampled_from(DTYPES)),
            draw(st.sampled_from(SPECIAL)))


def _apply(fh, mutation, names):
    """Apply one mutation; one that an earlier mutation made impossible (its target removed,
    or behind a link loop) is skipped."""
    try:
        _apply_one(fh, mutation, names)
    except (KeyError, OSError, RuntimeError, ValueError, TypeError):
        pass


def _apply_one(fh, mutation, names):
    op, target, seed, kind, special = mutation
    if target not in fh:
        return
    rng = np.random.default_rng(seed)
    obj = fh[target]
    is_ds = isinstance(obj, h5py.Dataset)

    def put(data):
        del fh[target]
        fh[target] = data

    if op == "dtype" and is_ds:
        put(_cast(obj[()], kind))
    elif op == "shape" and is_ds:
        data = np.atleast_1d(obj[()])
        choice = seed % 6
        if choice == 0:
            put(data.reshape(-1, 1))
        elif choice == 1 and data.size % 2 == 0 and data.size:
            put(data.reshape(2, -1))
        elif choice == 2:
            put(data[: max(0, data.size - 1 - seed % 3)])
        elif choice == 3:
            put(np.concatenate([data, data[:1] if data.size else np.zeros(1, data.dtype)]))
        elif choice == 4:
            put(data[0] if data.size else np.zeros((), data.dtype))
        else:
            put(np.zeros((0,), dtype=data.dtype))
    elif op == "value" and is_ds:
        data = np.atleast_1d(np.array(obj[()]))
        if data.size and data.dtype.kind in "fiu":
            k = int(rng.integers(data.size))
            with np.errstate(all="ignore"):
                if data.dtype.kind == "f" or np.isfinite(special):
                    try:
                        data.flat[k] = special
                    except (OverflowError, ValueError):
                        data.flat[k] = -1
                else:
                    data.flat[k] = -1
            put(data)
    elif op == "delete":
        del fh[target]
    elif op == "to_group":
        del fh[target]
        fh.create_group(target)
    elif op == "to_dataset":
        del fh[target]
        fh[target] = rng.normal(size=int(rng.integers(0, 5)))
    elif op == "soft_link":
        other = names[seed % len(names)]
        del fh[target]
        fh[target] = h5py.SoftLink("/" + other)
    elif op == "dangling_link":
        del fh[target]
        fh[target] = h5py.SoftLink("/does/not/exist")
    elif op == "external_link":
        del fh[target]
        fh[target] = h5py.ExternalLink("no-such-file.h5", "/" + target)
    elif op == "attribute":
        obj.attrs["note"] = np.arange(3)
    elif op == "extra":
        parent = target.rsplit("/", 1)[0] if "/" in target else ""
        grp = fh[parent] if parent else fh
        if isinstance(grp, h5py.Group) and "zz_extra" not in grp:
            grp["zz_extra"] = np.ones(2)


@st.composite
def hdf5_case(draw):
    storage = draw(st.sampled_from(sorted(BASE)))
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "x.hdf5"
        path.write_bytes(BASE[storage])
        with h5py.File(path, "r") as fh:
            names = _objects(fh)
    mutations = draw(st.lists(hdf5_mutation(names), min_size=1, max_size=3))
    truncate = draw(st.one_of(st.none(), st.floats(0.0, 1.0)))
    return storage, names, mutations, truncate


@FUZZ
@given(case=hdf5_case(), json_out=st.booleans())
def test_fuzzed_hdf5_is_read_or_refused_in_one_line(capsys, case, json_out):
    storage, names, mutations, truncate = case
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "fuzz.hdf5"
        path.write_bytes(BASE[storage])
        with h5py.File(path, "r+") as fh:
            for m in mutations:
                _apply(fh, m, names)
        if truncate is not None:
            data = path.read_bytes()
            path.write_bytes(data[: int(len(data) * truncate)])
        _outcome(capsys, path, ["--json"] if json_out else [])


def test_hdf5_fuzzer_refuses_known_bad_mutations(capsys):
    """The mutations bite: each of these is refused (not silently read)."""
    for mutation in [("dtype", "fclib_global_rolling/M/p", 0, "f4", 0.0),
                     ("dtype", "fclib_global_rolling/M/x", 0, "c16", 0.0),
                     ("delete", "fclib_global_rolling/vectors/mu", 0, "f4", 0.0),
                     ("dangling_link", "fclib_global_rolling/H/i", 0, "f4", 0.0),
                     ("value", "fclib_global_rolling/vectors/f", 3, "f4", np.nan)]:
        with tempfile.TemporaryDirectory() as d:
            path = Path(d) / "bad.hdf5"
            path.write_bytes(BASE["triplet"])
            with h5py.File(path, "r+") as fh:
                _apply(fh, mutation, _objects(fh))
            assert _outcome(capsys, path) == 2, mutation


# ---------------------------------------------------------------------- .dat
def _global_dat() -> str:
    """A small global problem as a Siconos print-out: M and H as CSparse triplets."""
    p = random_problem(2, 2, seed=4)

    def triplet(A):
        coo = A.tocoo()
        lines = ["2", f"{A.shape[0]}", f"{A.shape[1]}", "1",
                 "CSparse Version 3.2.0, Sept 12, 2017.  Copyright (c) Timothy A. Davis, 2006-2016",
                 f"triplet: {A.shape[0]}-by-{A.shape[1]}, nzmax: {coo.nnz} nnz: {coo.nnz}"]
        lines += [f"    {i} {j} : {x:g}" for i, j, x in zip(coo.row, coo.col, coo.data)]
        return lines

    def vec(x):
        return " ".join(f"{v:.17e}" for v in x)

    lines = ["5", f"{p.n_contacts}"] + triplet(p.M) + triplet(p.H)
    lines += [vec(p.f), vec(p.w), vec(p.mu), vec(p.mu_r)]
    return "\n".join(lines) + "\n"


DAT_BASES = {
    "local-dense": bundled_problems()["sphere"].read_text(),
    "local-csc": bundled_problems()["sphere-from-global"].read_text(),
    "global-triplet": _global_dat(),
}
TOKENS = ["0", "-1", "1", "2", "5", "99999999999", "123456789012345678901234567890", "nan", "inf",
          "-inf", "1e999", "1e-400", "-0.0", "0.5", "x", "", ":", "col", "CSparse", "\u22121",
          "1,5", "0x10", "\t"]


@st.composite
def dat_case(draw):
    base = draw(st.sampled_from(sorted(DAT_BASES)))
    text = DAT_BASES[base]
    ops = draw(st.lists(st.tuples(
        st.sampled_from(["delete_line", "duplicate_line", "swap_lines", "replace_token",
                         "insert_line", "unicode", "truncate", "bytes"]),
        st.integers(0, 10**6), st.sampled_from(TOKENS),
        st.text(max_size=6), st.binary(min_size=1, max_size=8)), min_size=1, max_size=3))
    return base, text, ops


def _mutate_text(text: str, ops) -> bytes:
    data = None
    for op, k, token, free_text, raw in ops:
        lines = text.split("\n")
        i = k % max(len(lines), 1)
        if op == "delete_line":
            del lines[i]
        elif op == "duplicate_line":
            lines.insert(i, lines[i])
        elif op == "swap_lines":
            j = (k // 7) % len(lines)
            lines[i], lines[j] = lines[j], lines[i]
        elif op == "replace_token":
            parts = lines[i].split()
            if parts:
                parts[(k // 3) % len(parts)] = token
                lines[i] = " ".join(parts)
        elif op == "insert_line":
            lines.insert(i, token if k % 2 else free_text)
        elif op == "unicode":
            lines[i] = lines[i] + free_text
        elif op == "truncate":
            text = text[: k % max(len(text), 1)]
            continue
        elif op == "bytes":
            encoded = "\n".join(lines).encode("utf-8", errors="surrogatepass")
            at = k % max(len(encoded), 1)
            data = encoded[:at] + raw + encoded[at:]
            text = data.decode("utf-8", errors="surrogateescape")
            continue
        text = "\n".join(lines)
    return text.encode("utf-8", errors="surrogateescape")


@FUZZ
@given(case=dat_case(), json_out=st.booleans())
def test_fuzzed_dat_is_read_or_refused_in_one_line(capsys, case, json_out):
    base, text, ops = case
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "fuzz.dat"
        path.write_bytes(_mutate_text(text, ops))
        _outcome(capsys, path, ["--json"] if json_out else [])


def test_dat_bases_are_valid(capsys):
    with tempfile.TemporaryDirectory() as d:
        for name, text in DAT_BASES.items():
            path = Path(d) / f"{name}.dat"
            path.write_text(text)
            assert _outcome(capsys, path) == 0, name
        for storage, data in BASE.items():
            path = Path(d) / f"{storage}.hdf5"
            path.write_bytes(data)
            assert _outcome(capsys, path) == 0, storage
