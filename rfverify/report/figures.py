"""The report's figures (matplotlib, Agg backend, PNG).  Every figure has axis labels with
units, a legend and a title saying what is counted."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .data import RunData, performance_profile

_STYLE = {
    "jqinv": ("tab:blue", "o"), "qp2": ("tab:orange", "s"), "reduced": ("tab:green", "^"),
    "reduced_factored": ("tab:olive", "v"), "noscaling": ("tab:purple", "D"),
    "clarabel": ("tab:red", "x"), "mixed precision": ("black", "*"),
}


def _plt():
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def _log_x(ax):
    """Log time axis with labels on decades only (minor labels overlap)."""
    from matplotlib.ticker import NullFormatter

    ax.set_xscale("log")
    ax.xaxis.set_minor_formatter(NullFormatter())


def _save(fig, path: Path) -> None:
    """PNG written atomically: a reader never sees half a figure."""
    import io

    from ..io.output import write_bytes_atomic

    buf = io.BytesIO()
    try:
        fig.savefig(buf, format="png", dpi=110)
    finally:
        _plt().close(fig)
    write_bytes_atomic(path, buf.getvalue())


def _style(method):
    return _STYLE.get(method, ("gray", "."))


def profiles(data: RunData, out: Path, measure: str) -> Path:
    """Dolan–Moré profiles, one panel per tolerance."""
    plt = _plt()
    tols = data.tols
    fig, axes = plt.subplots(1, len(tols), figsize=(4.2 * len(tols), 3.6), squeeze=False, sharey=True)
    for ax, tol in zip(axes[0], tols):
        taus, prof = performance_profile(data, tol, measure)
        for m, rho in prof.items():
            color, marker = _style(m)
            ax.step(taus, rho, where="post", color=color, label=m, lw=1.6)
        ax.set_xscale("log", base=2)
        ax.set_ylim(-0.02, 1.02)
        ax.set_xlim(1, taus[-1])
        ax.set_title(f"tol = {tol:g}")
        ax.set_xlabel(f"τ  ({measure} ≤ τ × best {measure})")
        ax.grid(True, which="both", alpha=0.3)
    axes[0][0].set_ylabel("share of problems solved (verified)")
    axes[0][-1].legend(loc="lower right", fontsize=8)
    what = "run time" if measure == "time" else "iterations"
    fig.suptitle(f"Performance profiles of {what} ({len(data.problems)} problems; unverified runs count as failures)",
                 fontsize=10)
    fig.tight_layout()
    path = out / f"profile_{'time' if measure == 'time' else 'iterations'}.png"
    _save(fig, path)
    return path


def _time_to_digits(times, digits, k):
    for t, d in zip(times, digits):
        if d is not None and d >= k:
            return t
    return math.inf


def work_precision_aggregate(data: RunData, out: Path) -> Path | None:
    """Left: median time to reach k correct digits of v; right: share of problems whose
    double run ever reaches k digits (how far double precision gets)."""
    keys = sorted(data.references)
    if not keys:
        return None
    plt = _plt()
    ks = np.arange(1, 17)
    series = {}
    for t in data.trajectories:
        if t["problem"] in data.references and t.get("digits_v_iterates"):
            times = [it["time"] for it in t["iterates"]]
            series.setdefault(t["method"], {})[t["problem"]] = [
                _time_to_digits(times, t["digits_v_iterates"], k) for k in ks]
    # The peer has no iterates: its points are its runs at each tolerance.
    for r in data.solves:
        if r["method"] == "clarabel" and r["problem"] in data.references and r.get("digits_v") is not None \
                and r.get("time") is not None:
            row = series.setdefault("clarabel", {}).setdefault(r["problem"], [math.inf] * len(ks))
            for i, k in enumerate(ks):
                if r["digits_v"] >= k:
                    row[i] = min(row[i], r["time"])
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10.5, 4.0))
    for m, per in series.items():
        T = np.array([per.get(k_, [math.inf] * len(ks)) for k_ in keys], dtype=float)
        med = np.median(T, axis=0)
        share = np.isfinite(T).mean(axis=0)
        color, marker = _style(m)
        ok = np.isfinite(med)
        if ok.any():
            ax1.plot(med[ok], ks[ok], color=color, marker=marker, ms=4, label=m)
        ax2.plot(ks, share, color=color, marker=marker, ms=4, label=m)
    mp = [d for k_, d in data.digits.items() if k_ in data.references and d.get("certified")]
    if mp:
        tt = np.median([d["time"] for d in mp])
        dv = np.median([min(d["certified_digits"]["v"], 17) for d in mp])
        ax1.plot([tt], [dv], marker="*", color="black", ms=12, ls="none",
                 label=f"mixed precision (double + warm mpmath), median of {len(mp)} certified")
    _log_x(ax1)
    ax1.set_xlabel("median elapsed time to reach k digits (s)")
    ax1.set_ylabel("k = correct digits of v (vs certified reference)")
    ax1.set_title("Work–precision (median over problems that reach k)", fontsize=10)
    ax1.grid(True, which="both", alpha=0.3)
    ax1.legend(fontsize=7, loc="lower right")
    ax2.set_xlabel("k = correct digits of v")
    ax2.set_ylabel("share of problems ever reaching k digits")
    ax2.set_title(f"How far each method gets ({len(keys)} problems with a reference)", fontsize=10)
    ax2.set_ylim(-0.02, 1.02)
    ax2.grid(True, alpha=0.3)
    ax2.legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    path = out / "work_precision.png"
    _save(fig, path)
    return path


def work_precision_problems(data: RunData, out: Path, keys: list) -> Path | None:
    """Per problem: verified error of each iterate against elapsed time."""
    if not keys:
        return None
    plt = _plt()
    cols = min(3, len(keys))
    rows = math.ceil(len(keys) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.6 * cols, 3.6 * rows), squeeze=False)
    for ax, key in zip(axes.ravel(), keys):
        has_ref = key in data.references
        for t in data.trajectories:
            if t["problem"] != key or not t.get("iterates"):
                continue
            color, marker = _style(t["method"])
            times = np.array([it["time"] for it in t["iterates"]])
            if has_ref and t.get("digits_v_iterates"):
                y = np.array([d if d is not None else np.nan for d in t["digits_v_iterates"]])
                y = np.minimum(y, 17)
            else:
                y = -np.log10(np.maximum([it["verified_max"] for it in t["iterates"]], 1e-30))
            ax.plot(np.maximum(times, 1e-4), y, color=color, marker=marker, ms=3, lw=1, label=t["method"])
        pts = sorted(((r["time"], r) for r in data.solves if r["problem"] == key and r["method"] == "clarabel"
                      and r.get("time") is not None), key=lambda p: p[0])
        if pts:
            xs = [p[0] for p in pts]
            if has_ref:
                ys = [min(p[1].get("digits_v") or 0, 17) for p in pts]
            else:
                ys = [-math.log10(max(p[1]["verified"]["max"], 1e-30)) if p[1].get("verified") else 0 for p in pts]
                ys = [y if math.isfinite(y) else 0 for y in ys]
            color, marker = _style("clarabel")
            ax.plot(xs, ys, color=color, marker=marker, ls=":", label="clarabel (one run per tol)")
        d = data.digits.get(key)
        if d and has_ref and d.get("certified_digits"):
            ax.plot([d["time"]], [min(d["certified_digits"]["v"], 17)], "k*", ms=11, label="mixed precision")
        _log_x(ax)
        ax.set_xlabel("elapsed time (s)")
        ax.set_ylabel("correct digits of v" if has_ref else "−log10 verified criterion")
        p = data.problems[key]
        ax.set_title(f"{key}\n(n = {p['n_contacts']}, m = {p['n_dofs']})", fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=6, loc="upper left")
    for ax in axes.ravel()[len(keys):]:
        ax.axis("off")
    fig.suptitle("Verified error of each iterate against elapsed time", fontsize=10)
    fig.tight_layout()
    path = out / "work_precision_problems.png"
    _save(fig, path)
    return path


def diagnostics(diag: dict, key: str, out: Path, index: int) -> Path:
    """Lockstep diagnosis: digits of agreement, max cond(Q_p), min λ2 double vs reference."""
    plt = _plt()
    its = diag["iterations"]
    k = np.array([r["iter"] for r in its])
    fig, (a1, a2, a3) = plt.subplots(1, 3, figsize=(13, 3.6))
    for name, lab in (("digits_v", "v"), ("digits_r_t", "r̃"), ("digits_z", "z")):
        y = np.array([min(r[name], 17) if r[name] is not None else np.nan for r in its], dtype=float)
        a1.plot(k + 1, y, marker="o", ms=3, label=lab)
    a1.set_xlabel("iteration")
    a1.set_ylabel("digits of agreement, double vs exact step")
    a1.set_ylim(bottom=0)
    a1.legend(fontsize=8)
    a1.grid(alpha=0.3)
    cond = np.array([r["max_cond_Qp"] for r in its], dtype=float)
    # cond(Q_p) of iterate k scales the step that produces iterate k + 1.
    a2.semilogy(k + 1, np.where(cond > 0, cond, np.nan), marker="o", ms=3, color="tab:red")
    a2.axhline(1 / np.finfo(float).eps, color="gray", ls="--", lw=1, label="1/ε (double)")
    a2.set_xlabel("iteration (step taken with this scaling)")
    a2.set_ylabel("max cond(Q_p)")
    a2.legend(fontsize=8)
    a2.grid(alpha=0.3, which="both")
    for fam, color in (("min_lam2_z", "tab:blue"), ("min_lam2_s", "tab:green")):
        dbl = np.array([r[fam]["double"] for r in its], dtype=float)
        ref = np.array([r[fam]["reference"] for r in its], dtype=float)
        label = "z" if fam.endswith("z") else "Jᵀr̃"
        a3.semilogy(k + 1, np.where(dbl > 0, dbl, np.nan), color=color, marker="o", ms=3, label=f"λ2({label}) double")
        a3.semilogy(k + 1, np.where(ref > 0, ref, np.nan), color=color, ls="--", label=f"λ2({label}) exact")
    events = [r["iter"] + 1 for r in its if r["flags"]]
    for e in events:
        a3.axvline(e, color="red", alpha=0.4, lw=1)
    a3.set_xlabel("iteration" + (" (red: λ2 underflow / sign events)" if events else ""))
    a3.set_ylabel("min λ2 over cones")
    a3.legend(fontsize=7)
    a3.grid(alpha=0.3, which="both")
    fig.suptitle(f"{key}: {diag['method']} at tol {diag.get('tol', float('nan')):g} — {diag['status']}"
                 f" after {diag['nit']} iterations", fontsize=10)
    fig.tight_layout()
    path = out / f"diagnostics_{index}.png"
    _save(fig, path)
    return path
