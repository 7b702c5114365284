"""Benchmark: streaming correction of a 1e7-sample numpy array through the Python package
against the Rust library's own streaming corrector on the same samples, in one run.

    pip install ./python && python3 benches/python_streaming.py [N]

Rows: the Rust library (`Streaming::push_block` on SI arrays, blocks of 65 536 samples,
buffers allocated once; and `correct_streaming` on the whole record, its outputs allocated);
`crosscal.Streaming.push_block` on arrays in the profile's units
(deg/s and g: converted a block at a time inside the call), and on SI arrays (read in
place); `crosscal.correct(..., mode="streaming")` on the whole array. Each is timed best of
three; the ratio is the Python path's rate over the Rust call it stands for (blocks against
blocks, the whole array against the whole record).
"""

import sys
import time

import numpy as np

import crosscal
from crosscal import _crosscal

N = int(float(sys.argv[1])) if len(sys.argv) > 1 else 10_000_000
BLOCK = 65_536


def best(f, repeat=3):
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        f()
        times.append(time.perf_counter() - t0)
    return min(times)


def main():
    session = crosscal.simulate(gyro_noise_deg_s=0.002, accel_noise_g=2e-5, duration_s=12)
    profile = crosscal.fit(session)
    rate_hz = 1000.0
    t = np.arange(N) / rate_hz
    phase = 2 * np.pi * 0.5 * t
    gyro = np.column_stack([10 * np.sin(phase), 10 * np.cos(phase), np.full(N, 3.0)])  # deg/s
    accel = np.column_stack([0.1 * np.sin(phase), 0.1 * np.cos(phase), np.ones(N)])  # g
    g_si, a_si = np.radians(gyro), accel * profile.data["g_m_s2"]
    text = profile.to_json()

    rust = min(_crosscal.bench_rust_streaming(text, t, g_si, a_si, BLOCK) for _ in range(3))
    rust_whole = min(_crosscal.bench_rust_streaming(text, t, g_si, a_si, 0) for _ in range(3))

    def blocks(g, a, **units):
        s = crosscal.Streaming(profile, **units)
        out = (np.empty(BLOCK), np.empty((BLOCK, 3)), np.empty((BLOCK, 3)), np.empty(BLOCK, dtype=np.uint8))
        for k in range(0, N, BLOCK):
            e = min(k + BLOCK, N)
            m = e - k
            s.push_block(t[k:e], g[k:e], a[k:e], out=out if m == BLOCK else None)

    # Each Python path against the Rust call it stands for: blocks against blocks, the
    # whole array against the whole record.
    rows = [
        ("Rust library: Streaming::push_block, SI", rust, rust),
        ("Python: Streaming.push_block, deg/s and g", best(lambda: blocks(gyro, accel)), rust),
        ("Python: Streaming.push_block, SI arrays", best(lambda: blocks(g_si, a_si, gyro_unit="rad/s", accel_unit="m/s^2")), rust),
        ("Rust library: correct_streaming (whole), SI", rust_whole, rust_whole),
        ("Python: correct(mode='streaming'), deg/s and g", best(lambda: crosscal.correct(profile, t, gyro, accel, mode="streaming")), rust_whole),
    ]
    print(f"{N:.0e} samples, profile '{profile.model}'")
    print(f"{'path':<50} {'time s':>8} {'Msamples/s':>11} {'vs Rust':>8}")
    for name, secs, peer in rows:
        print(f"{name:<50} {secs:8.3f} {N / secs / 1e6:11.1f} {peer / secs:8.2f}")


if __name__ == "__main__":
    main()
