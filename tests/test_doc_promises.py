"""What the docs promise, at the edges an audit of REFERENCE.md, RESULTS.md and every --help
against the behaviour found broken: all-zero data under --relative, integers read inexactly,
scene parameters that build no scene, the Coulomb start's label, certify's time limit beside a
stored certificate, RFVERIFY_THREADS for every command, certify's --dps, the bench file names."""

from __future__ import annotations

import numpy as np
import pytest

import rfverify
from rfverify.cli.app import main


@pytest.fixture(scope="module")
def zero_data():
    p = rfverify.load("bundled:chute")
    return rfverify.Problem.from_arrays(p.M, p.H, 0 * p.f, 0 * p.w, p.mu, p.mu_r)


def test_all_zero_data_under_relative_digits_is_not_certified_not_a_crash(zero_data, tmp_path):
    """f = w = 0 with relative digits demanded crashed (ZeroDivisionError, exit 3) in the extended
    phase started from the exact zero answer; a zero has no relative digits, and that is the verdict."""
    out = rfverify.solve_to_digits(zero_data, digits=5, relative=True)
    assert out.status == "NotCertified" and out.extended.nit == 0
    assert "v* = 0 exactly" in out.certificate.verdict
    assert rfverify.solve_to_digits(zero_data, digits=5).status == "Certified"
    zeros = np.zeros(zero_data.n_dofs), np.zeros(5 * zero_data.n_contacts), np.zeros(5 * zero_data.n_contacts)
    cert = rfverify.certify(zero_data, *zeros, digits=5, relative=True)
    assert cert.status == "NotCertified" and cert.bounds["v"] == 0.0
    path = tmp_path / "zero.h5"
    rfverify.save(zero_data, path)
    assert main(["solve", str(path), "--digits", "5", "--relative", "--quiet"]) == 1


@pytest.mark.parametrize("value, exact", [(2**53 + 1, False), (-(2**53) - 1, False), (2**62 + 1, False),
                                          (2**63 - 1, False), (2**53 + 2, True), (2**62, True), (7, True)])
def test_integers_are_read_only_where_float64_holds_them_exactly(tmp_path, value, exact):
    """'Nothing is read inexactly': 2^53 + 1 was read as 2^53 (the test cast first, then compared
    with 2^53), and 2^53 + 2, which float64 holds, was refused."""
    import h5py

    from rfverify.errors import ProblemFileError

    path = tmp_path / "ints.h5"
    rfverify.save(rfverify.load("bundled:chute"), path)
    with h5py.File(path, "r+") as f:
        grp = f["fclib_global_rolling/vectors"]
        w = np.zeros(grp["w"].shape, dtype=np.int64)
        w[3] = value
        del grp["w"]
        grp["w"] = w
    if exact:
        assert rfverify.load(path).w[3] == value
    else:
        with pytest.raises(ProblemFileError, match=f"{value} at index 3"):
            rfverify.load(path)


@pytest.mark.parametrize("scene, params, says", [
    ("Chute", dict(radius_max=0.02), "radius_min = 0.03 is above radius_max = 0.02"),
    ("AllOpen", dict(radius_max=0.005), "radius_min = 0.008 is above radius_max"),
    ("Chute", dict(stream_packing=0), "stream_packing = 0 must be in"),
    ("PrimitiveSoup", dict(rain_packing=1e-300), "rain_packing = 1e-300 must be in"),
    ("ElasticBlock", dict(cell=1e-300), "the parameters given (cell=1e-300) build no scene"),
])
@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # numpy's, on the way to the singular factor
def test_scene_parameters_that_build_no_scene_are_refused_with_the_fix(scene, params, says):
    """These ended in exit 3 (ValueError: high - low < 0, OverflowError, a singular factor)."""
    from rfverify.scenes import generate
    from rfverify.scenes.stepper import SceneError

    with pytest.raises(SceneError, match="fix:") as err:
        generate(scene, size=5 if scene != "ElasticBlock" else 2, **params)
    assert says in str(err.value)
    assert main(["generate", scene, "--out", "/nonexistent-never-written", "--quiet", "--size", "5",
                 *[a for k, v in params.items() for a in ("--param", f"{k}={v}")]]) == 2


def test_a_coulomb_run_from_zero_is_labelled_from_zero_after_its_friction_continuation(tmp_path):
    """The continuation's stages start from scaled shifts, and the last stage's label leaked out:
    the run said 'from the --start shift' and JSON "start": "given shift" where none was given."""
    from pathlib import Path

    path = Path(__file__).parent / "data" / "hard" / "MassRatio-ndof-240-nc-101-1-3d.hdf5"
    run = rfverify.solve(rfverify.load(str(path)), problem="coulomb")
    assert len(run.outer.stages) > 1  # the continuation ran
    assert not run.outer.started and run.outer.as_dict()["start"] == "zero"


def test_certify_cut_short_beside_a_stored_certificate_is_max_time(tmp_path, capsys):
    """certify --help: 'stop the search … after S seconds … (status MaxTime when short of --digits)'.
    With the file's stored point proving 6 of 10 digits and no time left for a point of its own,
    the status was NotCertified and the verdict did not mention the limit."""
    import json

    path = tmp_path / "chute6.h5"
    assert main(["solve", "bundled:chute", "--digits", "6", "--out", str(path), "--quiet"]) == 0
    capsys.readouterr()
    assert main(["certify", "bundled:chute", "--solution", str(path), "--time-limit", "1e-9", "--json"]) == 1
    out = json.loads(capsys.readouterr().out)
    assert out["status"] == "MaxTime" and "time limit of 1e-09 s" in out["verdict"]
    assert main(["certify", "bundled:chute", "--solution", str(path), "--json"]) == 1  # a 6-digit answer, searched
    out = json.loads(capsys.readouterr().out)
    assert out["status"] == "NotCertified" and "time limit" not in out["verdict"]


@pytest.mark.parametrize("command", [["certify", "bundled:sphere", "--solution", "bundled:sphere"],
                                     ["solve", "bundled:sphere"], ["info", "bundled:sphere"]])
def test_a_bad_rfverify_threads_is_refused_by_every_command_before_any_work(command, monkeypatch, capsys):
    """REFERENCE: 'RFVERIFY_THREADS=N (an integer ≥ 1) … a bad value: exit code 2 before anything
    is solved'; only solve --digits checked it (certify ran and exited 1, bench exited 0)."""
    monkeypatch.setenv("RFVERIFY_THREADS", "abc")
    assert main(command) == 2
    assert "RFVERIFY_THREADS" in capsys.readouterr().err


def test_the_cross_check_reference_must_outdo_float64(capsys):
    """certify --cross-check --dps 1 printed 'agreement u -13.2, r -0.0': a reference at one digit."""
    from rfverify.errors import InvalidArgumentError

    with pytest.raises(SystemExit) as stop:
        main(["certify", "bundled:sphere", "--solution", "bundled:sphere", "--cross-check", "--dps", "1"])
    assert stop.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--dps" in err[0] and "34" in err[0]
    p = rfverify.load("bundled:sphere")
    with pytest.raises(InvalidArgumentError, match="dps"):
        rfverify.certify(p, np.zeros(p.n_dofs), None, np.zeros(5 * p.n_contacts), cross_check=True, dps=10)


def _sphere_in_a_corner(mu: float) -> rfverify.Problem:
    """A sphere (m = 1, I = 4e-5) held by two walls whose normals (±1, 0, 2) meet in a μ > 2 corner:
    y = (1, ±2, 0, 0, 0) is a self-stress strictly inside K (from the fresh-data audit)."""
    import scipy.sparse as sp

    H = np.zeros((6, 10))
    for k, s in enumerate((1.0, -1.0)):
        N, T1, T2 = np.array([s, 0, 2.0]), np.array([2.0, 0, -s]), np.array([0, 1.0, 0])
        rho = -np.array([s, 0, 2.0]) / 4
        for j, d in enumerate((N, T1, T2)):
            H[0:3, 5 * k + j] = d
            H[3:6, 5 * k + j] = np.cross(rho, d)
        H[3:6, 5 * k + 3], H[3:6, 5 * k + 4] = T1 / 8, T2 / 8
    M = sp.diags([1.0] * 3 + [4e-5] * 3).tocsc()
    return rfverify.Problem.from_arrays(M, sp.csc_matrix(H), np.array([1e-2, 3e-3, -1e-2, 1e-5, 2e-5, -1e-5]),
                                        np.zeros(10), np.array([mu, mu]), np.zeros(2))


def test_a_cross_check_whose_reference_breaks_down_says_so(tmp_path, capsys):
    """The reference's factorisation fails along the self-stress of a μ = 5 corner: certify
    --cross-check crashed (ArithmeticError, exit 3); the proof stands, the opinion is missing."""
    p = _sphere_in_a_corner(5.0)
    sol = rfverify.solve_to_digits(p, 10)
    assert sol.certificate.certified
    cert = rfverify.certify(p, sol.v, sol.u, sol.r, cross_check=True)
    assert cert.certified and cert.cross_check["reference_status"] == "BrokeDown"
    assert "the reference broke down" in cert.cross_check["note"]


def test_bodies_at_rest_with_every_contact_open_are_proven_exactly():
    """f = 0 and w ∈ K* (one open contact): v = 0, r = 0 is the answer exactly. The path proved no
    digits after 80 double-double and 40 multiple-precision iterations (bound 1.2e-7 on v)."""
    import scipy.sparse as sp

    M = sp.diags([1.0, 1.0, 1.0, 1e-4, 1e-4, 1e-4]).tocsc()
    H = np.zeros((6, 5))
    H[2, 0] = H[0, 1] = H[1, 2] = H[3, 3] = H[4, 4] = 1.0
    H[3, 2], H[4, 1] = -0.01, 0.01
    w = np.array([0.1, 0, 0, 0, 0])
    p = rfverify.Problem.from_arrays(M, sp.csc_matrix(H), np.zeros(6), w, [0.3], [1e-3])
    out = rfverify.solve_to_digits(p, 10)
    assert out.certificate.certified and out.extended.nit == 0
    assert not out.v.any() and not out.r.any() and out.certificate.bounds["v"] == 0.0
    assert out.certificate.extra["point_source"].startswith("v = 0, r = 0")
    closed = rfverify.Problem.from_arrays(M, sp.csc_matrix(H), np.zeros(6), -w, [0.3], [1e-3])  # w ∉ K*
    assert rfverify.solve_to_digits(closed, 10).certificate.extra["point_source"] != out.certificate.extra["point_source"]


def test_a_plot_is_written_in_the_format_its_name_says(tmp_path):
    """diagnose --plot plot.pdf wrote PNG bytes into the .pdf."""
    for name, magic in (("f.pdf", b"%PDF"), ("f.svg", b"<?xml"), ("f.png", b"\x89PNG")):
        assert main(["diagnose", "bundled:sphere", "--plot", str(tmp_path / name), "--quiet", "--no-remedy"]) == 0
        assert (tmp_path / name).read_bytes().startswith(magic)


@pytest.mark.parametrize("argv, flag", [
    (["solve", "bundled:chute", "--relative"], "--relative"),
    (["solve", "bundled:chute", "--json", "--verbose"], "--verbose"),
    (["certify", "bundled:sphere", "--solution", "bundled:sphere", "--dps", "60"], "--dps"),
    (["diagnose", "bundled:sphere", "--plot", "figure.jpg"], "--plot"),
])
def test_a_flag_that_would_do_nothing_is_refused_not_ignored(argv, flag, capsys, tmp_path, monkeypatch):
    """Audit (2026-12-08): --relative without --digits, --dps without --cross-check, --verbose
    under --json and a --plot name whose extension is no format were accepted and ignored (exit 0;
    the figure written as PNG under a .jpg name)."""
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and flag in err[0] and "fix:" in err[0]
    assert not (tmp_path / "figure.jpg").exists()


def test_a_self_stress_strictly_inside_k_near_its_boundary_is_found():
    """At μ = 2 + 2⁻³⁰ the stress (1, ±2, 0, 0, 0) lies inside K within 1e-4 of its boundary: it was
    snapped onto the boundary, missed, and the verdict said 'the feasible set may have an
    interior'. Found, the problem is proven; with wᵀy < 0 it is called infeasible."""
    p = _sphere_in_a_corner(2.0 + 2.0 ** -30)
    p = rfverify.Problem.from_arrays(p.M, p.H, np.array([0, 0, -1e-2, 0, 0, 0]), p.w, p.mu, p.mu_r)
    out = rfverify.solve_to_digits(p, 10)
    assert out.certificate.certified and "r not unique" in out.certificate.verdict
    w = np.zeros(10)
    w[0] = w[5] = -1e-3  # y = (1, 2, 0, 0, 0 | 1, −2, 0, 0, 0): wᵀy = −2e-3 < 0
    bad = rfverify.Problem.from_arrays(p.M, p.H, p.f, w, p.mu, p.mu_r)
    verdict = rfverify.solve_to_digits(bad, 10).certificate.verdict
    assert "no velocity satisfies" in verdict and "interior thinner" not in verdict


def test_a_face_on_which_every_contact_sticks_is_not_posed_as_an_empty_problem():
    """The same corner pushed sideways: every contact of the stress is stuck on its face, and the
    face's problem with no contact was refused as 'mu: is empty' naming the user's file (exit 2)."""
    out = rfverify.solve_to_digits(_sphere_in_a_corner(2.0 + 2.0 ** -30), 10)
    assert out.certificate.extra["face"]["reduction"].startswith("not possible")


def test_a_contact_touching_no_body_with_w_outside_k_star_is_called_infeasible():
    """REFERENCE: 'Data whose forces y ∈ K balance with wᵀy < 0 have no feasible velocity: the
    verdict says so.' With H = 0 at contact 0 and w_N = −1 the search for y started from an empty
    neighbourhood (the seed touches no dof) and the verdict said 'may have an interior'."""
    p = rfverify.load("bundled:chute")
    H = p.H.tolil()
    H[:, 0:5] = 0
    w = p.w.copy()
    w[0] = -1.0
    bad = rfverify.Problem.from_arrays(p.M, H.tocsc(), p.f, w, p.mu, p.mu_r)
    verdict = rfverify.solve_to_digits(bad, 6).certificate.verdict
    assert "contact 0 carries forces y ∈ K with Hy = 0 and wᵀy < 0" in verdict and "no velocity satisfies" in verdict


def test_a_diagnosis_cut_short_labels_the_double_run_with_its_own_status(capsys):
    """The double run ended NumericalError (a λ2 breakdown at tol 1e-25); the diagnosis's time
    limit struck later, in the exact steps, and the run was labelled 'MaxTime after 19 iterations'."""
    code = main(["diagnose", "bundled:chute", "--tol", "1e-25", "--time-limit", "0.5", "--no-remedy"])
    out = capsys.readouterr().out.splitlines()
    run = next(line for line in out if line.startswith("double run ("))
    assert code == 1 and "NumericalError after" in run and "MaxTime" not in run


def test_no_presolve_names_the_field_that_holds_the_zeros(tmp_path, capsys):
    """Audit (2026-12-08): every problem with μr = 0 somewhere (every 3-D FCLIB file) was told
    'mu: has zero coefficients' under --no-presolve, though its μ were all positive."""
    p = rfverify.load("bundled:chute")
    q = rfverify.Problem.from_arrays(p.M, p.H, p.f, p.w, np.maximum(p.mu, 0.5), np.zeros_like(p.mu_r))
    path = tmp_path / "no_rolling.hdf5"
    rfverify.save(q, path)
    assert main(["solve", str(path), "--no-presolve"]) == 2
    err = capsys.readouterr().err
    assert "mu_r: has zero coefficients" in err and "error: mu:" not in err


def test_with_relative_digits_a_tie_is_broken_by_the_other_quantities(tmp_path):
    """Audit (2026-12-08): with relative=True on an all-open pile (Hr* = 0: every proof has 'Hr no
    relative digits') the tie went to the last point proven, the double answer, whose bound on v
    is 7.7e-4 (4.2 digits) where an iterate's proves v to 10.9."""
    assert main(["generate", "AllOpen", "--size", "20", "--seed", "7100", "--out", str(tmp_path), "--quiet"]) == 0
    (path,) = tmp_path.glob("*.hdf5")
    res = rfverify.solve_to_digits(rfverify.load(str(path)), 10, relative=True)
    assert not res.certificate.certified  # Hr* = 0 has no relative digits, as it must
    assert res.digits["v"] >= 10 and res.digits["u"] >= 10, res.digits
