"""The package against known truth: simulate with known parameters, fit, and check the
recovery within the predicted uncertainty; the diagnosis finds a hidden effect and invents
none on a clean unit; noise terms of known white noise; errors from bad arrays."""

import threading
import time

import numpy as np
import pytest

import crosscal

G_XZ = 5e-5


@pytest.fixture(scope="module")
def hidden():
    return crosscal.simulate(gyro_noise_deg_s=0.002, accel_noise_g=2e-5, seed=3, duration_s=12,
                             hidden=["gyro-g-sensitivity"], set={"gyro.g_xz": G_XZ})


def test_fit_recovers_the_paper_unit_within_its_uncertainty():
    s = crosscal.simulate(gyro_noise_deg_s=0.002, accel_noise_g=2e-5, seed=11, duration_s=12)
    p = crosscal.fit(s)
    c = p.coefficients.set_index("name")
    # The paper's unit (spec eqs. 3-4): C_w diagonal 1, c_xy = c_yz = c_zx = 0.01; C_e
    # e_xz = e_yx = e_zy = 0.001 s; K diagonal 1, off-diagonal 0.01; no bias.
    def truth(name):
        kind, rest = name.split(".")
        if rest.startswith("b_"):
            return 0.0
        i, j = rest[2], rest[3]
        if kind == "accel":
            return 1.0 if i == j else 0.01
        if rest.startswith("c_"):
            return 1.0 if i == j else (0.01 if i + j in ("xy", "yz", "zx") else 0.0)
        return 0.001 if i + j in ("xz", "yx", "zy") else 0.0

    z = [(n, (r["value"] - truth(n)) / r["std_error"]) for n, r in c.iterrows()]
    assert len(z) == 33
    assert all(abs(v) < 4 for _, v in z), z
    assert np.mean([v * v for _, v in z]) < 3  # the standard errors are not too small either
    assert (c["status"] == "fitted").all()
    cov = p.covariance
    se = np.sqrt(np.diag(cov.to_numpy()))
    fitted = c.loc[cov.index, "std_error"].to_numpy(dtype=float)
    assert np.allclose(se, fitted, rtol=1e-9)


def test_diagnose_finds_the_hidden_effect_and_the_fit_recovers_it(hidden):
    d = crosscal.diagnose(hidden)
    assert d.verdict == "explained"
    assert d.proposal == ["gyro-g-sensitivity"]
    assert list(d.steps["effect"]) == ["gyro-g-sensitivity"]
    assert len(d.candidates) > 10 and {"effect", "p_value", "delta_bic"} <= set(d.candidates.columns)
    html = d.to_html()
    assert html.startswith("<!DOCTYPE html>") and "<svg" in html
    p = crosscal.fit(hidden, effects=d.proposal)
    g = p.coefficients.set_index("name").loc["gyro.g_xz"]
    assert abs(g["value"] - G_XZ) < 3 * g["std_error"]
    before = crosscal.check(crosscal.fit(hidden), hidden)
    after = crosscal.check(p, hidden)
    assert not before.passed and after.passed


def test_a_clean_unit_gets_no_effect_over_seeds():
    false = 0
    for seed in (21, 22, 23):
        s = crosscal.simulate(gyro_noise_deg_s=0.002, accel_noise_g=2e-5, seed=seed, duration_s=12)
        false += len(crosscal.diagnose(s).proposal)
    assert false == 0


def test_the_paper_table_passes():
    s = crosscal.simulate()
    t = crosscal.paper_table(crosscal.fit(s), s)
    assert len(t) == 6 and t["pass"].all()
    z = t[(t.sensor == "gyro") & (t.axis == "z")].iloc[0]
    assert z["before_pct"] > 10 and z["offline_pct"] < 0.4


def test_noise_reads_a_known_white_density():
    rate = 200.0
    sigma = 0.05  # deg/s per sample
    x = np.random.default_rng(5).normal(0.0, sigma, size=(400_000, 1))
    r = crosscal.noise(x, rate, ["gz"])
    n = r.terms.loc["gz", "white_density"]
    expected = np.radians(sigma) / np.sqrt(rate)  # rad/s/√Hz
    assert n == pytest.approx(expected, rel=0.05)
    assert set(r.curve.columns) >= {"tau_s", "adev", "low", "high"}
    p = crosscal.fit(crosscal.simulate(duration_s=12), noise=r)
    assert p.data["noise"]["channels"][0]["channel"] == "gz"


def test_plan_predicts_what_the_fit_reports():
    # 1 mount, two rates, one cone: a few coefficients are unidentifiable, the rest get σ.
    plan = crosscal.plan([10, -10], [10], 1, duration_s=20, suggest=False)
    assert plan["unidentifiable"]
    fitted = [c for c in plan["coefficients"] if c["std_error"] is not None]
    assert fitted and all(c["std_error"] > 0 for c in fitted)


def test_bad_arrays_are_refused_naming_run_row_and_column():
    t = np.arange(100) * 0.01
    g = np.zeros((100, 3))
    a = np.tile([0.0, 0.0, 1.0], (100, 1))
    motion = {"kind": "static", "up_stand": [0, 0, 1]}
    g[41, 2] = np.nan
    with pytest.raises(crosscal.errors.BadValueError) as e:
        crosscal.Session.from_arrays("U1", [{"name": "still", "motion": motion, "t": t, "gyro": g, "accel": a}])
    assert "<memory>/still:42:4 (gz)" in str(e.value) and e.value.exit_code == 6
    g[41, 2] = 0.0
    t2 = t.copy()
    t2[10] = t2[9]
    with pytest.raises(crosscal.errors.TimeOrderError):
        crosscal.Session.from_arrays("U1", [{"name": "still", "motion": motion, "t": t2, "gyro": g, "accel": a}])
    with pytest.raises(crosscal.errors.UsageError):
        crosscal.Session.from_arrays("U1", [{"name": "still", "motion": motion, "t": t, "gyro": g[:, :2], "accel": a}])
    with pytest.raises(crosscal.errors.ManifestError):
        crosscal.Session.from_arrays("U1", [{"name": "still", "motion": {"kind": "spin"}, "t": t, "gyro": g, "accel": a}])


def test_profiles_round_trip_and_are_never_overwritten(tmp_path, hidden):
    p = crosscal.fit(hidden)
    q = crosscal.Profile.from_json(p.to_json())
    assert q.to_json() == p.to_json()
    first = p.save(tmp_path)
    second = p.save(tmp_path)
    assert first != second
    assert crosscal.Profile.load(tmp_path / p.serial).to_json() == p.to_json()
    with pytest.raises(crosscal.errors.ProfileFormatError):
        crosscal.Profile.from_json(p.to_json().replace("crosscal-profile/", "crosscal-profile-x/"))


def test_temperature_outside_the_range_is_clamped_or_refused():
    s = crosscal.simulate(temperature_c=[10, 40], hidden=["gyro-temp-bias"], set={"gyro.tb_x": 1e-4},
                          duration_s=12, gyro_noise_deg_s=0.001)
    p = crosscal.fit(s, effects=["gyro-temp-bias"])
    assert p.temperature_range_c[0] >= 10 - 1e-9 and p.temperature_range_c[1] <= 40 + 1e-9
    t, g, a, temp = s.arrays(0)
    hot = np.full_like(t, 55.0)
    c = crosscal.correct(p, t, g, a, hot)
    assert c.warnings and "outside" in c.warnings[0]
    with pytest.raises(crosscal.errors.CorrectionError):
        crosscal.correct(p, t, g, a, hot, temperature_range="error")
    with pytest.raises(crosscal.errors.CorrectionError):
        crosscal.correct(p, t, g, a)  # the model needs temperatures


def test_long_calls_release_the_gil():
    """Another Python thread keeps running while a correction runs: with the GIL held it
    would get at most one switch interval (5 ms) of the call."""
    s = crosscal.simulate(duration_s=12)
    p = crosscal.fit(s)
    n = 3_000_000
    t = np.arange(n) * 0.001
    g = np.tile([1.0, 2.0, 3.0], (n, 1))
    a = np.tile([0.0, 0.0, 1.0], (n, 1))
    count = [0]
    stop = threading.Event()

    def spin():
        while not stop.is_set():
            count[0] += 1

    th = threading.Thread(target=spin)
    th.start()
    time.sleep(0.2)
    c0, t0 = count[0], time.perf_counter()
    time.sleep(0.2)
    rate = (count[0] - c0) / (time.perf_counter() - t0)  # increments per second, alone
    shares = []
    for _ in range(3):
        c0, t0 = count[0], time.perf_counter()
        crosscal.correct(p, t, g, a, mode="offline")
        shares.append((count[0] - c0) / (rate * (time.perf_counter() - t0)))
    stop.set()
    th.join()
    # Released, the other thread counts through most of each call (two cores); held, it
    # could count for a switch interval at most, a few percent of a call this long.
    assert max(shares) > 0.5, shares


def test_slow_noise_is_noise_in_the_fit_and_the_diagnosis():
    # A MEMS-like unit whose bias wanders over the session clock (flicker and random walk
    # carried from run to run): with slow_noise the diagnosis calls it adequate and the
    # fit's bias standard errors widen to cover the wander.
    s = crosscal.simulate(arw_deg_rt_h=0.3, gyro_bias_instability_deg_h=8.0, rrw_deg_h_rt_h=60.0,
                          vrw_m_s_rt_h=0.06, accel_bias_instability_ug=60.0, accel_random_walk=2e-5,
                          carry_noise=True, session_clock_s=5.0, rates_deg_s=[10.0, -10.0, 20.0],
                          cone_angles_deg=[10.0, 20.0], mounts=3, duration_s=30.0, rate_hz=50.0,
                          seed=36104)
    d = crosscal.diagnose(s, slow_noise=True)
    assert d.verdict == "adequate", d.verdict
    # The default (automatic) choice takes the wander for noise too; the AR model alone
    # does not.
    assert crosscal.diagnose(s).verdict == "adequate"
    assert crosscal.diagnose(s, slow_noise=False).verdict == "unexplained"
    plain = crosscal.fit(s).coefficients.set_index("name")["std_error"]
    slow = crosscal.fit(s, slow_noise=True).coefficients.set_index("name")["std_error"]
    for b in ("gyro.b_x", "gyro.b_y", "gyro.b_z", "accel.b_x", "accel.b_y", "accel.b_z"):
        assert slow[b] > plain[b], (b, slow[b], plain[b])


KNEE = """
[[effect]]
id = "py-gyro-x-knee"
sensor = "gyro"
output = "x"
expr = "k * max(w_x - w0, 0)"
coefficients = ["k"]
parameters = { w0 = "3 deg" }
description = "scale step above a rate"
"""


def test_user_effects_from_text_everywhere_and_bad_ones_raise():
    assert crosscal.load_effects(text=KNEE) == ["py-gyro-x-knee"]
    w0 = np.radians(4.0)
    s = crosscal.simulate(gyro_noise_deg_s=0.002, accel_noise_g=2e-5, seed=5, duration_s=12,
                          rates_deg_s=[10, -10, 20], hidden=["py-gyro-x-knee"],
                          set={"py-gyro-x-knee.k": 0.03, "py-gyro-x-knee.w0": w0})
    # The diagnosis tries it beside the catalogue and proposes it alone.
    d = crosscal.diagnose(s)
    assert d.verdict == "explained" and d.proposal == ["py-gyro-x-knee"], (d.verdict, d.proposal)
    # The fit recovers it within 3 standard errors; the profile carries its definition.
    p = crosscal.fit(s, effects=["py-gyro-x-knee"])
    k = p.coefficients.set_index("name").loc["py-gyro-x-knee.k"]
    assert abs(k["value"] - 0.03) < 3 * k["std_error"], k
    w = next(c for c in p.data["nonlinear"] if c["name"] == "py-gyro-x-knee.w0")
    assert abs(w["value"] - w0) < 3 * w["std_error"], w
    assert p.data["user_effects"][0]["expr"] == "k * max(w_x - w0, 0)"
    # Bad definitions raise the package's exception with the documented exit code (25).
    for text, expected in [
        (KNEE.replace("max(w_x", "max(w_q"), "unknown name 'w_q'"),
        (KNEE.replace("k * max", "k * * max"), ":6:"),
        (KNEE.replace('["k"]', '["k", "m"]'), "coefficient 'm' is never used"),
    ]:
        with pytest.raises(crosscal.errors.EffectsFileError) as e:
            crosscal.load_effects(text=text)
        assert e.value.exit_code == 25 and expected in str(e.value), str(e.value)
