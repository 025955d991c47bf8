"""The command line meets the systems and the everyday path (issues 9, 11, 13), in-process
through ``jaxsplit.cli.main`` with tiny runs: every system simulated with every invariant
measured, states at requested times, one data format (simulate -> fit, npz and csv), the
heavy top's hidden centre of mass, float32 with and without the projection, and the
figures' honesty (no chords across the sphere, maxima from every state)."""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxsplit
from jaxsplit.cli import main
from jaxsplit.cli._data import read
from jaxsplit.cli._diagnostics import bucket

# A splitting of exact flows keeps its Casimirs to round-off over tens of steps.
CASIMIR_TOL = 1e-12
# Chunked and one-piece runs differ by where flows merge: round-off.
CHUNK_TOL = 1e-13
# The exact solution and the elliptic functions agree to ~1e-15 relative; the summary recomputed from the file.
EXACT_RTOL = 1e-9
# Inertia ratios recovered from clean data (the model is Kahan-Li 6 with 0.1 steps).
RATIO_RTOL = 1e-3
# The heavy top's hidden centre of mass from noisy (sigma 1e-3) data (issue 9's acceptance).
CENTER_RTOL = 0.01


def _json(capsys):
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 1, lines
    return json.loads(lines[0])


SYSTEMS = {
    "rigid-body": jaxsplit.RigidBody(jnp.array([2.0, 2.0, 1.0])),
    "attitude": jaxsplit.attitude(jnp.array([2.0, 2.0, 1.0])),
    "heavy-top": jaxsplit.heavy_top(jnp.array([2.0, 2.0, 1.0]), jnp.array([0.0, 0.0, 0.5]), 1.0),
    "gravity-gradient": jaxsplit.gravity_gradient(jnp.array([2.0, 2.0, 1.0]), 1.0),
}
PARTS = {"rigid-body": {"m": (3,)}, "attitude": {"m": (3,), "Q": (3, 3)},
         "heavy-top": {"m": (3,), "gamma": (3,)}, "gravity-gradient": {"m": (3,), "gamma": (3,)}}


# one worker with test_cli_check_sweep's attitude check: the attitude's exact solution (64 padded rows) compiles once
@pytest.mark.parametrize("name", [pytest.param(name, marks=pytest.mark.xdist_group("attitude-exact-solution"))
                                  if name == "attitude" else name for name in SYSTEMS])
def test_simulate_measures_every_invariant_of_each_system(name, tmp_path, capsys):
    import matplotlib.image

    out = tmp_path / "run.npz"
    drawn = name in ("attitude", "heavy-top")  # the new spheres (the free body's figure: test_cli.py)
    assert main(["simulate", "--system", name, "--scheme", "strang", "--steps", "40", "--dt", "0.05",
                 "--out", str(out), "--json", "--quiet"] + ([] if drawn else ["--no-figure"])) == 0
    s = _json(capsys)
    system = SYSTEMS[name]
    assert set(s["invariant_errors"]) == set(system.invariants())
    for label in system.casimirs():
        assert s["invariant_errors"][label] < CASIMIR_TOL
    assert 0 < s["energy_error_max"] < 1e-2  # Strang is not exact on the axes split
    arrays, meta = read(str(out))
    assert meta["system"] == name and arrays["t"].shape == (41,)
    for part, shape in PARTS[name].items():
        assert arrays[part].shape == (41, *shape)
    parts = tuple(jnp.asarray(arrays[p]) for p in PARTS[name])
    state = parts if len(parts) > 1 else parts[0]
    energy = np.asarray(jax.vmap(system.hamiltonian)(state))
    np.testing.assert_allclose(arrays["energy"], energy, rtol=1e-14)
    assert s["energy_error_max"] == pytest.approx(np.max(np.abs(energy / energy[0] - 1)), rel=1e-9)
    if name in ("rigid-body", "attitude"):  # the free body: distance to the elliptic solution, recomputed
        x0 = jax.tree_util.tree_map(lambda a: a[0], state)
        # the times padded as the CLI pads its rows: the run's compiled exact solution serves (4 s for the attitude)
        times = np.concatenate([arrays["t"], np.full(bucket(41) - 41, arrays["t"][-1])])
        exact = [a[:41] for a in jax.tree_util.tree_leaves(jaxsplit.exact_solution(system, x0, jnp.asarray(times)))]
        distance = np.max([np.max(np.abs(np.asarray(a - b)).reshape(41, -1), axis=1) for a, b in zip(parts, exact)],
                          axis=0)
        assert s["exact_error_max"] == pytest.approx(np.max(distance), rel=EXACT_RTOL)
    else:
        assert s["exact_error_max"] is None and "m_exact" not in arrays
    if drawn:
        image = matplotlib.image.imread(tmp_path / "run.png")
        assert image.shape[1] >= 1200 and np.mean(np.any(image[..., :3] < 0.9, axis=-1)) > 0.05


def test_invariant_errors_are_measured_not_assumed(monkeypatch, capsys):
    """Explicit Euler keeps neither Casimir of the heavy top: the summary must say so."""

    def euler(system, scheme, split=None, **options):
        return lambda x, h: jax_tree_add(x, system.vector_field(x), h)

    monkeypatch.setattr("jaxsplit.systems._splitting.splitting", euler)
    assert main(["simulate", "--system", "heavy-top", "--steps", "40", "--dt", "0.05", "--no-save", "--json"]) == 0
    s = _json(capsys)
    assert s["invariant_errors"]["|Gamma|^2"] > 1e-3 and s["invariant_errors"]["<m,Gamma>"] > 1e-3


def jax_tree_add(x, v, h):
    return jax.tree_util.tree_map(lambda a, b: a + h * b, x, v)


# ---------------------------------------------------------------- --save-at: partial steps
def test_save_at_gives_partial_steps_in_the_chunk_that_holds_them(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr("jaxsplit.cli._chunked.TARGET_FLOWS_PER_CHUNK", 90)  # chunks of 30 Strang steps (3 flows)
    times = [0.0, 0.013, 0.3, 0.305, 1.0, 1.777]
    body, m0 = jaxsplit.RigidBody(jnp.array([3.0, 2.0, 1.5])), jnp.array([0.2, 0.9, 0.3])
    common = ["simulate", "--inertia", "3,2,1.5", "--m0", "0.2,0.9,0.3", "--scheme", "strang", "--dt", "0.01",
              "--json", "--no-figure", "--quiet"]
    assert main(common + ["--save-at", ",".join(map(str, times)), "--out", str(tmp_path / "at.csv")]) == 0
    s = _json(capsys)
    assert s["steps"] == 178 and s["states_at_times"] == len(times)  # ends at the last time, rounded up
    arrays, meta = read(str(tmp_path / "at.csv"))
    assert "step" not in arrays and list(arrays["t"]) == times and "save-at" in meta["rows"]
    direct = np.asarray(jaxsplit.integrate(jaxsplit.splitting(body, "strang"), m0, 0.01, ts=jnp.array(times)).x)
    np.testing.assert_allclose(arrays["m"], direct, rtol=0, atol=CHUNK_TOL)
    exact = np.asarray(jaxsplit.exact_solution(body, m0, jnp.array(times)))
    error = np.max(np.abs(arrays["m"] - exact), axis=1)
    assert np.all(error < 1e-4)  # Strang's accuracy at h = 0.01
    casimir = 0.5 * np.sum(arrays["m"] ** 2, axis=1)
    assert np.max(np.abs(casimir / casimir[0] - 1)) < CASIMIR_TOL  # partial steps stay on the sphere
    # A partial step, not the nearest grid state: t = 0.013 lies between the states after 1 and 2 steps.
    grid = np.asarray(jaxsplit.integrate(jaxsplit.splitting(body, "strang"), m0, 0.01, 2, save_every=1).x)
    assert np.min(np.max(np.abs(grid[1:] - arrays["m"][1]), axis=1)) > 100 * error[1]
    # The same times from a file (comments and blank lines allowed) give the same states.
    (tmp_path / "times.txt").write_text("# times\n" + "\n".join(map(str, times[::-1])) + "\n\n")
    assert main(common + ["--save-at", f"@{tmp_path / 'times.txt'}", "--out", str(tmp_path / "file.npz")]) == 0
    capsys.readouterr()
    np.testing.assert_array_equal(read(str(tmp_path / "file.npz"))[0]["m"], arrays["m"])


# ---------------------------------------------------------------- one data format: simulate -> fit
@pytest.fixture(scope="module")
def observations(tmp_path_factory):
    """The same clean free-body run written as .npz and as .csv."""
    folder = tmp_path_factory.mktemp("obs")
    common = ["simulate", "--inertia", "3,2,1.5", "--m0", "0.2,0.9,0.3", "--scheme", "kahan-li-6", "--dt", "0.01",
              "--t-end", "2", "--save-every", "10", "--no-figure", "--quiet"]
    for name in ("obs.npz", "obs.csv"):
        assert main(common + ["--out", str(folder / name)]) == 0
    return folder


def _expected_ratios(energy):
    """The ratios of the body whose 1/I differ from the truth by the gauge c fixed by ``energy``."""
    w, m0 = 1 / np.array([3.0, 2.0, 1.5]), np.array([0.2, 0.9, 0.3])
    c = (2 * energy - np.sum(w * m0**2)) / np.sum(m0**2)
    return np.array([(w[0] + c) / (w[1] + c), (w[0] + c) / (w[2] + c)])


# Both files hold the same data: one worker runs both, so the module fixture and the fit's
# compilation are paid once (the second fit reuses the compiled optimiser).
@pytest.mark.xdist_group("cli-fit-observations")
@pytest.mark.parametrize("name", ["obs.npz", "obs.csv"])
def test_simulate_output_fits_unchanged_with_and_without_energy(name, observations, capsys):
    energy = float(jaxsplit.RigidBody(jnp.array([3.0, 2.0, 1.5])).hamiltonian(jnp.array([0.2, 0.9, 0.3])))
    fit = ["fit", "--data", str(observations / name), "--max-step", "0.1", "--json"]
    assert main(fit) == 0  # the file's per-state energy fixes the gauge
    r = _json(capsys)
    np.testing.assert_allclose(r["inertia_ratios"], [2 / 3, 0.5], rtol=RATIO_RTOL)
    assert "energy E = " in r["gauge"] and r["ratio_std"] is not None and not r["gauge_assumed"]
    assert "computed by jaxsplit simulate" in r["gauge_source"] and "exact only for synthetic data" in r["gauge_source"]
    assert main(fit + ["--energy", str(1.2 * energy)]) == 0  # the option overrides the file
    r = _json(capsys)
    assert r["gauge_source"] == "--energy"
    np.testing.assert_allclose(r["inertia_ratios"], _expected_ratios(1.2 * energy), rtol=RATIO_RTOL)
    assert abs(r["inertia_ratios"][0] - 2 / 3) > 10 * RATIO_RTOL  # another gauge: other ratios


def test_without_a_gauge_the_ratios_carry_no_uncertainty(monkeypatch, capsys, tmp_path):
    """The ratios under an assumed I1 are not measured: no +-, null in JSON; the measured
    differences keep theirs (the fit itself replaced by a fixed result: no compilation)."""
    import jaxsplit.cli.fit as fit_cli
    from jaxsplit.explore._fit_inertia import FitResult

    def result(gauge):
        return FitResult(inertia=np.array([1.0, 2.0, 4.0]), inertia_ratios=np.array([2.0, 4.0]),
                         ratio_std=np.array([3.7e-12, 4e-12]), inverse_differences=np.array([0.75, 0.25]),
                         inverse_differences_std=np.array([1e-6, 2e-6]), m0=np.ones(3), loss=1e-9, noise_sigma=1e-3,
                         iterations=3, gauge=gauge, ratio_range=np.array([[0.0, 1.0], [0.0, 1.0]]),
                         null_direction=np.ones(3), null_alignment=1.0, hessian_eigenvalues=np.ones(3), seconds=0.1)

    np.savez(tmp_path / "obs.npz", t=np.linspace(0, 1, 5), m=np.ones((5, 3)))
    gauges = {"ASSUMED I1 = 1 (m(t) does not determine it; pass energy= or inertia1=)": False,
              "known I1 = 1": True}
    for gauge, measured in gauges.items():
        monkeypatch.setattr(fit_cli, "fit_inertia", lambda *a, gauge=gauge, **k: result(gauge))
        assert main(["fit", "--data", str(tmp_path / "obs.npz")]) == 0
        text = capsys.readouterr().out
        assert ("I2/I1 = 2.000000 +- 3.70e-12" in text) is measured
        assert "1/I1 - 1/I3 = 0.750000 +- 1.00e-06" in text
        assert ("not measured (no uncertainty)" in text) is not measured
        assert main(["fit", "--data", str(tmp_path / "obs.npz"), "--json"]) == 0
        r = _json(capsys)
        assert (r["ratio_std"] is not None) is measured and r["inverse_inertia_differences_std"] == [1e-6, 2e-6]
        assert "energy=" not in r["gauge"]


def test_fit_recovers_a_hidden_center_of_mass_from_noisy_simulated_data(tmp_path, capsys):
    center = np.array([0.1, -0.2, 0.5])
    out = tmp_path / "top.csv"
    assert main(["simulate", "--system", "heavy-top", "--inertia", "2,1.5,1", "--center-of-mass",
                 ",".join(map(str, center)), "--weight", "2", "--gamma0", "0,0.6,0.8", "--m0", "0.3,0.4,2",
                 "--scheme", "kahan-li-6", "--dt", "0.01", "--t-end", "2", "--save-every", "10", "--noise", "1e-3",
                 "--seed", "3", "--out", str(out), "--no-figure", "--quiet"]) == 0
    capsys.readouterr()
    arrays, meta = read(str(out))
    assert meta["noise"] == 1e-3 and meta["seed"] == 3 and arrays["gamma"].shape == (21, 3)
    assert main(["fit", "--data", str(out), "--scheme", "strang", "--json"]) == 0  # weight from the file
    r = _json(capsys)
    assert r["system"] == "heavy-top" and r["weight"] == 2.0
    np.testing.assert_allclose(r["center_of_mass"], center, rtol=CENTER_RTOL, atol=0)
    np.testing.assert_allclose(r["inertia"], [2.0, 1.5, 1.0], rtol=CENTER_RTOL)
    assert all(s is not None and s < 0.01 for s in r["center_of_mass_std"])
    assert r["noise_sigma"] == pytest.approx(1e-3, rel=0.3)  # the residuals see the noise that was added


# ---------------------------------------------------------------- float32 and the projection
def test_float32_drift_is_reported_and_the_projection_is_opt_in(capsys):
    run = ["simulate", "--dtype", "float32", "--scheme", "kahan-li-6", "--inertia", "3,2,1.5", "--m0", "0.2,0.9,0.3",
           "--steps", "2e4", "--no-save", "--json", "--quiet"]
    assert main(run) == 0
    captured = capsys.readouterr()
    plain = json.loads(captured.out)
    assert "float32 run" in captured.err and "--renormalize" in captured.err
    assert plain["dtype"] == "float32" and plain["projection"] is None
    assert main(run + ["--renormalize"]) == 0
    projected = json.loads(capsys.readouterr().out)
    assert projected["projection"] == "|m| restored after every step"
    drift, kept = plain["casimir_error_max"], projected["casimir_error_max"]
    eps32 = float(np.finfo(np.float32).eps)
    assert drift > 1e-5  # float32 round-off accumulates over 2e4 steps of 9 stages (measured 1.5e-5)
    assert kept <= 4 * eps32 and drift > 10 * kept  # the projection holds |m| at float32 round-off


# ---------------------------------------------------------------- figures: honest orbits and maxima
def test_figure_orbit_never_joins_far_apart_states():
    from jaxsplit.cli._figures import CHORD, _joined, envelope, sparse

    angle = np.linspace(0, 2 * np.pi, 1000)
    circle = np.stack([np.cos(angle), np.sin(angle), 0 * angle], axis=1)
    assert not sparse(circle, 1.0) and not np.isnan(_joined(circle, 1.0)).any()
    thinned = circle[::97]  # consecutive saved states ~0.6 rad apart: chords would cut the sphere
    assert sparse(thinned, 1.0)
    joined = _joined(thinned, 1.0)
    finite = joined[np.all(np.isfinite(joined), axis=1)]
    assert np.isnan(joined).any() and len(finite) == len(thinned)
    segments = np.split(joined, np.flatnonzero(np.isnan(joined[:, 0])))
    assert all(np.all(np.linalg.norm(np.diff(seg[np.isfinite(seg[:, 0])], axis=0), axis=1) <= CHORD) for seg in segments)
    # Thinning keeps every bucket's maximum: the drawn maximum is the true one.
    t = np.arange(100_003.0)
    spikes = np.zeros_like(t)
    spikes[[17, 50_001, 99_999]] = [1.0, 3.0, 2.0]
    tt, ee = envelope(t, spikes, 1000)
    assert len(tt) <= 1100 and ee.max() == 3.0 and set(tt[ee > 0]) == {17.0, 50_001.0, 99_999.0}
    assert spikes[::101].max() < 3.0  # a stride would have missed it


# ---------------------------------------------------------------- --tol (jaxsplit.auto_splitting, branch speed)
def test_tol_runs_what_auto_splitting_chose(monkeypatch, capsys):
    """The CLI side of --tol against auto_splitting's signature (system, x0, *, tol, t_end) and
    result fields; the library function is stood in for here, its choices are tested where it lives."""
    from collections import namedtuple

    choice = namedtuple("AutoSplitting", "step h n_steps scheme split options predicted_error cost candidates")
    calls = []

    def auto_splitting(system, x0, *, tol, t_end):
        calls.append((type(system).__name__, np.asarray(x0).tolist(), tol, t_end))
        return choice(None, 0.05, 40, "strang", "casimir", {"shift": 1}, 3e-6, 120.0, ())

    monkeypatch.setattr(jaxsplit, "auto_splitting", auto_splitting, raising=False)
    assert main(["simulate", "--tol", "1e-5", "--t-end", "2", "--inertia", "3,2,1.5", "--no-save", "--json"]) == 0
    s = _json(capsys)
    assert calls == [("RigidBody", [0.6, 0.0, 0.8], 1e-5, 2.0)]
    assert (s["scheme"], s["split"], s["shift_axis"], s["dt"], s["steps"]) == ("strang", "casimir", 2, 0.05, 40)
    assert s["tol"] == 1e-5 and s["predicted_error"] == 3e-6
    assert s["exact_error_max"] < 1e-4  # what the run measured, next to the prediction


def test_tol_reaches_the_tolerance_it_was_given(capsys):
    """The real choice (no stand-in): the measured error against the exact solution meets --tol."""
    tol = 1e-6
    assert main(["simulate", "--tol", str(tol), "--t-end", "20", "--inertia", "3,2,1.5", "--no-save", "--json",
                 "--quiet"]) == 0
    s = _json(capsys)
    assert s["tol"] == tol and s["exact_error_max"] <= tol, s
