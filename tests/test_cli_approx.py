"""``regrasp-pin approx CURVE.csv -m M``: on files, in text and JSON, and its errors."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import assert_close

from regrasp_pin import cli
from regrasp_pin.commands import approx
from regrasp_pin.polygon.approximate import METHODS, approximate_polygon
from regrasp_pin.polygon.deviation import DEVIATIONS


def curve(n: int = 60) -> np.ndarray:
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.c_[np.cos(t), np.sin(t) + 0.2 * np.sin(4 * t)]


@pytest.fixture()
def csv_2d(tmp_path):
    path = tmp_path / "curve.csv"
    np.savetxt(path, curve(), delimiter=",", header="x,y", comments="")
    return path


def test_json_output_matches_the_library(csv_2d, capsys):
    code = cli.main(
        [
            "approx",
            str(csv_2d),
            "-m",
            "7",
            "--closed",
            "--deviation",
            "ise",
            "--json",
        ]
    )
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    for key in ("indices", "energy", "n", "m", "method", "deviation", "closed", "time_ms"):
        assert key in out
    assert (out["n"], out["m"], out["method"], out["deviation"], out["closed"]) == (
        60,
        7,
        "hopfield",
        "ise",
        True,
    )
    ref = approximate_polygon(curve(), 7, closed=True, deviation="ise")
    assert out["indices"] == ref.indices.tolist()
    assert_close(out["energy"], ref.energy, atol=1e-12)
    assert out["time_ms"] > 0


def test_text_output_3d_without_header_exact(tmp_path, capsys):
    path = tmp_path / "helix.csv"
    t = np.linspace(0, 4 * np.pi, 50)
    np.savetxt(path, np.c_[np.cos(t), np.sin(t), 0.1 * t], delimiter=",")
    assert cli.main(["approx", str(path), "-m", "5", "--method", "exact", "--full-matrix"]) == 0
    out = capsys.readouterr().out
    assert "50 points (open, 3-D) -> 5 vertices, method exact, deviation ise" in out
    assert "the exact optimum" in out  # what the chosen method did, nothing of the network
    assert "network" not in out and "sweeps" not in out
    assert out.count("(") >= 5 + 1  # one line per vertex


def test_plot_is_written(csv_2d, tmp_path, capsys):
    png = tmp_path / "fig8.png"
    assert cli.main(["approx", str(csv_2d), "-m", "6", "--plot", str(png)]) == 0
    image = pytest.importorskip("matplotlib.image").imread(png)
    assert image.ndim == 3 and min(image.shape[:2]) > 100
    assert np.ptp(image[..., :3]) > 0.5  # something is drawn: dark lines on white
    assert f"plot written to {png}" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("content", "args", "message"),
    [
        (None, ["-m", "3"], "curve: cannot read"),
        ("x,y\n0,0\n1,a\n", ["-m", "2"], "line 3: '1,a' is not numeric"),
        ("x,y\n0,0\n1,1,1\n", ["-m", "2"], "line 3: 3 columns, earlier rows have 2"),
        ("x,y\n", ["-m", "2"], "has no data rows"),
        ("0,0\n1,1\n2,0\n", ["-m", "1"], "m: 1 is too small for an open curve"),
        ("0,0\n1,1\n2,0\n", ["-m", "3", "--closed"], None),
        ("0,0\n1,1\n2,0\n", ["-m", "4"], "m: 4 exceeds the number of points n=3"),
        ("0,0,0,0\n1,1,1,1\n", ["-m", "2"], "points: has shape (2, 4)"),
        ("0,0\nnan,1\n2,0\n", ["-m", "2"], "points: contains NaN or inf"),
    ],
)
def test_errors_are_reported_with_the_argument(tmp_path, capsys, content, args, message):
    path = tmp_path / "c.csv"
    if content is not None:
        path.write_text(content)
    code = cli.main(["approx", str(path), *args])
    err = capsys.readouterr().err
    if message is None:
        assert code == 0
        return
    assert code == 2
    assert err.startswith("regrasp-pin approx: error: ")
    assert message in err


def test_unknown_choice_lists_the_valid_ones(csv_2d, capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(["approx", str(csv_2d), "-m", "3", "--deviation", "mean"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "argument --deviation: invalid choice: 'mean'" in err
    assert all(name in err for name in DEVIATIONS)


def test_cli_choices_match_the_library():
    assert approx._DEVIATIONS == DEVIATIONS
    assert approx._METHODS == METHODS
