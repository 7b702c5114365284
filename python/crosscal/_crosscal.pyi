"""Type stubs of the native module (python/src/lib.rs). Use the package's public API
(``crosscal.fit``, ``crosscal.correct`` …); these are its building blocks."""

from typing import Any, Optional

import numpy as np
import numpy.typing as npt

F64 = npt.NDArray[np.float64]

class Session:
    serial: str
    path: Optional[str]
    run_names: list[str]
    n_samples: int
    warnings: list[str]
    def manifest_json(self) -> str: ...
    def run_columns(self, index: int) -> tuple[F64, F64, F64, Optional[F64]]: ...
    def save(self, folder: str) -> str: ...

class Streaming:
    warmup_samples: int
    samples: int
    time_offset_s: float
    def __init__(
        self,
        profile_json: str,
        temperature_range: str = "clamp",
        gyro_unit: Optional[str] = None,
        accel_unit: Optional[str] = None,
    ) -> None: ...
    def push_block(
        self,
        t: F64,
        gyro: F64,
        accel: F64,
        temp: Optional[F64] = None,
        out: Optional[tuple[F64, F64, F64, npt.NDArray[np.uint8]]] = None,
    ) -> tuple[F64, F64, F64, npt.NDArray[np.uint8]]: ...
    def reset(self) -> None: ...
    def temperature_warning(self) -> Optional[str]: ...

class Diagnosis:
    kind: str
    verdict: str
    temperature_note: Optional[str]
    def json(self) -> str: ...
    def html(self) -> str: ...

def read_session(path: str, strict: bool = False) -> Session: ...
def session_from_columns(
    manifest_json: str, runs: list[tuple[F64, F64, F64, Optional[F64]]]
) -> Session: ...
def fit(
    session: Session,
    preset: str,
    effects: list[str],
    disable: list[str],
    robust: bool,
    strict: bool,
    holdout: list[str],
    stand: bool,
    classic_six_position: bool,
    trim_rest: bool,
    stream: bool,
    noise_json: Optional[str],
) -> tuple[str, int, bool, list[str], Optional[str]]: ...
def profile_normalise(json: str, label: str) -> str: ...
def profile_read(path: str) -> tuple[str, str]: ...
def profile_save(json: str, store: str) -> str: ...
def correct(
    profile_json: str,
    t: F64,
    gyro: F64,
    accel: F64,
    temp: Optional[F64],
    mode: str,
    temperature_range: str,
    gyro_unit: Optional[str],
    accel_unit: Optional[str],
) -> tuple[F64, F64, F64, Optional[npt.NDArray[np.uint8]], int, float, list[str]]: ...
def diagnose(
    session: Session, preset: str, effects: list[str], profile_json: Optional[str], trim_rest: bool
) -> Diagnosis: ...
def datasheet(
    store: str,
    unit: str,
    at: Optional[str],
    gyro_range_deg_s: Optional[float],
    accel_range_g: Optional[float],
) -> str: ...
def cpk(
    values: list[float], lsl: Optional[float], usl: Optional[float]
) -> tuple[float, float, Optional[float], Optional[float], Optional[float]]: ...
def noise(
    data: F64,
    channels: list[str],
    rate_hz: float,
    gyro_unit: str,
    accel_unit: str,
    g_m_s2: float,
    max_tau_s: Optional[float],
    deviation: str,
    source: str,
) -> str: ...
def plan(
    rates_deg_s: list[float],
    cone_angles_deg: list[float],
    mounts: int,
    duration_s: float,
    rate_hz: float,
    preset: str,
    effects: list[str],
    arw_deg_rt_h: float,
    vrw_m_s_rt_h: float,
    suggest: bool,
) -> str: ...
def simulate(options: dict[str, Any]) -> Session: ...
def check(session: Session, profile_json: str, mode: str, allow_other_unit: bool = False) -> str: ...
def paper_table(session: Session, profile_json: str, run: str) -> str: ...
def exit_codes() -> list[tuple[int, str]]: ...
def version() -> str: ...
def register_effects(source: str, is_text: bool) -> list[str]: ...
def bench_rust_streaming(profile_json: str, t_s: F64, gyro_rad_s: F64, accel_m_s2: F64, block: int) -> float: ...
