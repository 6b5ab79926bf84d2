"""What ``rfverify info`` says about a problem: :func:`problem_summary` (a JSON-able dict) and
:func:`format_summary` (its text form)."""

from __future__ import annotations

import numpy as np


def problem_summary(problem, *, solution_tol: float = 1e-6, max_asymmetry: float | None = None) -> dict:
    """JSON-able description of a problem (what ``rfverify info --json`` prints)."""
    from .check import check_solution
    from ..io.fclib3d import ROLLING, SOLUTION_LAYOUT, describe_symmetrised, file_layout, symmetrised
    from .problem import DEFAULT_MAX_ASYMMETRY

    mu, mu_r = problem.mu, problem.mu_r
    blocks = problem.blocks
    sizes, counts = np.unique(blocks.sizes, return_counts=True)
    free = problem.contact_free_dofs
    free_blocks = int(np.unique(blocks.labels[free]).size) if free.size else 0
    lam = blocks.lam_lower
    finite = np.isfinite(lam)
    summary = {
        "title": problem.title,
        "description": problem.description.strip(),
        "source": problem.source,
        "format": "siconos-dat" if "read_from" in problem.provenance else problem.provenance.get("format", "fclib-hdf5"),
        "storage": dict(problem.storage),
        "m": problem.n_dofs,
        "n": problem.n_contacts,
        "spacedim": problem.spacedim,
        "nnz": {"M": int(problem.M.nnz), "H": int(problem.H.nnz)},
        "mu": {"min": float(mu.min()), "max": float(mu.max()), "zero_count": int(np.sum(mu == 0))},
        "mu_r": {"min": float(mu_r.min()), "max": float(mu_r.max()),
                 "zero_count": int(np.sum(mu_r == 0))},
        "both_zero_count": int(np.sum((mu == 0) & (mu_r == 0))),
        "M_asymmetry": {
            "scaled": problem.symmetry.scaled,
            "frobenius": problem.symmetry.frobenius,
            "entrywise": problem.symmetry.scaled,
            "normwise": problem.symmetry.frobenius,
            "at": None if problem.symmetry.row is None else [problem.symmetry.row, problem.symmetry.col],
            "symmetrised": problem.symmetry.scaled > 0,
        },
        "M_blocks": {
            "count": blocks.count,
            "sizes": {str(int(s)): int(c) for s, c in zip(sizes, counts)},
            "contact_free_blocks": free_blocks,
            "contact_free_dofs": int(free.size),
            "min_eigenvalue_lower": float(lam[finite].min()) if finite.any() else None,
            "decided_exactly": int(blocks.exact_blocks),
        },
    }
    sym = symmetrised(problem)
    summary["symmetrised"] = {**sym, "text": describe_symmetrised(sym),
                              "limit": DEFAULT_MAX_ASYMMETRY if max_asymmetry is None else max_asymmetry,
                              "limit_measure": "entrywise"}
    layout = file_layout(problem)
    if layout != ROLLING:  # a 3-D FCLIB file read into the rolling layout: say what was done
        pv = problem.provenance
        summary["spacedim"] = pv["spacedim"]
        summary["internal_spacedim"] = problem.spacedim
        summary["file"] = {k: pv[k] for k in ("format", "spacedim", "relaxation", "mu_r", "embedding")}
        if "read_from" in pv:  # a Siconos 3-D .dat file, read as the FCLIB group of its kind
            summary["file"]["read_from"] = pv["read_from"]
        summary["file"]["solution_layout"] = SOLUTION_LAYOUT[layout]
        if "lifted" in pv:
            summary["file"]["lifted"] = pv["lifted"]
    if problem.provenance.get("ignored_groups"):
        summary["ignored_groups"] = list(problem.provenance["ignored_groups"])
    if problem.provenance.get("ignored"):
        summary["ignored_lines"] = list(problem.provenance["ignored"])
    if "significant_digits" in problem.provenance:
        summary["significant_digits"] = problem.provenance["significant_digits"]
    if "lift" in problem.provenance:
        summary["lifted_from_local"] = problem.provenance["lift"]
    if problem.solution is None:
        summary["solution"] = None
    else:
        chk = check_solution(problem, problem.solution)
        summary["solution"] = {"problem": "relaxation", **chk.as_dict(), "tolerance": solution_tol,
                               "consistent": chk.ok(solution_tol),
                               "verdict": chk.verdict(solution_tol)}
    summary["guesses"] = len(problem.guesses)
    return summary


def _negative_eigenvalue_note(lf: dict, add) -> None:
    """Where the lifting saw a negative eigenvalue: W may not be PSD as stored (a float64
    eigenvalue proves nothing either way), and what to do if a proof refuses it."""
    if lf["min_eigenvalue"] < 0:
        add("           W may not be positive semidefinite as stored (that eigenvalue is negative in "
            "floating point); where solve --digits or certify refuses it, --psd-shift proves W + D instead")


def format_summary(s: dict) -> str:
    """The text ``rfverify info`` prints for a :func:`problem_summary`."""
    from .directed import bound_text

    lines = []
    add = lines.append
    add(f"problem    {s['title'] or '(untitled)'}")
    if s["description"]:
        for k, text in enumerate(s["description"].splitlines()):
            add(f"{'' if k else 'about':<11}{text}")
    add(f"source     {s['source']} ({s['format']}; "
        + ", ".join(f"{k} {v}" for k, v in s["storage"].items()) + ")")
    fl = s.get("file")
    if fl:
        origin = f"{fl['read_from']} .dat, d = 3" if fl.get("read_from") else f"/{fl['format']}, spacedim {fl['spacedim']}"
        add(f"file       3-D Coulomb friction ({origin}, 3 per contact): "
            f"solved as its convex relaxation (De Saxcé term dropped), embedded in the rolling "
            f"layout with mu_r = 0 and zero rolling rows")
        add(f"           solutions are written back as {fl['solution_layout'].split(': ', 1)[1]}")
        lf = fl.get("lifted")
        if lf:
            add(f"lifted     local problem W ({lf['W_size']}×{lf['W_size']}) lifted to global form: "
                f"M = I, f = 0, w = q, W = HᵀH; rank {lf['rank']}, {lf['dropped']} eigenvalue(s) "
                f"≤ {lf['rank_tol']:.1e}·‖W‖ dropped (smallest {lf['min_eigenvalue']:.2e})")
            add("           v of the lifted problem is not a quantity of the file (a stored "
                "solution's v is recovered as v = H r)")
            _negative_eigenvalue_note(lf, add)
    if s.get("ignored_groups"):
        add(f"ignored    {', '.join(s['ignored_groups'])}: the file holds several problem groups; "
            f"read the first of /fclib_global_rolling, /fclib_global, /fclib_local")
    for note in s.get("ignored_lines", []):
        add(f"ignored    {note}")
    if s.get("significant_digits"):
        add(f"precision  matrices printed with {s['significant_digits']} significant digits")
    if s.get("lifted_from_local"):
        lf = s["lifted_from_local"]
        add(f"lifted     local problem W = HᵀH: rank {lf['rank']}, {lf['dropped']} eigenvalue(s) "
            f"≤ {lf['rank_tol']:.1e}·‖W‖ dropped (smallest {lf['min_eigenvalue']:.2e})")
        _negative_eigenvalue_note(lf, add)
    per = (f"3n = {3 * s['n']} in the file, 5n = {5 * s['n']} in the rolling layout" if fl
           else f"5n = {5 * s['n']}")
    add(f"sizes      m = {s['m']} dofs, n = {s['n']} contacts ({per}), "
        f"nnz(M) = {s['nnz']['M']}, nnz(H) = {s['nnz']['H']}")
    b = s["M_blocks"]
    add(f"M blocks   {b['count']} diagonal block(s): "
        + ", ".join(f"{c} of size {k}" for k, c in b["sizes"].items())
        + f"; {b['contact_free_blocks']} contact-free ({b['contact_free_dofs']} dofs)")
    if b["min_eigenvalue_lower"] is not None:
        exact = f"; {b['decided_exactly']} block(s) decided in exact arithmetic" if b["decided_exactly"] else ""
        add(f"           positive definite (verified): smallest block eigenvalue ≥ {bound_text(b['min_eigenvalue_lower'], 3, upper=False)}"
            f"{exact}")
    a, sym = s["M_asymmetry"], s["symmetrised"]
    limit = f"limit {sym['limit']:g}, --max-asymmetry"
    rows = [("M", a)] if sym["matrix"] == "M" else [("M", a), ("W", sym)]
    for X, d in rows:
        if d["symmetrised"]:
            at = "" if d["at"] is None else f" at {tuple(d['at'])}"
            add(f"{X} asym.    entrywise max|{X}_ij - {X}_ji|/sqrt({X}_ii {X}_jj) = {d['entrywise']:.3e}{at} "
                f"({limit}); normwise ||{X} - {X}ᵀ||_F/||{X}||_F = {d['normwise']:.3e}")
            use = "solving" if X == "M" else "the lifting (W = HᵀH)"
            add(f"           symmetrised: ({X} + {X}ᵀ)/2 is used for {use}")
        elif X == "M" and sym["matrix"] == "W":
            add("M asym.    0 (M = I of the lifted local problem)")
        else:
            add(f"{X} asym.    0 (exactly symmetric): nothing symmetrised ({limit})")
    for key in ("mu", "mu_r"):
        c = s[key]
        add(f"{key:<11}in [{c['min']:g}, {c['max']:g}]; {c['zero_count']} contact(s) with {key} = 0")
    add(f"           {s['both_zero_count']} contact(s) with mu = mu_r = 0")
    sol = s["solution"]
    add("solution   none stored" if sol is None else f"solution   stored: {sol['verdict']}")
    add(f"guesses    {s['guesses']}")
    return "\n".join(lines)
