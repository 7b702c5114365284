"""The Python package and the command line give the same numbers: a fit of the same
session gives the same profile bit for bit (apart from its creation time), and a
correction through numpy equals `crosscal correct`'s output file."""

import json

import numpy as np
import pytest

import crosscal
from conftest import run


def read_csv(path):
    """A recording CSV as (header, array); the shortest-round-trip decimals crosscal writes
    parse back to the same doubles."""
    with open(path) as f:
        header = f.readline().strip().split(",")
    return header, np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)


def without_time(profile_json):
    d = json.loads(profile_json)
    d.pop("created_utc")
    return d


@pytest.fixture(scope="module")
def unit(tmp_path_factory, crosscal_bin):
    """A simulated unit with a hidden g-sensitivity, noise and a temperature ramp."""
    d = tmp_path_factory.mktemp("unit")
    run(crosscal_bin, "simulate", "-o", d / "s", "--gyro-noise", "0.002", "--accel-noise", "2e-5", "--seed", "7",
        "--hidden", "gyro-g-sensitivity", "--set", "gyro.g_xz=0.00005", "--rates", "10,-10,20", "--cone-angles", "10,20",
        "--duration", "12")
    return d


@pytest.mark.parametrize("args", [[], ["--model", "paper"], ["--effect", "gyro-g-sensitivity", "--robust"]])
def test_fit_from_a_manifest_equals_the_command_bit_for_bit(unit, crosscal_bin, args):
    cli = run(crosscal_bin, "fit", unit / "s/session.json", "--json", "--dry-run", *args).stdout
    model = args[args.index("--model") + 1] if "--model" in args else "default"
    effects = [args[args.index("--effect") + 1]] if "--effect" in args else []
    p = crosscal.fit(unit / "s/session.json", model, effects, robust="--robust" in args)
    assert without_time(p.to_json()) == without_time(cli)
    # Not merely close: every coefficient is the same double.
    for sensor in ("gyro", "accel"):
        a = [c["value"] for c in json.loads(cli)[sensor]["coefficients"]]
        b = [c["value"] for c in p.data[sensor]["coefficients"]]
        assert [x.hex() for x in a] == [x.hex() for x in b]


def test_a_session_built_from_dataframes_fits_as_its_files_do(unit, crosscal_bin):
    """The same samples handed over as DataFrames (read back from the CSVs) give the same
    coefficients as the command on the files, to rounding of the summation order."""
    s = crosscal.read_session(unit / "s/session.json")
    manifest = s.manifest
    runs = []
    for r in manifest["runs"]:
        header, a = read_csv(unit / "s" / r["file"])
        import pandas as pd

        runs.append({"name": r["name"], "motion": r["motion"], "mount": r["mount"], "data": pd.DataFrame(a, columns=header)})
    built = crosscal.Session.from_arrays(manifest["serial"], runs)
    assert built.n_samples == s.n_samples and built.path is None
    mem = crosscal.fit(built)
    cli = json.loads(run(crosscal_bin, "fit", unit / "s/session.json", "--json", "--dry-run").stdout)
    for sensor in ("gyro", "accel"):
        for c, m in zip(cli[sensor]["coefficients"], mem.data[sensor]["coefficients"]):
            assert c["name"] == m["name"]
            assert m["value"] == pytest.approx(c["value"], rel=1e-9, abs=1e-12 * max(1.0, abs(c["value"])))
            if c["std_error"] is not None:
                assert m["std_error"] == pytest.approx(c["std_error"], rel=1e-6)


@pytest.mark.parametrize("mode", ["offline", "streaming"])
def test_correction_through_numpy_equals_crosscal_correct(unit, crosscal_bin, tmp_path, mode):
    store = tmp_path / "profiles"
    run(crosscal_bin, "fit", unit / "s/session.json", "--out", store, "--effect", "gyro-g-sensitivity")
    out = tmp_path / f"{mode}.csv"
    run(crosscal_bin, "correct", "--profile", store / "I1426-0042", unit / "s/cone+20.csv", "-o", out, "--mode", mode)
    _, expected = read_csv(out)
    _, rec = read_csv(unit / "s/cone+20.csv")
    profile = crosscal.Profile.load(store / "I1426-0042")
    c = crosscal.correct(profile, rec[:, 0], rec[:, 1:4], rec[:, 4:7], mode=mode)
    got = np.column_stack([c.t, c.gyro, c.accel])
    assert got.shape == expected.shape
    assert np.array_equal(got, expected), f"largest difference {np.max(np.abs(got - expected))}"
    if mode == "streaming":
        # The block corrector fed in uneven pieces gives the same bits as one call.
        s = crosscal.Streaming(profile)
        pieces = [s.push_block(rec[a:b, 0], rec[a:b, 1:4], rec[a:b, 4:7]) for a, b in [(0, 1), (1, 700), (700, 5000), (5000, len(rec))]]
        joined = np.column_stack([np.concatenate([p[0] for p in pieces]), np.concatenate([p[1] for p in pieces]),
                                  np.concatenate([p[2] for p in pieces])])
        assert np.array_equal(joined, expected)


def test_errors_carry_the_command_lines_message_and_exit_code(tmp_path, crosscal_bin, unit):
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "session.json").write_text((unit / "s/session.json").read_text())
    for f in (unit / "s").glob("*.csv"):
        (bad / f.name).write_text(f.read_text())
    lines = (bad / "cone+10.csv").read_text().splitlines()
    fields = lines[3].split(",")
    fields[4] = "abc"
    lines[3] = ",".join(fields)
    (bad / "cone+10.csv").write_text("\n".join(lines) + "\n")
    cli = run(crosscal_bin, "fit", bad / "session.json", "--dry-run", check=False)
    assert cli.returncode == 6
    with pytest.raises(crosscal.errors.BadValueError) as e:
        crosscal.read_session(bad / "session.json")
    assert e.value.exit_code == 6
    assert "cone+10.csv:4:5 (ax)" in str(e.value)
    assert "cone+10.csv:4:5 (ax)" in cli.stderr
    # The innermost cause, as the command prints it, is in the exception's message.
    assert cli.stderr.strip().split(": ", 1)[1].endswith(str(e.value).split(": ", 1)[1])
