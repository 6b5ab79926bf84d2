"""The live solver log (``verbose=True``): a settings header, then one row per iteration as it
happens, labelled by component when the problem is solved as several independent components,
and a closing line.  Rows are printed from :class:`~rfverify.solver.result.IterationInfo`, the
same record a ``callback`` receives."""

from __future__ import annotations

import sys

from ..engines.factor import schur_engine_name
from ..model.lifting import cone_words

COLUMNS = (("iteration", "iter", "{:>4d}"), ("criterion", "criterion", "{:>10.2e}"),
           ("pinfeas", "pinfeas", "{:>9.2e}"), ("dinfeas", "dinfeas", "{:>9.2e}"), ("mu", "mu", "{:>9.2e}"),
           ("sigma", "sigma", "{:>9.2e}"), ("alpha_aff", "alpha_aff", "{:>9.2e}"), ("alpha", "alpha", "{:>9.2e}"),
           ("min_lam2_z", "min λ2(z)", "{:>10.2e}"), ("min_lam2_s", "λ2(Jᵀr̃)", "{:>10.2e}"),
           ("max_cond_Qp", "cond(Qp)", "{:>9.2e}"), ("solve_residual", "solve res", "{:>9.2e}"),
           ("elapsed", "time [s]", "{:>8.3f}"))
HELD_BY = "held by"
"""The last column: the cone whose boundary cut the row's step α short (blank for a full step)."""


def settings_header(problem, method: str, settings, cone_counts: dict) -> str:
    """The settings block printed before the iterations (also used by the CLI)."""
    from .._version import __version__

    st = settings
    form = f"{method} (factored by {schur_engine_name()})" if method == "schur" else method
    lines = [
        "-" * 78,
        f"rfverify {__version__}: Algorithm 1 (Mehrotra predictor-corrector, NT scaling), form {form}",
        "-" * 78,
        f"problem:  {problem.title or problem.source}",
        f"          m = {problem.n_dofs} dofs, n = {problem.n_contacts} contacts, "
        f"nnz(M) = {problem.M.nnz}, nnz(H) = {problem.H.nnz}",
        "cones:    " + ", ".join(f"{v} {k}" for k, v in cone_counts.items() if v)
        + " (full: L3×L3, coulomb/rolling: L3, normal: L1)",
        f"settings: tol = {st.tol:g} (rfverify.model.measures criterion), max_iter = {st.max_iter}, "
        f"start = {st.start}, sigma_rule = {st.sigma_rule}, gamma0 = {st.gamma0}"
        + (f", time_limit = {st.time_limit:g} s" if st.time_limit else ""),
        f"          longdouble: jordan = {st.longdouble_jordan}, residuals = {st.longdouble_residuals}, "
        f"refinement = {st.refine_longdouble} (max {st.refine_max} steps, refine_tol = {st.refine_tol}), "
        + ("from the start" if st.longdouble_below is None else
           f"once the criterion is ≤ {st.longdouble_below:g} or a float64 solve falls short"),
        f"          static_reg = {st.static_reg:g}, adaptive_reg = {st.adaptive_reg}, "
        f"stall_iterations = {st.stall_iterations}, compiled_kernels = {st.compiled_kernels}",
        f"presolve: reduce_cones = {st.reduce_cones}, drop_free_bodies = {st.drop_free_bodies}, "
        f"split_components = {st.split_components}",
    ]
    return "\n".join(lines)


def _shown(label: str) -> int:
    """Display width of a label (combining marks, as in r̃, take no column)."""
    import unicodedata

    return sum(not unicodedata.combining(ch) for ch in label)


def column_header(labelled: bool) -> str:
    head = " ".join(" " * max(0, len(fmt.format(0 if "d" in fmt else 0.0)) - _shown(label)) + label
                    for _, label, fmt in COLUMNS)
    return ("comp " if labelled else "") + head + "  " + HELD_BY


def row(info, labelled: bool) -> str:
    """One table row; a quantity the final row has no value for (no step was taken: σ, α,
    cond(Qp), the solve residual) is printed as "-", not "nan"; the last column names the cone
    that held a step shorter than 1."""
    cells = []
    for name, _, fmt in COLUMNS:
        val = getattr(info, name)
        width = len(fmt.format(0 if "d" in fmt else 0.0))
        if "d" in fmt:
            cells.append(fmt.format(int(val)))
        elif val is None or val != val:
            cells.append(f"{'-':>{width}}")
        else:
            cells.append(fmt.format(float(val)))
    held = getattr(info, "held_by", None)
    if held is not None and "contact" in held:
        cells.append(" " + cone_words(held))
    return (f"{info.component:>4d} " if labelled else "") + " ".join(cells)


class IterationPrinter:
    """Prints the header at construction and a row per call (``printer(info)``)."""

    def __init__(self, problem, method, settings, lp, components: int = 1, stream=None):
        self.stream = stream or sys.stdout
        self.labelled = components > 1
        print(settings_header(problem, method, settings, lp.reduction_counts()), file=self.stream)
        if self.labelled:
            print(f"solved as {components} independent components (column 'comp')", file=self.stream)
        print(column_header(self.labelled), file=self.stream)
        print("-" * _shown(column_header(self.labelled)), file=self.stream, flush=True)

    def __call__(self, info):
        print(row(info, self.labelled), file=self.stream, flush=True)

    def summary(self, result):
        print("-" * _shown(column_header(self.labelled)), file=self.stream)
        print(f"status {result.status}: {result.message}", file=self.stream)
        free = int(result.presolve.get("free_dofs", 0) or 0)
        # The rows judge each iterate on its own run's data; say so where that is not the whole problem.
        apart = ([f"without the {free} contact-free dofs"] if free else []) + (
            ["each component on its own"] if self.labelled else [])
        rows = f" (the rows judge each iterate {', '.join(apart)})" if apart else ""
        print(f"criterion of the returned (v, u, r) on the whole problem: {result.criterion:.2e}{rows}; "
              f"time in the solver {result.timings.get('total', float('nan')):.3f} s", file=self.stream, flush=True)
