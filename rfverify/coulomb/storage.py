"""The De Saxcé shift an answer to the physical problem was solved with, kept beside its
/solution (``solve --problem coulomb --out``: group ``/coulomb``) so that ``certify --problem
coulomb`` proves the answer for the same shifted problem.  Any shift gives a valid certificate
(the bound on δ counts |ŝ − Φ(û)|); the solver's own makes it as tight as the solve's."""

from __future__ import annotations

import numpy as np

GROUP = "coulomb"
FORMAT = "rfverify-coulomb-shift"


def write_shift(fh, shift, statement: str, backward_error: float | None) -> None:
    """Write ``/coulomb/shift`` (n,) into the open h5py file ``fh`` (replacing any), and name the
    problem the /solution beside it answers (its ``problem`` attribute, ``statement``): the
    physical one, not the relaxation the writer of /solution assumes."""
    if GROUP in fh:
        del fh[GROUP]
    grp = fh.create_group(GROUP)
    grp.attrs["format"] = FORMAT
    grp.attrs["problem"] = statement
    grp.attrs["meaning"] = ("the shift s (one per contact) whose convex problem, with w_N + s, the /solution "
                            "solves: s = mu |u_T| + mu_r |u_R| at a fixed point")
    if backward_error is not None:
        grp.attrs["backward_error"] = float(backward_error)
    grp.create_dataset("shift", data=np.asarray(shift, dtype=np.float64))
    if "solution" in fh:
        fh["solution"].attrs["problem"] = statement


def read_shift(path, n: int):
    """The shift stored in ``path`` (an .hdf5 file), or None when it holds none of ``n`` entries
    (then the certificate takes Φ of the solution's u)."""
    import h5py

    try:
        with h5py.File(path, "r") as fh:
            if GROUP not in fh or "shift" not in fh[GROUP] or fh[GROUP].attrs.get("format") != FORMAT:
                return None
            s = np.asarray(fh[GROUP]["shift"][()], dtype=np.float64).ravel()
    except OSError:
        return None
    return s if s.size == n and np.all(np.isfinite(s)) else None
