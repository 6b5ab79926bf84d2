"""The report's figures (matplotlib, Agg backend, PNG).  Every figure has axis labels with
units, a legend and a title saying what is counted."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..solver.result import METHODS
from .aggregates import DIGITS_CAP, performance_profile
from .data import RunData

_STYLE = {
    "jqinv": ("tab:blue", "o"), "qp2": ("tab:orange", "s"), "reduced": ("tab:green", "^"),
    "reduced_factored": ("tab:olive", "v"), "noscaling": ("tab:purple", "D"), "auto": ("tab:cyan", "P"),
    "clarabel": ("tab:red", "x"), "mixed precision": ("black", "*"),
}

_LINE = {
    # Forms often take the same iterations or times: distinct dashes and widths (widest drawn
    # first) keep a curve that lies under another visible.
    "jqinv": ("-", 4.0, 0.45), "qp2": ("-", 2.2, 0.9), "reduced": ((0, (5, 2)), 2.2, 0.9),
    "reduced_factored": ((0, (3, 1, 1, 1)), 1.8, 0.9), "noscaling": ((0, (1, 1.2)), 2.4, 1.0),
    "auto": ((0, (2, 2)), 1.4, 1.0), "clarabel": ((0, (6, 2, 1, 2)), 1.6, 1.0),
}

# A method declared later (a new form or peer) gets a style of its own, not the gray fallback.
_SPARE = iter(zip(("tab:brown", "tab:pink", "tab:gray", "gold", "teal", "navy"), "<>hp8d"))
for _m in METHODS:
    if _m not in _STYLE:
        _color, _marker = next(_SPARE, ("gray", "."))
        _STYLE[_m] = (_color, _marker)
        _LINE[_m] = ((0, (4, 1, 1, 1, 1, 1)), 1.6, 1.0)


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
    """The figure written atomically (a reader never sees half a figure), in the format its
    extension names (PDF, SVG, EPS, PS), else PNG."""
    import io

    from ..io.output import write_bytes_atomic

    kind = Path(path).suffix.lower().lstrip(".")
    buf = io.BytesIO()
    try:
        fig.savefig(buf, format=kind if kind in ("pdf", "svg", "eps", "ps") else "png", dpi=110)
    finally:
        _plt().close(fig)
    write_bytes_atomic(path, buf.getvalue())


# Where a label may go around its point, in points (dx, dy, horizontal alignment): beside it
# first, then ever further out, joined to the point by a thin line.
_LABEL_SPOTS = [(5, 3, "left"), (5, -9, "left"), (-5, 3, "right"), (-5, -9, "right"), (0, 7, "center"),
                (0, -14, "center")] + [(dx * r, dy * r, h) for r in (1, 2, 3, 4, 5, 6)
                                       for dx, dy, h in ((14, 10, "left"), (14, -16, "left"), (-14, 10, "right"),
                                                         (-14, -16, "right"), (0, 14, "center"), (0, -20, "center"),
                                                         (22, -3, "left"), (-22, -3, "right"))]


def labels_apart(ax, items, fontsize: float = 6) -> list:
    """Annotate ``items`` — (x, y, text, colour) in data coordinates — so that no two labels
    overlap and none covers another labelled point: each goes to the first of
    :data:`_LABEL_SPOTS` that is free (inside the axes), the far ones with a thin line to their
    point; where none is free, the least covered.  Call it after the layout is final.  Returns the
    annotations."""
    from matplotlib.text import Text

    fig = ax.figure
    renderer = fig.canvas.get_renderer()
    frame = ax.get_window_extent(renderer)
    pad = 1.5 * fig.dpi / 72  # points to pixels
    points = []  # the labelled points, each a small box a label of another point must not cover
    for x, y, _, _ in items:
        px, py = ax.transData.transform((x, y))
        points.append((px - 4 * pad, py - 4 * pad, px + 4 * pad, py + 4 * pad))
    boxes, placed = [], []
    for k, (x, y, text, color) in enumerate(items):
        obstacles = points[:k] + points[k + 1:] + boxes
        best = None
        for dx, dy, align in _LABEL_SPOTS:
            far = abs(dx) > 6 or dy > 7 or dy < -14
            ann = ax.annotate(text, (x, y), textcoords="offset points", xytext=(dx, dy), fontsize=fontsize,
                              color=color, ha=align, annotation_clip=False,
                              arrowprops=dict(arrowstyle="-", color=color, lw=0.5, alpha=0.7) if far else None)
            ann.get_window_extent(renderer)  # places the text (and its line)
            ext = Text.get_window_extent(ann)  # the text alone
            box = (ext.x0 - pad, ext.y0 - pad, ext.x1 + pad, ext.y1 + pad)
            outside = ext.x0 < frame.x0 or ext.x1 > frame.x1 or ext.y0 < frame.y0 or ext.y1 > frame.y1
            score = (outside, sum(_overlap(box, o) for o in obstacles))
            if best is None or score < best[0]:
                if best is not None:
                    best[1].remove()
                best = (score, ann, box)
            else:
                ann.remove()
            if score == (False, 0.0):
                break
        boxes.append(best[2])
        placed.append(best[1])
    return placed


def _overlap(a, b) -> float:
    """Area shared by two boxes (x0, y0, x1, y1)."""
    return max(0.0, min(a[2], b[2]) - max(a[0], b[0])) * max(0.0, min(a[3], b[3]) - max(a[1], b[1]))


def _style(method):
    return _STYLE.get(method, ("gray", "."))


def profiles(data: RunData, out: Path, measure: str) -> Path:
    """Dolan–Moré profiles, one panel per tolerance."""
    plt = _plt()
    tols = data.tols
    fig, axes = plt.subplots(1, len(tols), figsize=(4.2 * len(tols), 3.9), squeeze=False, sharey=True)
    for ax, tol in zip(axes[0], tols):
        taus, prof = performance_profile(data, tol, measure)
        for m, rho in prof.items():
            color, marker = _style(m)
            ls, lw, alpha = _LINE.get(m, ("-", 1.6, 1.0))
            ax.step(taus, rho, where="post", color=color, label=m, ls=ls, lw=lw, alpha=alpha)
        ax.set_xscale("log", base=2)
        ax.set_ylim(-0.02, 1.02)
        ax.set_xlim(1, taus[-1])
        ax.set_title(f"tol = {tol:g}")
        ax.set_xlabel(f"τ  ({measure} ≤ τ × best {measure})")
        ax.grid(True, which="both", alpha=0.3)
    axes[0][0].set_ylabel("share of problems solved (verified)")
    what = "run time" if measure == "time" else "iterations"
    fig.suptitle(f"Performance profiles of {what} ({len(data.problems)} problems; a run not verified solved never "
                 "counts)", fontsize=10)
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=len(labels), fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    path = out / f"profile_{'time' if measure == 'time' else 'iterations'}.png"
    _save(fig, path)
    return path


def _best_so_far(points):
    """(times, digits) of a run's points, sorted by time, digits as the running maximum."""
    pts = sorted((t, d) for t, d in points if t is not None and d is not None and math.isfinite(t))
    times = np.array([max(t, 1e-6) for t, _ in pts], dtype=float)
    best = np.maximum.accumulate(np.array([min(d, DIGITS_CAP) for _, d in pts], dtype=float)) if pts \
        else np.array([])
    return times, best


def _at(times, best, grid):
    """Best digits reached by each time of ``grid`` (0 before the first point)."""
    if times.size == 0:
        return np.zeros(grid.size)
    idx = np.searchsorted(times, grid, side="right") - 1
    return np.where(idx >= 0, best[np.maximum(idx, 0)], 0.0)


def work_precision_series(data: RunData) -> tuple[list, dict]:
    """Per method, per problem with relative digits of v: the points (time, correct digits of v)
    of its run — every iterate of an Algorithm 1 trajectory, each Clarabel run (one per
    tolerance), and the k-digit path's end (its proven digits of v at its total time)."""
    keys = sorted(k for k in data.references if k not in data.absolute_v)
    series: dict = {}
    for t in data.trajectories:
        if t["problem"] in keys and t.get("digits_v_iterates"):
            series.setdefault(t["method"], {})[t["problem"]] = [
                (it["time"], d) for it, d in zip(t["iterates"], t["digits_v_iterates"])]
    for r in data.solves:
        if r["method"] == "clarabel" and r["problem"] in keys and r.get("digits_v") is not None \
                and r.get("time") is not None:
            series.setdefault("clarabel", {}).setdefault(r["problem"], []).append((r["time"], r["digits_v"]))
    for k in keys:
        d = data.digits.get(k)
        digs = (d or {}).get("certified_digits") or {}
        if d and digs.get("v") is not None and d.get("time") is not None:
            series.setdefault("mixed precision", {})[k] = [(d["time"], digs["v"])]
    return keys, series


def work_precision_medians(keys: list, series: dict, grid=None) -> tuple[np.ndarray, dict]:
    """(grid of times, {method: median over ALL ``keys`` of the best digits reached by each
    time}); a problem a method has no point for counts with 0 digits."""
    if grid is None:
        all_t = [t for per in series.values() for pts in per.values() for t, _ in pts if t is not None and t > 0]
        grid = np.logspace(math.log10(max(min(all_t), 1e-5)) - 0.1, math.log10(max(all_t)) + 0.1, 400)
    grid = np.asarray(grid, dtype=float)
    medians = {}
    for m, per in series.items():
        curves = np.array([_at(*_best_so_far(per.get(k, [])), grid) for k in keys])
        medians[m] = np.median(curves, axis=0)  # the report's median (numpy's), over all problems
    return grid, medians


def work_precision_aggregate(data: RunData, out: Path) -> Path | None:
    """Left: at each elapsed time t, the median over ALL problems with a reference of the best
    correct digits of v a method has reached by t (a problem it has not reached yet, or never
    reaches, counts with what it has: no method is judged only where it does well).  Right:
    the share of those problems on which it ever reaches k digits."""
    keys, series = work_precision_series(data)
    if not keys or not series:
        return None
    plt = _plt()
    grid, medians = work_precision_medians(keys, series)
    ks = np.arange(1, 17)
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11.5, 4.3))
    order = [m for m in list(_STYLE) if m in series]
    for m in order:
        per = series[m]
        color, marker = _style(m)
        med = medians[m]
        label = (f"k-digit path (proven digits of v at its end; it stops once {data.manifest.get('digits', 10)} "
                 "are proven)" if m == "mixed precision"
                 else "clarabel (one run per tolerance)" if m == "clarabel" else m)
        ls, lw, alpha = _LINE.get(m, ("-", 2.2, 1.0))
        ax1.step(grid, med, where="post", color=color, ls=ls, lw=lw, alpha=alpha, label=label)
        best = np.array([_best_so_far(per.get(k, []))[1][-1] if per.get(k) else 0.0 for k in keys])
        share = [(best >= k - 1e-9).mean() for k in ks]
        ax2.plot(ks, share, color=color, marker=marker, ms=4, ls=ls, lw=lw, alpha=alpha, label=label)
    _log_x(ax1)
    ax1.set_xlabel("elapsed time t (s)")
    ax1.set_ylabel("median best correct digits of v by time t")
    ax1.set_ylim(-0.3, DIGITS_CAP + 0.5)
    ax1.set_title(f"Work–precision: median over all {len(keys)} problems with a reference", fontsize=10)
    ax1.grid(True, which="both", alpha=0.3)
    ax2.set_xlabel("k = correct digits of v")
    ax2.set_ylabel("share of problems ever reaching k digits")
    ax2.set_title(f"How far each method gets ({len(keys)} problems)", fontsize=10)
    ax2.set_ylim(-0.02, 1.02)
    ax2.set_xticks(ks)
    ax2.grid(True, alpha=0.3)
    handles, labels = ax1.get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=min(len(labels), 4), fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.12 if len(labels) > 4 else 0.07, 1, 1))
    path = out / "work_precision.png"
    _save(fig, path)
    return path


def work_precision_problems(data: RunData, out: Path, keys: list) -> Path | None:
    """Per problem: every iterate against elapsed time — correct digits of v where a proven
    reference exists (v* not ≈ 0), otherwise −log10 of the verified criterion."""
    if not keys:
        return None
    plt = _plt()
    cols = min(3, len(keys))
    rows = math.ceil(len(keys) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(4.6 * cols, 3.4 * rows + 0.6), squeeze=False)
    seen = {}
    for ax, key in zip(axes.ravel(), keys):
        has_ref = key in data.references and key not in data.absolute_v
        for t in sorted((t for t in data.trajectories if t["problem"] == key and t.get("iterates")),
                        key=lambda t: list(_STYLE).index(t["method"]) if t["method"] in _STYLE else 99):
            color, marker = _style(t["method"])
            times = np.array([it["time"] for it in t["iterates"]])
            if has_ref and t.get("digits_v_iterates"):
                y = np.array([min(d, DIGITS_CAP) if d is not None else np.nan for d in t["digits_v_iterates"]])
            else:
                y = -np.log10(np.maximum([it["verified_max"] for it in t["iterates"]], 1e-30))
            line, = ax.plot(np.maximum(times, 1e-4), y, color=color, marker=marker, ms=3, lw=1)
            seen.setdefault(t["method"], line)
        pts = sorted(((r["time"], r) for r in data.solves if r["problem"] == key and r["method"] == "clarabel"
                      and r.get("time") is not None), key=lambda p: p[0])
        if pts:
            xs = [p[0] for p in pts]
            if has_ref:
                ys = [min(p[1].get("digits_v") or 0, DIGITS_CAP) for p in pts]
            else:
                ys = [-math.log10(max(p[1]["verified"]["max"], 1e-30)) if p[1].get("verified") else 0 for p in pts]
                ys = [y if math.isfinite(y) else 0 for y in ys]
            color, marker = _style("clarabel")
            line, = ax.plot(xs, ys, color=color, marker=marker, ls=":")
            seen.setdefault("clarabel (one run per tolerance)", line)
        d = data.digits.get(key)
        digs = (d or {}).get("certified_digits") or {}
        if d and has_ref and digs.get("v") is not None:
            line, = ax.plot([d["time"]], [min(digs["v"], DIGITS_CAP)], "k*", ms=11, ls="none")
            seen.setdefault("k-digit path (proven digits of v)", line)
        _log_x(ax)
        ax.set_xlabel("elapsed time (s)")
        ax.set_ylabel("correct digits of v" if has_ref else "−log10 verified criterion")
        p = data.problems[key]
        ax.set_title(f"{key}\n(n = {p['n_contacts']} contacts, m = {p['n_dofs']} dofs)", fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
    for ax in axes.ravel()[len(keys):]:
        ax.axis("off")
    fig.suptitle("Each iterate against elapsed time: correct digits of v (proven reference) or −log10 of the "
                 "verified criterion (no reference)", fontsize=10)
    if seen:  # a run of Algorithm 1 forms only, without trajectories or the k-digit path, has no lines
        fig.legend(list(seen.values()), list(seen), loc="lower center", ncol=min(len(seen), 4), fontsize=8,
                   frameon=False)
    fig.tight_layout(rect=(0, 0.1 / rows + (0.04 if len(seen) > 4 else 0), 1, 0.97))
    path = out / "work_precision_problems.png"
    _save(fig, path)
    return path


def diagnostics(diag: dict, key: str, out: Path, index: int, what: str = "") -> Path:
    """The report's lockstep figure of one diagnosed run (:func:`lockstep_figure`)."""
    what = what or f"{diag['method']}, tol {diag.get('tol', float('nan')):g}"
    return lockstep_figure(diag, out / f"diagnostics_{index}.png", f"{key} ({what})")


def _finite_or_nan(x):
    return float(x) if x is not None and math.isfinite(float(x)) else np.nan


def lockstep_figure(diag: dict, path, title: str = "") -> Path:
    """The figure of a diagnosis (``Diagnosis.to_dict()``; ``rfverify diagnose --plot`` and the
    report's lockstep section), per step k (from iterate k to k+1): digits of agreement of the
    double step with the exact one (v, u, Hr; r and z where r is unique) with the threshold and
    the digits the form's conditioning leaves; max cond(Q_p) in double and exactly; min λ2 of z
    and of Jᵀr̃ in double and exactly; and the criterion of the double run's iterates beside the
    exact continuation's (and the mpmath witness's).  The departure is marked in every panel
    (crimson), and the first step with fewer digits than the tolerance needs where it differs
    (orange, dashed)."""
    plt = _plt()
    from matplotlib.ticker import MaxNLocator

    its = diag["iterations"]
    k = np.array([r["iter"] for r in its], dtype=float)
    fig, axes = plt.subplots(1, 4, figsize=(17, 3.9))
    a1, a2, a3, a4 = axes
    for name, lab in (("digits_v", "$v$"), ("digits_u", "$u$"), ("digits_Hr", "$Hr$"), ("digits_r_t", "$r$"),
                      ("digits_z", "$z$")):
        y = np.array([_finite_or_nan(r.get(name)) for r in its], dtype=float)
        if np.all(np.isnan(y)):
            continue  # not measured (r not unique, or a local problem's v)
        # Below 0 there is no digit of agreement at all (the error exceeds the value): drawn at 0.
        a1.plot(k, np.clip(y, 0.0, DIGITS_CAP), marker="o", ms=3, label=lab)
    thr = np.array([_finite_or_nan(r.get("threshold")) for r in its], dtype=float)
    exp = np.array([_finite_or_nan(r.get("expected")) for r in its], dtype=float)
    if not np.all(np.isnan(thr)):
        a1.plot(k, np.clip(thr, 0.0, None), color="black", ls="--", lw=1.2, label="threshold")
    if not np.all(np.isnan(exp)):
        a1.plot(k, np.clip(exp, 0.0, None), color="gray", ls=":", lw=1.2, label="left by cond (form)")
    a1.set_xlabel("step k (iterate k → k+1)")
    a1.set_ylabel("digits of agreement, double vs exact step")
    a1.set_title("Rounding error of each step", fontsize=9)
    a1.set_ylim(bottom=0)
    a1.legend(fontsize=7, loc="lower left")
    for fam, lab, color in (("max_cond_Qp", "double", "tab:red"), ("max_cond_Qp_exact", "exact", "tab:purple")):
        y = np.array([_finite_or_nan(r.get(fam)) for r in its], dtype=float)
        if not np.all(np.isnan(y)):
            a2.semilogy(k, np.where(y > 0, y, np.nan), marker="o" if lab == "double" else None, ms=3, color=color,
                        ls="-" if lab == "double" else "--", label=f"cond($Q_p$) {lab}")
    a2.axhline(1 / np.finfo(float).eps, color="gray", ls=":", lw=1, label="1/ε (double)")
    a2.set_xlabel("step k (scaling at iterate k)")
    a2.set_ylabel("max cond($Q_p$) over cones")
    a2.set_title("Conditioning of the NT scaling", fontsize=9)
    a2.legend(fontsize=7)
    for fam, color in (("min_lam2_z", "tab:blue"), ("min_lam2_s", "tab:green")):
        dbl = np.array([_finite_or_nan(r[fam]["double"]) for r in its], dtype=float)
        ref = np.array([_finite_or_nan(r[fam]["reference"]) for r in its], dtype=float)
        label = "z" if fam.endswith("z") else r"J^T\tilde r"
        a3.semilogy(k, np.where(dbl > 0, dbl, np.nan), color=color, marker="o", ms=3,
                    label=rf"$\lambda_2({label})$ double")
        a3.semilogy(k, np.where(ref > 0, ref, np.nan), color=color, ls="--", label=rf"$\lambda_2({label})$ exact")
    events = [r["iter"] for r in its if r["flags"]]
    for e in events:
        a3.axvline(e, color="red", alpha=0.4, lw=1)
    a3.set_xlabel("step k (λ2 of iterate k+1)" + (" — red: λ2 lost in double" if events else ""))
    a3.set_ylabel(r"min $\lambda_2$ over cones")
    a3.set_title("Distance to the cone boundary", fontsize=9)
    a3.legend(fontsize=7, loc="best")
    crit = np.array([_finite_or_nan(r.get("criterion")) for r in its], dtype=float)
    a4.semilogy(k, np.where(crit > 0, crit, np.nan), marker="o", ms=3, color="tab:blue", label="double run")
    ev = diag.get("evidence") or {}
    for key, lab, style in (("exact", "exact, continued", "--"), ("exact_from_start", "exact, from the start", ":")):
        run = ev.get(key)
        if run and run.get("iterations"):
            kk = np.array([r["iter"] for r in run["iterations"]], dtype=float)
            cc = np.array([_finite_or_nan(r["criterion"]) for r in run["iterations"]], dtype=float)
            a4.semilogy(kk, np.where(cc > 0, cc, np.nan), ls=style, color="tab:orange" if key == "exact" else "tab:brown",
                        label=f"{lab} (double-double)")
    wit = (ev.get("witness") or {}).get("run")
    if wit and wit.get("criteria"):
        kk = wit["start"] + np.arange(len(wit["criteria"]), dtype=float)
        cc = np.array([_finite_or_nan(c) for c in wit["criteria"]], dtype=float)
        a4.semilogy(kk, np.where(cc > 0, cc, np.nan), ls="none", marker="x", color="black", label="mpmath witness")
    tol = diag.get("tol")
    if tol is not None and math.isfinite(float(tol)):
        a4.axhline(float(tol), color="gray", ls=":", lw=1, label=f"tol {float(tol):g}")
    a4.set_xlabel("iteration")
    a4.set_ylabel("criterion (DESIGN §4.5)")
    a4.set_title("The run and the exact algorithm", fontsize=9)
    a4.legend(fontsize=7, loc="best")
    dep, short = ev.get("departure"), ev.get("shortfall")
    if short and dep and short["iter"] == dep["iter"]:
        short = None  # one mark where they coincide
    for ax in axes:
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.grid(alpha=0.3, which="both")
        if dep:
            ax.axvline(dep["iter"], color="crimson", lw=1.5, alpha=0.7)
        if short:
            ax.axvline(short["iter"], color="darkorange", lw=1.5, ls="--", alpha=0.8)
    if dep:
        a1.annotate(f"departure: step {dep['iter']}", xy=(dep["iter"], 1), xycoords=("data", "axes fraction"),
                    xytext=(3, -10), textcoords="offset points", color="crimson", fontsize=8)
    if short:
        a1.annotate(f"< tol's digits: step {short['iter']}", xy=(short["iter"], 1), xycoords=("data", "axes fraction"),
                    xytext=(3, -22), textcoords="offset points", color="darkorange", fontsize=8)
    cause = diag.get("cause")
    head = f"{diag['status']} after {diag['nit']} iterations" + (f"; cause: {cause}" if cause else "")
    fig.suptitle(f"{title + ': ' if title else ''}{diag['method']}, {head}", fontsize=10)
    fig.tight_layout()
    path = Path(path)
    _save(fig, path)
    return path


def proven_digits_time(data: RunData, out: Path) -> Path | None:
    """The first screen's figure: the proven digits of every answer against its run time, one
    colour per method, the k-digit path as black stars; a line at the bench's k digits, and per
    method the median (time, digits) at each tolerance joined by a line."""
    k = int(data.manifest.get("digits") or 10)
    pts = {}
    for r in data.solves:
        d = (r.get("proven") or {}).get("answer")
        if d is not None and r.get("time") is not None:
            pts.setdefault(r["method"], []).append((r["time"], min(d, DIGITS_CAP), r["tol"]))
    from .aggregates import path_answer_digits

    path_pts = [(d["time"], min(x, DIGITS_CAP)) for d in data.digits.values()
                if d.get("time") is not None and (x := path_answer_digits(d)) is not None]
    if not pts and not path_pts:
        return None
    plt = _plt()
    fig, ax = plt.subplots(figsize=(8.4, 4.9))
    labels = []
    for m in [m for m in _STYLE if m in pts]:
        color, marker = _style(m)
        xs, ys, tols = zip(*pts[m])
        ax.scatter(np.maximum(xs, 1e-4), ys, color=color, marker=marker, s=16, alpha=0.35, lw=0.8)
        med = []
        for tol in sorted(set(tols), reverse=True):
            at = [(x, y) for x, y, t in pts[m] if t == tol]
            med.append((float(np.median([x for x, _ in at])), float(np.median([y for _, y in at]))))
        ax.plot([max(x, 1e-4) for x, _ in med], [y for _, y in med], color=color, marker=marker, ms=7, lw=1.6,
                label=f"{m} ({len(xs)} answers; line: medians per tolerance)")
        labels += [(max(x, 1e-4), y, f"{tol:g}", color)  # which median is which tolerance
                   for (x, y), tol in zip(med, sorted(set(tols), reverse=True))]
    if path_pts:
        xs, ys = zip(*path_pts)
        ax.scatter(xs, ys, color="black", marker="*", s=70, label=f"{k}-digit path ({len(xs)} problems)", zorder=5)
    ax.axhline(k, color="gray", ls="--", lw=1)
    ax.text(1.005, k, f"{k} digits", transform=ax.get_yaxis_transform(), va="center", fontsize=8, color="gray")
    _log_x(ax)
    ax.set_xlabel("wall time of the run (s)")
    ax.set_ylabel("proven correct digits (min of v, u, Hr)")
    ax.set_ylim(bottom=min(0, ax.get_ylim()[0]), top=max(DIGITS_CAP, k + 1))
    ax.grid(True, which="both", alpha=0.3)
    ax.set_title("Proven digits against time, every answer of every method (DESIGN §6: a rigorous bound at "
                 "each problem's proven point)", fontsize=9)
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.14), ncol=2, fontsize=8, frameon=False)
    fig.tight_layout()
    labels_apart(ax, labels)  # after the layout: the placement is in the final display coordinates
    path = out / "proven_digits.png"
    _save(fig, path)
    return path


def hard_iterations(picks: list, out: Path, method: str = "jqinv") -> Path | None:
    """cond(Q_p) and the smallest λ₂ (of z and Jᵀr̃) per iteration, for one representative hard
    problem per family (its ``method`` trajectory, every iterate)."""
    if not picks:
        return None
    plt = _plt()
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.4))
    cmap = plt.get_cmap("tab10")
    markers = (".", "s", "^", "v", "D")  # beyond ten families colours repeat: the marker tells them apart
    for i, p in enumerate(picks):
        color, mark = cmap(i % 10), markers[(i // 10) % len(markers)]
        its = p["trajectory"]["iterates"]
        k = np.arange(len(its))
        cond = np.array([it.get("max_cond_Qp") or np.nan for it in its], dtype=float)
        lam = np.array([min((x for x in (it.get("min_lam2_z"), it.get("min_lam2_s")) if x is not None),
                            default=np.nan) for it in its], dtype=float)
        label = f"{p['family']}: {p['problem'].rsplit('/', 1)[-1]}"
        ax1.plot(k, cond, color=color, marker=mark, ms=4, lw=1.2, label=label)
        ax2.plot(k, np.where(lam > 0, lam, np.nan), color=color, marker=mark, ms=4, lw=1.2)
        bad = np.flatnonzero(~(lam > 1e-300) & np.isfinite(lam))
        if bad.size:
            ax2.plot(k[bad], np.full(bad.size, 1e-300), "x", color=color, ms=8)
    ax1.axhline(1e15, color="gray", ls="--", lw=1)
    ax1.set_yscale("log")
    ax1.set_xlabel("iteration")
    ax1.set_ylabel("max cond(Q_p) over cones")
    ax1.set_title(f"cond(Q_p) per iteration ({method}, every iterate kept)", fontsize=9)
    ax2.axhline(1e-300, color="gray", ls="--", lw=1)
    ax2.set_yscale("log")
    ax2.set_xlabel("iteration")
    ax2.set_ylabel("min λ2 of z and Jᵀr̃ (x: ≤ 1e-300)")
    ax2.set_title("smallest λ2 per iteration", fontsize=9)
    for ax in (ax1, ax2):
        ax.grid(True, which="both", alpha=0.3)
    fig.legend(*ax1.get_legend_handles_labels(), loc="lower center", ncol=min(len(picks), 3), fontsize=7.5,
               frameon=False)
    rows = math.ceil(len(picks) / 3)
    fig.tight_layout(rect=(0, min(0.45, 0.06 * rows + 0.02), 1, 1))
    path = out / "hard_per_family.png"
    _save(fig, path)
    return path
