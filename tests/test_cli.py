"""The command line end to end, in-process through ``jaxsplit.cli.main``: the default
``simulate`` (acceptance 3), outputs and metadata, csv, --force, non-finite runs,
chunked runs equal to one run, ``check``, ``schemes`` and every ``--help``."""

import json
import os

import jax.numpy as jnp
import numpy as np
import pytest

import jaxsplit
from jaxsplit.cli import COMMANDS, main
from jaxsplit.cli._chunked import first_nonfinite, run_chunked
from jaxsplit.cli._metadata import read_metadata

# Chunking changes where flows merge across step boundaries: equal up to round-off.
CHUNK_RTOL = 1e-13
# A splitting of exact rotations keeps the Casimir to round-off over 10^4 steps.
CASIMIR_TOL = 1e-12
ROUNDOFF_ULPS = 8  # two computations of one round-off-level maximum agree to a few ulps


def _json_out(capsys):
    out = capsys.readouterr().out.strip().splitlines()
    assert len(out) == 1, out
    return json.loads(out[0])


def test_simulate_with_no_arguments_is_the_paper_case(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["simulate"]) == 0
    out = capsys.readouterr().out
    assert "lie-trotter" in out and "vs exact solution" in out and "10,000 steps" in out
    files = sorted(p.name for p in (tmp_path / "jaxsplit-runs").iterdir())
    assert len(files) == 2 and files[0].endswith(".npz") and files[1].endswith(".png")
    # A second run with no arguments does not fail on the existing files: new names.
    assert main(["simulate", "--steps", "10"]) == 0
    assert len(list((tmp_path / "jaxsplit-runs").iterdir())) == 4

    with np.load(tmp_path / "jaxsplit-runs" / files[0]) as z:
        meta = read_metadata(z)
        t, m = z["t"], z["m"]
    assert meta["inertia"] == list(jaxsplit.PAPER_BODY) and meta["m0"] == list(jaxsplit.PAPER_M0)
    assert meta["scheme"] == "lie-trotter" and meta["dt"] == 0.01 and meta["steps_requested"] == 10_000
    assert meta["dtype"] == "float64" and meta["jaxsplit_version"] == jaxsplit.__version__
    assert meta["xla_flags"] == os.environ.get("XLA_FLAGS", "")  # what this process compiled with
    assert m.dtype == np.float64 and m.shape == (10_001, 3) and t[-1] == pytest.approx(100.0)
    # The trajectory is Lie-Trotter's: compare with the library called directly.
    body = jaxsplit.RigidBody(jnp.asarray(jaxsplit.PAPER_BODY))
    direct = jaxsplit.integrate(jaxsplit.splitting(body, "lie-trotter"), jnp.asarray(jaxsplit.PAPER_M0),
                                0.01, 10_000).final
    np.testing.assert_allclose(m[-1], np.asarray(direct), rtol=CHUNK_RTOL, atol=CHUNK_RTOL)


def test_json_summary_matches_the_saved_trajectory(capsys, tmp_path):
    out = tmp_path / "run.npz"
    argv = ["simulate", "--scheme", "strang", "--dt", "0.05", "--steps", "400", "--save-every", "3",
            "--out", str(out), "--json", "--no-figure"]
    assert main(argv) == 0
    s = _json_out(capsys)
    for key in ("energy_error_max", "casimir_error_max", "steps", "scheme", "seconds", "exact_error_max"):
        assert key in s
    assert s["steps"] == 400 and s["scheme"] == "strang" and s["outputs"] == {"trajectory": str(out)}
    with np.load(out) as z:
        m, step, t = z["m"], z["step"], z["t"]
        assert read_metadata(z)["save_every"] == 3
    # x0, every 3rd state and the last one, as integrate(save_every=3) saves them.
    np.testing.assert_array_equal(step, np.r_[np.arange(0, 400, 3), 400])
    np.testing.assert_allclose(t, step * 0.05, rtol=1e-15)
    inertia = np.asarray(jaxsplit.PAPER_BODY)
    energy = 0.5 * np.sum(m * m / inertia, axis=1)
    casimir = 0.5 * np.sum(m * m, axis=1)
    assert s["energy_error_max"] == pytest.approx(np.max(np.abs(energy / energy[0] - 1)), rel=1e-12)
    # at round-off level the summary (on device) and the file's column (recomputed here) differ by ulps
    assert s["casimir_error_max"] == pytest.approx(np.max(np.abs(casimir / casimir[0] - 1)), rel=1e-12,
                                                   abs=ROUNDOFF_ULPS * np.finfo(np.float64).eps)
    assert s["casimir_error_max"] < CASIMIR_TOL
    exact = np.asarray(jaxsplit.symmetric_solution(jaxsplit.RigidBody(inertia), jnp.asarray(jaxsplit.PAPER_M0),
                                                   jnp.asarray(t)))
    assert s["exact_error_max"] == pytest.approx(np.max(np.abs(m - exact)), rel=1e-12)
    assert s["exact_error_max"] > 0  # Strang is not exact on the axes split


def test_csv_holds_the_same_trajectory_as_npz(capsys, tmp_path):
    from jaxsplit.cli._data import read

    common = ["simulate", "--inertia", "3,2,1.5", "--m0", "0.2,-0.9,0.3", "--scheme", "kahan-li-6",
              "--split", "casimir", "--t-end", "2", "--dt", "0.1", "--no-figure", "--quiet"]
    assert main(common + ["--out", str(tmp_path / "a.npz")]) == 0
    assert main(common + ["--out", str(tmp_path / "b"), "--format", "csv"]) == 0
    capsys.readouterr()
    npz, meta = read(str(tmp_path / "a.npz"))
    csv, csv_meta = read(str(tmp_path / "b.csv"))
    text = (tmp_path / "b.csv").read_text().splitlines()
    stamp = "created_utc"  # two runs: their clocks may straddle a second
    assert text[0].startswith("# metadata: ") and {**csv_meta, stamp: None} == {**meta, stamp: None}
    assert text[1] == "# t,step,m1,m2,m3,energy,casimir,m_exact1,m_exact2,m_exact3"
    assert sorted(csv) == sorted(npz)
    for key, value in npz.items():  # %.17g round-trips float64 exactly
        np.testing.assert_array_equal(csv[key], value)
    assert meta["inertia"] == [3.0, 2.0, 1.5] and meta["steps_requested"] == 20 and meta["shift_axis"] == 2
    # An asymmetric body has its exact (elliptic) solution too.
    exact = jaxsplit.exact_solution(jaxsplit.RigidBody(jnp.array([3.0, 2.0, 1.5])), jnp.array([0.2, -0.9, 0.3]),
                                    jnp.asarray(npz["t"]))
    np.testing.assert_allclose(npz["m_exact"], np.asarray(exact), rtol=0, atol=1e-14)


def test_force_overwrites_atomically(capsys, tmp_path):
    out = tmp_path / "run.npz"
    out.write_bytes(b"old")
    assert main(["simulate", "--steps", "5", "--out", str(out), "--force", "--no-figure"]) == 0
    with np.load(out) as z:
        assert z["m"].shape == (6, 3)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.npz"]  # no temporary files left


def test_no_save_writes_nothing(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["simulate", "--steps", "10", "--no-save"]) == 0
    assert "no files written" in capsys.readouterr().out
    assert list(tmp_path.iterdir()) == []


def test_negative_values_and_backward_integration(capsys, tmp_path):
    out = tmp_path / "back.npz"
    assert main(["simulate", "--m0", "-0.6,0,0.8", "--dt", "-0.01", "--steps", "100", "--out", str(out),
                 "--no-figure", "--json"]) == 0
    s = _json_out(capsys)
    assert s["m0"] == [-0.6, 0.0, 0.8] and s["t_end"] == pytest.approx(-1.0)
    with np.load(out) as z:
        assert z["t"][-1] == pytest.approx(-1.0)


def _doubling(body, scheme, split="axes", **kwargs):
    return lambda x, h: 2.0 * x


def _first_overflow_step():
    x, k = 1.0, 0
    while np.isfinite(x):
        x, k = x * 2.0, k + 1
    return k


def test_nonfinite_state_stops_reports_and_keeps_the_work(capsys, tmp_path, monkeypatch):
    monkeypatch.setattr("jaxsplit.systems._splitting.splitting", _doubling)
    out = tmp_path / "blowup.npz"
    rc = main(["simulate", "--m0", "1,0,0", "--steps", "5000", "--save-every", "100", "--out", str(out)])
    captured = capsys.readouterr()
    bad = _first_overflow_step()  # 1024 for float64
    assert rc == 3
    assert f"non-finite at step {bad:,}" in captured.err and f"t = {bad * 0.01:g}" in captured.err
    assert "Traceback" not in captured.err
    with np.load(out) as z:
        step, m, meta = z["step"], z["m"], read_metadata(z)
    assert np.all(np.isfinite(m))
    assert step[-1] == bad - 1 and list(step[:-1]) == list(range(0, bad - 1, 100))
    np.testing.assert_array_equal(m[-1], [2.0 ** (bad - 1), 0, 0])
    assert meta["status"] == "nonfinite" and meta["nonfinite_step"] == bad
    assert (tmp_path / "blowup.png").exists()


def test_first_nonfinite_narrows_down_to_the_step():
    bad = _first_overflow_step()
    for n in (bad, bad + 1, 3 * bad, 50_000):
        k, last = first_nonfinite(lambda x, h: 2.0 * x, jnp.ones(2), 0.1, n)
        assert k == bad and np.all(np.asarray(last) == 2.0 ** (bad - 1))


@pytest.mark.parametrize("save_every,chunk", [(1, 64), (7, 70), (1000, 1000), (250, 64), (3000, 64)])
def test_chunked_run_equals_one_run(save_every, chunk):
    body = jaxsplit.RigidBody(jnp.asarray([3.0, 2.0, 1.5]))
    step = jaxsplit.splitting(body, "strang")
    m0 = jnp.asarray([0.2, 0.9, 0.3])
    res = run_chunked(step, m0, 0.05, 1000, save_every, chunk=chunk)
    one = jaxsplit.integrate(step, m0, 0.05, 1000, save_every=save_every)
    assert res.completed == 1000 and res.nonfinite_step is None and not res.interrupted
    np.testing.assert_allclose(res.steps * 0.05, np.asarray(one.t), rtol=1e-15)
    np.testing.assert_allclose(res.x, np.asarray(one.x), rtol=CHUNK_RTOL, atol=CHUNK_RTOL)


def test_check_measures_poisson_defect_and_order(capsys):
    assert main(["check", "--scheme", "strang", "--json", "--states", "8"]) == 0
    r = _json_out(capsys)
    assert r["poisson_ok"] and r["poisson_defect_max"] < 1e-12
    assert abs(r["measured_order"] - 2) < 0.3 and r["order_ok"]
    assert r["reference"].startswith("exact")


def test_check_reports_a_non_poisson_map_and_a_wrong_order(capsys, monkeypatch):
    # Explicit Euler is neither Poisson nor of order 2: check must say so (exit 1).
    def euler(body, scheme, split="axes", **kwargs):
        return lambda m, h: m + h * body.vector_field(m)

    monkeypatch.setattr("jaxsplit.systems._splitting.splitting", euler)
    assert main(["check", "--scheme", "strang", "--json", "--states", "4", "--t-end", "1"]) == 1
    r = _json_out(capsys)
    assert not r["poisson_ok"] and r["poisson_defect_max"] > 1e-6
    assert abs(r["measured_order"] - 1) < 0.3 and not r["order_ok"]


def test_check_exact_splitting_is_not_a_failure(capsys):
    # Symmetric body, Casimir split with the automatic shift: one piece, so the scheme is exact.
    assert main(["check", "--scheme", "strang", "--split", "casimir", "--json", "--states", "4"]) == 0
    r = _json_out(capsys)
    assert r["measured_order"] is None and "exact" in r["order_note"] and r["order_ok"]


def test_schemes_table_lists_every_registered_scheme(capsys):
    assert main(["schemes"]) == 0
    table, legend = capsys.readouterr().out.split("\n\n")
    lines = table.splitlines()
    assert lines[0].split()[:6] == ["name", "order", "stages", "form", "flows/2", "flows/3"]
    names = [line.split()[0] for line in lines[1:]]
    assert names == list(jaxsplit.schemes)
    assert all(form in legend for form in ("symmetric:", "lie-adjoint:", "partitioned:"))  # what stages count
    assert main(["schemes", "--json"]) == 0
    table = _json_out(capsys)["schemes"]
    body = jaxsplit.RigidBody(jnp.asarray([3.0, 2.0, 1.5]))
    for row in table:
        s = jaxsplit.schemes[row["name"]]
        assert (row["order"], row["stages"], row["form"]) == (s.order, s.stages, s.form)
        assert row["stages_unit"]
        # the flows column is the sub-flow count of the built step (one step, no FSAL across steps)
        two = jaxsplit.splitting(body, s.name, split="casimir")
        assert row["flows_per_step"]["2"] == two.flows_per_step + (1 if two.fsal else 0), s.name
        assert (row["flows_per_step"]["3"] is None) == (s.form == "partitioned")




@pytest.mark.parametrize("command", COMMANDS)
def test_every_command_help_shows_examples(command, capsys):
    with pytest.raises(SystemExit) as exit_:
        main([command, "--help"])
    assert exit_.value.code == 0
    assert "example" in capsys.readouterr().out.lower()


def test_top_level_help_lists_the_commands(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    out = capsys.readouterr().out
    for command in COMMANDS:
        assert command in out and command in COMMANDS
    assert main([]) == 0


def test_figure_is_a_png_of_legible_size(capsys, tmp_path):
    import matplotlib.image

    out = tmp_path / "r.npz"
    assert main(["simulate", "--steps", "200", "--out", str(out), "--quiet"]) == 0
    image = matplotlib.image.imread(tmp_path / "r.png")
    height, width = image.shape[:2]
    assert width >= 1200 and height >= 600
    # Not blank: a good share of pixels is not white.
    assert np.mean(np.any(image[..., :3] < 0.9, axis=-1)) > 0.05


def test_ctrl_c_keeps_the_finished_chunks(capsys, tmp_path, monkeypatch):
    """A real SIGINT during the third chunk: that chunk finishes, the run stops, all is written."""
    import os
    import signal

    import jaxsplit.core._integrate as integrate_module

    real, calls = integrate_module.integrate, []

    def interrupted_during_third_chunk(*args, **kwargs):
        calls.append(args[3])
        if len(calls) == 3:
            os.kill(os.getpid(), signal.SIGINT)  # the policy defers it: the chunk completes
        return real(*args, **kwargs)

    monkeypatch.setattr(integrate_module, "integrate", interrupted_during_third_chunk)
    monkeypatch.setattr("jaxsplit.cli._chunked.TARGET_FLOWS_PER_CHUNK", 3000)  # 1000 lie-trotter steps
    out = tmp_path / "part.npz"
    rc = main(["simulate", "--steps", "10000", "--save-every", "10", "--out", str(out), "--no-figure"])
    captured = capsys.readouterr()
    assert rc == 130 and "interrupted (SIGINT) after 3,000 of 10,000 steps" in captured.err
    with np.load(out) as z:
        assert z["step"][-1] == 3000 and len(z["step"]) == 301
        assert read_metadata(z)["status"] == "interrupted"


def test_default_outputs_in_an_unwritable_directory_still_run(capsys, monkeypatch):
    monkeypatch.chdir("/proc")  # not writable, even for root
    assert main(["simulate", "--steps", "10"]) == 0
    captured = capsys.readouterr()
    assert "no files written" in captured.err and "--out" in captured.err
    assert "max relative energy error" in captured.out


def test_figure_only(capsys, tmp_path):
    assert main(["simulate", "--steps", "10", "--figure", str(tmp_path / "f.png"), "--quiet"]) == 0
    assert [p.name for p in tmp_path.iterdir()] == ["f.png"]


@pytest.mark.parametrize("command", COMMANDS)
def test_help_examples_parse(command):
    """Every example line of --help is a valid invocation (options and values parse)."""
    import shlex

    from jaxsplit.cli import _load, build_parser

    epilog = _load(command).EXAMPLES
    text = epilog.replace("\\\n", " ")
    examples = [line.split("#")[0].strip() for line in text.splitlines() if line.strip().startswith("jaxsplit ")]
    examples = [e for e in examples if "..." not in e and "COMMAND" not in e]
    assert examples
    parser = build_parser()
    for example in examples:
        args = parser.parse_args(shlex.split(example)[1:])
        assert args.command == command


def test_memory_refusal_suggests_a_save_every_that_fits():
    import re

    from jaxsplit import InputError
    from jaxsplit.cli._bounds import saved_states
    BYTES_PER_SAVED = 2 * 10 * 8  # the free body: t, step, m, exact m and 2 invariants, twice

    steps, limit = 10**9, 2**20
    with pytest.raises(InputError) as err:
        saved_states(steps, 1, BYTES_PER_SAVED, limit)
    k = int(re.search(r"--save-every (\d+)", str(err.value)).group(1))
    saved_states(steps, k, BYTES_PER_SAVED, limit)  # fits: no error


@pytest.mark.parametrize("save_every,chunk", [(100, 300), (5000, 100)])
def test_chunked_run_stops_at_the_first_nonfinite_step(save_every, chunk):
    bad = _first_overflow_step()
    res = run_chunked(lambda x, h: 2.0 * x, jnp.ones(3), 0.1, 5000, save_every, chunk=chunk)
    assert res.nonfinite_step == bad and res.completed == bad - 1
    expected = [*range(0, bad, save_every), bad - 1] if (bad - 1) % save_every else list(range(0, bad, save_every))
    assert list(res.steps) == expected
    np.testing.assert_array_equal(res.x, 2.0 ** res.steps[:, None] * np.ones((1, 3)))


def _rk4_orbit(inertia, m0, t_end=12.0, n=3000):
    """A free body's m(t) by classical RK4 in NumPy (an independent path, no compilation)."""
    w = 1 / np.asarray(inertia, float)

    def f(m):
        return np.cross(m, w * m)

    h, m, out = t_end / n, np.asarray(m0, float), []
    for _ in range(n):
        k1 = f(m)
        k2 = f(m + h / 2 * k1)
        k3 = f(m + h / 2 * k2)
        m = m + h / 6 * (k1 + 2 * k2 + 2 * k3 + f(m + h * k3))
        out.append(m)
    return np.array(out)


VIEW_AREA_FRACTION = 0.9  # the drawn orbit encloses at least this part of its largest projected area


@pytest.mark.parametrize("inertia,m0", [((3, 2, 1.5), (0.2, 0.9, 0.3)), ((3, 2, 1.5), (0.9, 0.2, 0.3)),
                                        ((2, 2, 1), (0.6, 0.0, 0.8)), ((1, 2, 2.5), (0.1, 0.3, 0.95))])
def test_sphere_view_never_sees_the_orbit_edge_on(inertia, m0):
    """The sphere panel looks along the orbit's area vector: the orbit as drawn (the line's
    screen coordinates) encloses nearly its largest projected area, on the near side (once
    seen edge-on, I = (3, 2, 1.5), m0 = (0.2, 0.9, 0.3): a line across the level curves)."""
    from jaxsplit.cli._figures import Curve, Sphere, _pyplot, _sphere_panel, area_vector

    orbit = _rk4_orbit(inertia, m0)
    radius = float(np.linalg.norm(m0))
    plt = _pyplot()
    fig, ax = plt.subplots()
    _sphere_panel(ax, Sphere("m", [Curve(orbit, "m(t)", "C0")], radius,
                             levels=lambda p: np.sum(p**2 / np.asarray(inertia, float), axis=-1)))
    line = next(ln for ln in ax.lines if ln.get_label() == "m(t)")  # the near-side part, as drawn
    x, y = np.asarray(line.get_xdata(), float), np.asarray(line.get_ydata(), float)
    plt.close(fig)
    assert np.isfinite(x).all(), "part of the orbit is drawn on the far side"
    drawn = 0.5 * abs(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))
    assert drawn >= VIEW_AREA_FRACTION * np.linalg.norm(area_vector([orbit])), (drawn, area_vector([orbit]))
