"""The multiple-precision tail of the k-digit path (rfverify.extended.wide): its Jordan kernels
against the mpmath reference, its contact factors and Newton solve, and the hyperstatic
lattice it proves where double-double stalls (DESIGN §6.5, DECISIONS "Multiple-precision tail")."""

from __future__ import annotations

import math

import gmpy2
import mpmath
import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

import rfverify
import rfverify.io.certificate
from reference import jordan as RJ
from rfverify.verify import digits as D
from rfverify.verify import driver as DR
from rfverify.verify import extend as E
from rfverify.verify import prepare as P
from rfverify.extended import wide, wide_data, wide_factor
from rfverify.extended.wide_cholesky import DenseWideCholesky
from rfverify.extended.data import ExtendedData
from rfverify.jordan import mpfr as JM
from rfverify.scenes.random_problems import random_problem
from rfverify.scenes import generate

BITS = wide.DEFAULT_BITS


def _cones(rng, n3, n1, gap_exp):
    """Interior cone vectors: L3 cones with λ₂/λ₁ down to 10^-gap_exp (far below what
    double-double resolves when gap_exp > 32), as mpfr built from λ₁, λ₂ and a direction in
    the working precision (so λ₂ is exact to ~1e-96 relative: far inside the cone)."""
    out = []
    for c in range(n3):
        l1 = gmpy2.mpfr(float(rng.uniform(0.5, 2.0)))
        l2 = l1 * gmpy2.mpfr(10) ** (-int(rng.integers(0, gap_exp + 1)))
        th = float(rng.uniform(0, 2 * math.pi))
        d1, d2 = gmpy2.cos(gmpy2.mpfr(th)), gmpy2.sin(gmpy2.mpfr(th))
        out += [(l1 + l2) / 2, (l1 - l2) / 2 * d1, (l1 - l2) / 2 * d2]
    out += [gmpy2.mpfr(float(rng.uniform(1e-3, 2.0))) for _ in range(n1)]
    return np.array(out, dtype=object)


def _mp(x):
    return mpmath.mpf(int(x.as_integer_ratio()[0])) / int(x.as_integer_ratio()[1])


@settings(max_examples=20)
@given(st.integers(0, 2**31), st.integers(0, 60))
@example(0, 60)  # cones 1e-60 from their boundary: double-double sees λ₂ = 0 there
@example(1, 0)
def test_wide_kernels_agree_with_the_reference(seed, gap_exp):
    """NT scaling (Q_p z = Q_{p⁻¹} s = λ), Q_{p^k}, ∘ and Jordan division against
    reference.jordan at 150 digits, to the working precision times the condition."""
    rng = np.random.default_rng(seed)
    n3, n1 = 3, 2
    with wide_data.context(BITS):
        z, s = _cones(rng, n3, n1, gap_exp), _cones(rng, n3, n1, gap_exp)
        y = wide_data.from_dd(rng.normal(size=3 * n3 + n1))
        sc, bad = JM.nt_scaling(n3, z, s)
        assert bad == -1
        Qz, Qs = JM.quad_pow(n3, 1, sc, z), JM.quad_pow(n3, -1, sc, s)
        prods = {k: JM.quad_pow(n3, k, sc, y) for k in (1, -1, 2, -2)}
        zs = JM.product(n3, z, s)
        back = JM.arrow_solve(n3, z, zs)
    ctx = RJ.context(150)
    with mpmath.workdps(150):
        for c in range(n3 + n1):
            sl = slice(3 * c, 3 * c + 3) if c < n3 else slice(3 * n3 + c - n3, 3 * n3 + c - n3 + 1)
            zc, scc, yc = ([_mp(x) for x in a[sl]] for a in (z, s, y))
            p_ref, _, lam_ref = RJ.nt_scaling(RJ.to_ctx(ctx, zc), RJ.to_ctx(ctx, scc))
            kappa = max(float(RJ.cond_quad(zc)), float(RJ.cond_quad(scc)))
            tol = 2.0 ** (-BITS + 30) * kappa
            lam_scale = float(max(abs(x) for x in lam_ref))
            for got in (sc.lam[sl], Qz[sl], Qs[sl]):  # all three are λ
                assert max(abs(_mp(a) - b) for a, b in zip(got, lam_ref)) <= tol * lam_scale
            for k, o in prods.items():
                want = RJ.quad_apply(RJ.power(p_ref, k), yc)
                ref_scale = float(max(abs(x) for x in yc)) * float(max(RJ.spectral_values(RJ.power(p_ref, k)))) ** 2
                assert max(abs(_mp(a) - b) for a, b in zip(o[sl], want)) <= tol * ref_scale
            assert max(abs(_mp(a) - b) for a, b in zip(back[sl], scc)) <= tol * float(max(abs(x) for x in scc))


def test_nt_scaling_refuses_a_point_outside_the_cone():
    with wide_data.context(BITS):
        z = wide_data.from_dd(np.array([1.0, 0.6, 0.8, 1.0]))  # λ₂ = 0: on the boundary
        s = wide_data.from_dd(np.array([1.0, 0.0, 0.0, 1.0]))
        sc, bad = JM.nt_scaling(1, z, s)
    assert sc is None and bad == 0


def test_max_step_is_the_distance_to_the_boundary():
    """x + α·dx stays in the cone up to α = max_step and leaves it just after."""
    rng = np.random.default_rng(5)
    with wide_data.context(BITS):
        x = _cones(rng, 4, 2, 50)
        dx = wide_data.from_dd(rng.normal(size=14))
        a = JM.max_step(4, x, dx)
        assert 0 < a < math.inf
        inside = JM.lambda2(4, x + (a * (1 - 1e-12)) * dx)
        outside = JM.lambda2(4, x + (a * (1 + 1e-12)) * dx)
    assert all(v >= 0 for v in inside) and any(v < 0 for v in outside)


def _interior_scaling(problem, gap_exp, seed=0):
    data = ExtendedData(problem)
    rng = np.random.default_rng(seed)
    with wide_data.context(BITS):
        z, s = _cones(rng, data.n3, data.n1, gap_exp), _cones(rng, data.n3, data.n1, gap_exp)
        sc, bad = JM.nt_scaling(data.n3, z, s)
    assert bad == -1
    return data, sc


def test_contact_factor_inverse_whitens_every_contact_kind():
    """F_c⁻¹ G_c F_c⁻ᵀ = I with G_c = J_c Q_{p⁻²} J_cᵀ formed directly, for full contacts,
    friction-only, rolling-only and normal rays, at a scaling whose eigenvalues span 1e±40."""
    problem = random_problem(6, 12, seed=3, mu_zero_fraction=0.25, mu_r_zero_fraction=0.25)
    data, sc = _interior_scaling(problem, 40)
    assert set(np.unique(data.kinds)) >= {0, 1, 2}
    with wide_data.context(BITS):
        Finv = wide_factor.contact_factor_inverse(data, sc)
        J = data.lp.J.tocsr()
        worst = 0.0
        for c in range(data.n):
            rows = np.arange(data.row_start[c], data.row_start[c] + data.row_count[c])
            k = rows.size
            cols = np.unique(J[rows].indices)
            G = np.empty((k, k), dtype=object)
            for b in range(k):
                e = wide_data.zeros(data.nk)
                e[rows[b]] = gmpy2.mpfr(1)
                col = wide_data.WideMatrix(data.J) @ JM.quad_pow(data.n3, -2, sc, wide_data.WideMatrix(data.JT) @ e)
                G[:, b] = col[rows]
            assert cols.size > 0
            Fc = Finv[c, :k, :k]
            I = np.matmul(np.matmul(Fc, G), Fc.T)
            worst = max(worst, max(float(abs(I[a, b] - (1 if a == b else 0))) for a in range(k) for b in range(k)))
    assert worst <= 2.0 ** (-BITS + 150), worst  # G_c's condition ≈ 1e80 eats 80 digits of 96


def test_dense_dof_space_solves_the_newton_system_to_working_precision():
    """M dv − H̃ᵀ dr̃ = a and H̃ dv + G dr̃ = t at a scaling with cones 1e-40 from the boundary."""
    problem = rfverify.load("bundled:chute")
    data, sc = _interior_scaling(problem, 40, seed=2)
    rng = np.random.default_rng(1)
    with wide_data.context(BITS):
        W = wide_data.WideData(data)
        back = wide_factor.WideDofSpace(data, W, DenseWideCholesky)
        assert back.update(sc)
        a, t = wide_data.from_dd(rng.normal(size=data.m)), wide_data.from_dd(rng.normal(size=data.nk))
        dv, dr = back.solve(a, t)
        residual = newton_residual(data, W, sc, a, t, dv, dr)  # in the tail's precision
    assert residual <= 1e-50


def newton_residual(data, W, sc, a, t, dv, dr) -> float:
    """Residual of the tail's Newton system [[M, −H̃ᵀ], [H̃, G]] (dv, dr) = (a, t), relative to
    the largest term (and 1); call it inside the tail's precision context."""
    Gdr = W.J @ JM.quad_pow(data.n3, -2, sc, W.JT @ dr)
    e1 = W.M @ dv - W.HtT @ dr - a
    e2 = W.Ht @ dv + Gdr - t
    scale = max(wide_data.inf_norm(W.M @ dv), wide_data.inf_norm(W.HtT @ dr), wide_data.inf_norm(Gdr), 1.0)
    return max(wide_data.inf_norm(e1), wide_data.inf_norm(e2)) / scale


def test_the_tail_leaves_the_precision_as_it_found_it():
    before = gmpy2.get_context().precision
    problem = rfverify.load("bundled:chute")
    out = rfverify.solve_to_digits(problem, digits=10)
    data = ExtendedData(problem)
    it = out.extended
    start = {"v": (it.v.h, it.v.l), "r_t": (it.r_t.h, it.r_t.l), "z": (it.z.h, it.z.l)}
    wide.run(data, start, max_iter=1)
    assert gmpy2.get_context().precision == before


# ---------------------------------------------------------------------- the hyperstatic lattice
@pytest.fixture(scope="module")
def lattice():
    """80 contacts on 20 spheres, 4 per sphere (hyperstatic), at rest under gravity: v* is
    about 1e-10 of ‖M⁻¹f‖∞, so 10 relative digits need rᵀu ≈ 1e-48."""
    problem = generate("Lattice", count=1, seed=0, size=20)[0]
    assert (problem.n_contacts, problem.n_dofs) == (80, 120)
    return problem, rfverify.solve_to_digits(problem, digits=10)


_TRUTH = {}


def _truth(problem):
    """v* and u* from the independent mpmath reference at 80 digits (gap 1e-55)."""
    import reference

    if "lattice" not in _TRUTH:
        ref = reference.solve(problem, dps=80, tol=1e-55)
        assert ref.success, ref.message
        _TRUTH["lattice"] = ref
    return _TRUTH["lattice"]


def test_double_double_alone_stalls_on_the_lattice_and_says_so(lattice):
    problem, _ = lattice
    out = rfverify.solve_to_digits(problem, digits=10, wide_tail=False)
    assert not out.success
    assert out.wide is None and "switched off" in out.certificate.extra["wide_tail"]
    assert out.certificate.quantities["v"].digits < 6


def test_the_tail_proves_ten_digits_of_the_lattice_and_they_are_true(lattice):
    problem, out = lattice
    assert out.success, out.certificate.verdict
    assert out.wide is not None and out.wide.bits == BITS
    extra = out.certificate.extra
    assert extra["wide_iterations"] == out.wide.nit > 0 and "multiple-precision" in extra["point_source"]
    # the tail's steps shorter than 1, each with the cone whose boundary cut it short
    assert [h["from_iteration"] for h in extra["wide_steps_held"]] == [
        k for k, a in enumerate(out.wide.trace["alpha"]) if a < 1]
    assert extra["wide_steps_held"] and all({"contact", "part", "side"} <= set(h) for h in extra["wide_steps_held"])
    assert out.point.terms == -(-BITS // 53)
    ref = _truth(problem)
    with mpmath.workdps(80):
        for name, x in (("v", out.v), ("u", out.u)):
            err = max(abs(mpmath.mpf(float(a)) - b) for a, b in zip(x, getattr(ref, name)))
            q = out.certificate.quantities[name]
            assert err <= q.abs_bound, (name, float(err), q.abs_bound)
            scale = max(abs(b) for b in getattr(ref, name))
            assert q.own_scale <= scale and err <= 1e-10 * scale


def test_the_tail_solves_its_newton_systems_as_inexactly_as_double_double(lattice, monkeypatch):
    """The tail's Newton solves stop at the same per-block η as the double-double phase's
    (predictor 1e-2, corrector 1e-8), each against its own floor; the proof above checks the
    digits that come of it against the reference."""
    import rfverify.algorithm.newton as N
    from rfverify.algorithm import rules

    problem, _ = lattice
    asked = []

    def spy(*args, floor, enough, **kw):
        asked.append((floor, enough))
        return rules.refined_newton(*args, floor=floor, enough=enough, **kw)

    monkeypatch.setattr(N, "refined_newton", spy)
    out = rfverify.solve_to_digits(problem, digits=10)
    assert out.success and out.wide is not None
    tail = [enough for floor, enough in asked if floor == 2.0 ** (24 - BITS)]
    assert len(tail) >= 2 * out.wide.nit > 0
    assert set(tail[0::2]) == {N.PREDICTOR_ENOUGH} and set(tail[1::2]) == {N.NEWTON_ENOUGH}


@pytest.mark.parametrize("digit", [9, 11])
def test_a_perturbed_lattice_solution_is_judged_by_the_tails_point(lattice, digit):
    """The tail's point certifies the returned v but not v changed in its 9th digit."""
    problem, out = lattice
    v = out.v.copy()
    big = np.abs(v) >= 0.5 * np.abs(v).max()
    v[big] *= 1 + 3 * 10.0 ** (-digit)
    cert = rfverify.certify(problem, v, out.u, out.r, digits=10, point=out.point)
    assert cert.certified == (digit == 11), cert.verdict


def test_the_tails_certificate_rechecks_from_the_file(lattice, tmp_path, capsys):
    from rfverify.cli import main

    problem, _ = lattice
    src = tmp_path / "lattice.hdf5"
    rfverify.save(problem, src)
    sol = tmp_path / "lattice-sol.h5"
    assert main(["solve", str(src), "--digits", "10", "--out", str(sol)]) == 0
    out = capsys.readouterr().out
    assert "multiple-precision (320 bits) iterations" in out and "multiple precision" in out
    point = rfverify.io.certificate.read_point(sol)
    assert point.v_more is not None and point.v_more.shape[1] == problem.n_dofs
    assert main(["certify", str(src), "--solution", str(sol)]) == 0
    assert "proven to 10 digits" in capsys.readouterr().out


def test_a_malformed_tail_point_in_the_file_is_refused(lattice, tmp_path):
    import h5py

    problem, out = lattice
    sol = tmp_path / "sol.h5"
    rfverify.save(problem, sol)
    with h5py.File(sol, "a") as fh:
        rfverify.io.certificate.write_certificate(fh, out.certificate, problem)
        del fh["certificate/point/r_more"]
    with pytest.raises(rfverify.ProblemFileError, match="v_more and r_more"):
        rfverify.io.certificate.read_point(sol)
    with h5py.File(sol, "a") as fh:
        fh["certificate/point"].create_dataset("r_more", data=np.zeros((2, 3)))
    with pytest.raises(rfverify.ProblemFileError, match="r_more must be a 2-D float dataset"):
        rfverify.io.certificate.read_point(sol)


def test_the_tail_factors_sparsely_and_has_no_limit_in_dofs(lattice):
    """Issue 27: the tail's factor is sparse (memory O(nnz(L))); only its predicted cost
    limits it, so the old 3000-dof limit is gone."""
    _, out = lattice
    assert out.wide is not None and out.wide.backend == "sparse dof-space (M + H̃ᵀG⁻¹H̃), multiple precision"
    assert not hasattr(D, "WIDE_MAX_DOFS")


def test_handover_skips_iterates_outside_the_cones(lattice):
    """The last double-double iterates of a stalled run may leave the cones in exact
    arithmetic; the handover takes the latest one that is interior and centred."""
    problem, _ = lattice
    out = rfverify.solve_to_digits(problem, digits=10, wide_tail=False)
    data = ExtendedData(problem)
    driver = DR.ProofDriver(P.ProofContext(problem), data, 10)
    E.extend(data, P.start_from(data, out.double), driver, P.choose_backend(data), wide_tail=False)
    good = wide.handover(data, driver.recent)
    assert good is not None
    broken = driver.recent[-1]
    z = broken.z.h.copy()
    z[0] = -1.0  # first cone's head negative: not interior
    spoiled = type(broken)(broken.k + 100, broken.v, broken.r_t, type(broken.z)(z, broken.z.l), broken.mu,
                           broken.pinfeas, broken.dinfeas)
    assert wide.handover(data, driver.recent + [spoiled]) is good


def test_help_states_the_tails_limits(capsys):
    from rfverify.cli import main

    with pytest.raises(SystemExit):
        main(["solve", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert f"{wide.DEFAULT_BITS}-bit" in text
    assert f"at most {E.WIDE_MAX_FACTOR_OPS:.0e}".replace("e+0", "e") in text


def test_the_tail_gives_up_where_no_point_can_be_proven(monkeypatch):
    """A Chute whose wedge contacts leave no strictly feasible point: without the face step
    (issue 45) every proof is invalid, and the tail stops after WIDE_GIVE_UP of them instead of
    running its 40 iterations."""
    from pathlib import Path

    from rfverify.proof import face

    monkeypatch.setattr(face, "find_self_stress", lambda *a, **k: [])
    problem = rfverify.load(Path(__file__).parent / "data" / "hard" / "Chute-ndof-24-nc-4-0.hdf5")
    out = rfverify.solve_to_digits(problem, digits=10)
    assert not out.success and not out.certificate.proof.valid
    assert out.wide is not None and out.wide.nit < E.WIDE_GIVE_UP + 2
    assert f"{E.WIDE_GIVE_UP} proofs in a row were invalid" in out.certificate.extra["wide_tail"]
    assert "no self-stress" in out.message  # the verdict says what was looked for


def test_the_wedge_chute_is_proven_on_its_face():
    """The same Chute with the face step: its self-stress (contacts 2 and 3) is found and
    verified exactly, the point moved onto the face, and 10 digits proven; r is not unique."""
    from pathlib import Path

    problem = rfverify.load(Path(__file__).parent / "data" / "hard" / "Chute-ndof-24-nc-4-0.hdf5")
    out = rfverify.solve_to_digits(problem, digits=10)
    assert out.success, out.message
    face = out.certificate.proof.face
    assert face is not None and [list(s.contacts) for s in face.stresses] == [[2, 3]]
    assert out.certificate.proof.quantities["r"].mode == "information"
    assert "self-stress" in out.certificate.proof.quantities["r"].note


def test_certify_without_a_stored_point_goes_on_to_the_tail(lattice):
    """certify of the 10-digit lattice solution, given no point: the polish must not stop while
    the point's own bound still dominates (√(M⁻¹)_jj ≈ 2e3 here), and the tail proves it."""
    problem, out = lattice
    cert = rfverify.certify(problem, out.v, out.u, out.r, digits=10)
    assert cert.certified, cert.verdict
    assert "multiple-precision" in cert.extra["point_source"] and cert.extra["wide_iterations"] > 0


def test_the_tail_is_skipped_when_its_factor_would_be_too_costly(lattice, monkeypatch):
    problem, _ = lattice
    _, ops = wide_factor.dof_space_ordering(ExtendedData(problem))
    assert 0 < ops < E.WIDE_MAX_FACTOR_OPS
    monkeypatch.setattr(E, "WIDE_MAX_FACTOR_OPS", ops / 2)
    out = rfverify.solve_to_digits(problem, digits=10)
    assert not out.success and out.wide is None and "multiply-subtract pairs" in out.certificate.extra["wide_tail"]


def test_a_singular_contact_factor_in_the_tail_is_a_status_not_a_crash(lattice, monkeypatch):
    problem, _ = lattice

    def singular(data, sc):
        raise ArithmeticError("a contact's factor is singular")

    monkeypatch.setattr(wide_factor, "contact_factor_inverse", singular)
    out = rfverify.solve_to_digits(problem, digits=10)
    assert not out.success and out.wide is not None and out.wide.status == "NumericalError"
    assert "singular" in out.certificate.extra["wide_tail"]
