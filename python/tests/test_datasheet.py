"""Datasheets and lot capability from Python: the same numbers as the command, the paper
unit's known misalignment, and Cpk against a hand computation."""

import json
import math

import pytest

import crosscal
from conftest import run


@pytest.fixture(scope="module")
def store(tmp_path_factory, crosscal_bin):
    d = tmp_path_factory.mktemp("ds")
    run(crosscal_bin, "simulate", "--preset", "paper", "--duration", "6", "--gyro-noise", "0.002",
        "--accel-noise", "2e-5", "-o", d / "demo")
    run(crosscal_bin, "fit", d / "demo/session.json", "--out", d / "store")
    return d / "store"


def test_datasheet_frame_is_the_commands_json(store, crosscal_bin):
    frame = crosscal.datasheet("I1426-0042", store)
    cli = json.loads(run(crosscal_bin, "datasheet", "I1426-0042", "--store", store, "--json").stdout)
    assert len(frame) == len(cli["quantities"])
    mis = frame[frame["name"] == "gyro.misalignment"].set_index("axis")
    # The paper's unit: c_xy = c_yz = c_zx = 0.01, so each pair of axes is 10 mrad from 90°.
    for pair in ("xy", "yz", "zx"):
        assert mis.loc[pair, "unit"] == "mrad"
        assert abs(mis.loc[pair, "value"] - 10.0) < 5 * mis.loc[pair, "uncertainty"] + 0.05
    arw = frame[frame["name"] == "gyro.arw"].iloc[0]
    assert math.isnan(arw["value"]) and "crosscal noise" in arw["not_measured"]
    assert frame.attrs["unit"] == "I1426-0042"


def test_cpk_matches_the_formula():
    vals = [0.1, -0.2, 0.3, 0.0, 0.15, -0.05]
    r = crosscal.cpk(vals, -1.0, 1.0)
    n = len(vals)
    m = sum(vals) / n
    s = math.sqrt(sum((v - m) ** 2 for v in vals) / (n - 1))
    c = min(1 - m, m + 1) / (3 * s)
    assert abs(r["cpk"] - c) < 1e-12
    se = math.sqrt(1 / (9 * n) + c * c / (2 * (n - 1)))
    assert abs(r["cpk_low"] - (c - 1.96 * se)) < 1e-12
    with pytest.raises(crosscal.CrosscalError):
        crosscal.cpk([1.0])


def test_unknown_unit_is_an_error(store):
    with pytest.raises(crosscal.CrosscalError):
        crosscal.datasheet("NO-SUCH", store)
