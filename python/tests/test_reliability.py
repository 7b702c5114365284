"""Issue 38: the Python boundary refuses what the command line refuses, and every error is
one of the package's exception classes (never a PanicException, which ``except Exception``
does not catch)."""

import os

import numpy as np
import pytest

import crosscal
from crosscal import errors


@pytest.fixture(scope="module")
def unit():
    s = crosscal.simulate(gyro_noise_deg_s=0.002, accel_noise_g=2e-5, seed=5, duration_s=4)
    return s, crosscal.fit(s)


def _record(n=200):
    t = np.arange(n) * 0.01
    gyro = np.column_stack([np.sin(t), np.cos(t), 0.1 * t])
    accel = np.column_stack([np.zeros(n), np.zeros(n), np.ones(n)])
    return t, gyro, accel


def test_push_block_refuses_time_that_does_not_increase(unit):
    _, p = unit
    t, g, a = _record()
    for bad in ("zero", "equal"):
        tt = t.copy()
        if bad == "zero":
            tt[30] = 0.0
        else:
            tt[31] = tt[30]
        with pytest.raises(errors.TimeOrderError):
            crosscal.correct(p, tt, g, a, mode="streaming")
        with pytest.raises(errors.TimeOrderError, match="does not increase"):
            crosscal.Streaming(p).push_block(tt, g, a)
    # Across blocks: a block repeating earlier stamps is refused, and refused whole.
    s = crosscal.Streaming(p)
    s.push_block(t[:100], g[:100], a[:100])
    with pytest.raises(errors.TimeOrderError):
        s.push_block(t[50:150], g[50:150], a[50:150])
    assert s.samples == 100
    s.push_block(t[100:], g[100:], a[100:])
    s.reset()
    s.push_block(t[:10], g[:10], a[:10])  # a new record may start again


def test_check_refuses_another_units_profile(unit):
    s, p = unit
    other = crosscal.simulate(gyro_noise_deg_s=0.002, seed=6, duration_s=4, serial="OTHER-1")
    with pytest.raises(errors.WrongUnitError):
        crosscal.check(p, other)
    assert crosscal.check(p, other, allow_other_unit=True) is not None
    assert crosscal.check(p, s) is not None


def test_save_keeps_run_files_inside_the_folder(tmp_path):
    t, g, a = _record(50)
    for name in ("../ESC", "/tmp/abs", "sub/run", "../.."):
        run = {"name": name, "motion": {"kind": "static", "up_stand": [0, 0, 1]}, "t": t, "gyro": g, "accel": a}
        s = crosscal.Session.from_arrays("U1", [run])
        with pytest.raises(errors.UsageError, match="plain file name"):
            s.save(tmp_path / "out")
    assert not (tmp_path / "ESC.csv").exists()


def test_out_arrays_that_alias_or_are_read_only_are_usage_errors(unit):
    _, p = unit
    t, g, a = _record(64)
    n = len(t)
    s = crosscal.Streaming(p)
    ro = np.zeros(n)
    ro.flags.writeable = False
    shared = np.zeros((n, 3))
    cases = {
        "read-only t": (ro, np.zeros((n, 3)), np.zeros((n, 3)), np.zeros(n, dtype=np.uint8)),
        "gyro and accel the same array": (np.zeros(n), shared, shared, np.zeros(n, dtype=np.uint8)),
        "out t is the input t": (t, np.zeros((n, 3)), np.zeros((n, 3)), np.zeros(n, dtype=np.uint8)),
        "wrong length": (np.zeros(n - 1), np.zeros((n, 3)), np.zeros((n, 3)), np.zeros(n, dtype=np.uint8)),
        "wrong dtype": (np.zeros(n, dtype=np.float32), np.zeros((n, 3)), np.zeros((n, 3)), np.zeros(n, dtype=np.uint8)),
        "flags dtype": (np.zeros(n), np.zeros((n, 3)), np.zeros((n, 3)), np.zeros(n)),
    }
    for what, out in cases.items():
        try:
            s.push_block(t, g, a, out=out)
        except errors.CrosscalError as e:
            assert "out" in str(e), (what, str(e))
        else:
            raise AssertionError(f"{what}: accepted")
    # A good out still works after every refusal.
    out = (np.zeros(n), np.zeros((n, 3)), np.zeros((n, 3)), np.zeros(n, dtype=np.uint8))
    r = s.push_block(t, g, a, out=out)
    assert r[0] is out[0] and np.isfinite(out[1]).all()


def _huge_arrays(tmp_path):
    """t, gyro and accel of more samples than this machine's RAM and swap could correct, as
    sparse memory-mapped files (nothing is read or allocated to make them)."""
    with open("/proc/meminfo") as f:
        kib = {line.split(":")[0]: int(line.split()[1]) for line in f if line.split()[1].isdigit()}
    n = int((kib["MemTotal"] + kib.get("SwapTotal", 0)) * 1024 // 100) + 1
    arrays = []
    for name, shape in (("t", (n,)), ("gyro", (n, 3)), ("accel", (n, 3))):
        path = tmp_path / f"{name}.bin"
        with open(path, "wb") as f:
            f.truncate(8 * n * (3 if len(shape) == 2 else 1))
        arrays.append(np.memmap(path, dtype=np.float64, mode="r", shape=shape))
    return n, arrays


@pytest.mark.skipif(not os.path.exists("/proc/meminfo"), reason="needs Linux's /proc/meminfo")
def test_inputs_too_large_for_memory_raise_the_packages_error(unit, tmp_path):
    # Issue 38 item 8: the interpreter used to abort on the refused allocation.
    _, profile = unit
    n, (t, gyro, accel) = _huge_arrays(tmp_path)
    with pytest.raises(crosscal.errors.OutOfMemoryError) as e:
        crosscal.correct(profile, t, gyro, accel)
    assert isinstance(e.value, MemoryError) and isinstance(e.value, crosscal.CrosscalError)
    assert f"{n} samples" in str(e.value) and "push_block" in str(e.value)
    with pytest.raises(crosscal.errors.OutOfMemoryError):
        crosscal.Streaming(profile).push_block(t, gyro, accel)
    with pytest.raises(crosscal.errors.OutOfMemoryError):
        run = {"name": "r", "motion": {"kind": "static", "up_stand": [0, 0, 1]}, "t": t, "gyro": gyro, "accel": accel}
        crosscal.Session.from_arrays("big", [run])
    # A name that is not there is the package's error and still a KeyError.
    with pytest.raises(crosscal.errors.NotFoundError) as e:
        profile.value("gyro.no_such_coefficient")
    assert isinstance(e.value, KeyError) and "no_such_coefficient" in str(e.value)
