"""``jaxsplit simulate --system spin-lattice`` and ``jaxsplit spins-audit``: a small run with
its files and JSON summary, and the one-line errors (exit status 2)."""

import json

import numpy as np
import pytest

from jaxsplit.cli import main


def test_spin_lattice_run_writes_trajectory_figure_and_summary(capsys, tmp_path):
    out = tmp_path / "chain.npz"
    argv = ["simulate", "--system", "spin-lattice", "--lattice", "chain", "--size", "16", "--exchange", "1",
            "--field", "0,0,0.1", "--dt", "0.05", "--steps", "400", "--save-every", "4", "--out", str(out), "--json"]
    assert main(argv) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["n_sites"] == 16 and summary["method"] == "bonds" and summary["scheme"] == "strang"
    assert summary["spin_length_max_relative_error"] < 1e-13
    assert summary["magnetisation_conserved"] == [0.0, 0.0, 1.0]
    with np.load(out) as data:
        assert data["spins"].shape == (101, 16, 3) and data["t"][-1] == pytest.approx(20.0)
        assert json.loads(str(data["metadata"]))["lattice"] == "chain"
        assert abs(data["magnetisation"][:, 2] - data["magnetisation"][0, 2]).max() < 1e-12
    png = (tmp_path / "chain.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("argv, message", [
    (["--lattice", "kagome"], "invalid choice: 'kagome'"),
    (["--size", "0x4"], "size must be >= 1"),
    (["--size", "4x4x4"], "a square lattice has 2 axes"),
    (["--lattice", "chain", "--size", "2"], "needs at least 3 cells per axis"),
    (["--exchange", "nan"], "exchange must be finite"),
    (["--spin-length", "-1"], "-1"),
    (["--axis", "0,0,0"], "--axis must be a nonzero vector"),
    (["--initial", "neel", "--lattice", "triangular", "--size", "4"], "needs a bipartite lattice"),
    (["--inertia", "1,2,3"], "--inertia do(es) not apply to --system spin-lattice"),
    (["--method", "heun", "--scheme", "strang"], "--method heun is an integrator of its own"),
    (["--method", "sweep", "--size", "32"], "at most 256 sites"),
])
def test_bad_spin_input_is_one_line_exit_2(capsys, argv, message):
    assert main(["simulate", "--system", "spin-lattice", "--no-save", *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


def test_spin_options_are_refused_for_other_systems(capsys):
    assert main(["simulate", "--system", "heavy-top", "--field", "0,0,1", "--no-save"]) == 2
    assert "--field appl(ies) only to --system spin-lattice" in capsys.readouterr().err


def test_spins_audit_refuses_unknown_names(capsys, tmp_path):
    assert main(["spins-audit", "--out", str(tmp_path), "--methods", "bonds,verlet"]) == 2
    assert "unknown method 'verlet'" in capsys.readouterr().err
