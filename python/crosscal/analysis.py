"""The calibration itself: fit a profile, correct outputs (offline or streaming), diagnose
what a model misses, characterise noise, plan a session and simulate one. Each function is
the library call the ``crosscal`` command makes, so the numbers are the command's.
"""

from __future__ import annotations

import json
from typing import Any, Optional, Sequence, Union

import numpy as np

from . import _crosscal
from .profile import Profile
from .session import PathLike, Session, contiguous_f64, read_session

SessionLike = Union[Session, PathLike]


def _session(s: SessionLike) -> Session:
    return s if isinstance(s, Session) else read_session(s)


def fit(
    session: SessionLike,
    model: str = "default",
    effects: Sequence[str] = (),
    *,
    disable: Sequence[str] = (),
    robust: bool = False,
    strict: bool = False,
    holdout: Sequence[str] = (),
    stand: bool = False,
    classic_six_position: bool = False,
    trim_rest: bool = False,
    stream: bool = False,
    noise: Optional["AllanResult"] = None,
    effects_file: Optional[PathLike] = None,
    slow_noise: bool = False,
    effect_definitions: Optional[str] = None,
) -> Profile:
    """Fit a calibration profile to a session (``crosscal fit``).

    crosscal fits each unit's cross-coupling — the gyro matrix C_ω with its
    angular-acceleration terms C_ε, the accelerometer matrix K, biases and any catalogue
    effect you add — from the session's runs, with every coefficient's standard error and
    what the runs could not identify.

    Parameters
    ----------
    session : Session or path
        A :class:`Session` or the path of a ``session.json``. A session read from disk is
        fitted from its manifest exactly as ``crosscal fit`` fits it (streamed from the
        files where the model allows), so the profile equals the command's bit for bit
        (apart from its creation time).
    model : str
        ``default`` (biases, full C_ω, C_ε, K), ``paper`` (exactly the paper's eqs. 3–4),
        ``ferraris`` or ``tedaldi`` (protocol sessions).
    effects : list of str
        Catalogue effects to add (``crosscal effects`` lists them), e.g.
        ``["gyro-g-sensitivity"]``.
    disable : list of str
        Coefficients held at their nominal value, e.g. ``["gyro.e_xx"]``.
    robust, strict, holdout, stand, classic_six_position, trim_rest, stream
        As the command's ``--robust`` (Huber IRLS), ``--strict`` (gaps and unidentifiable
        coefficients are errors), ``--holdout RUN`` (validate on held-out runs),
        ``--stand`` (estimate each conic run's actual settings), ``--classic-six-position``,
        ``--trim-rest`` and ``--stream``.
    noise : AllanResult, optional
        A noise characterisation to store in the profile (``fit --noise``).
    effects_file : path, optional
        An effects file (TOML) whose user effects may then be named in ``effects``, as
        ``crosscal fit --effects-file F --effect ID`` (see ``docs/your-own-effect.md``).
    effect_definitions : str, optional
        The same ``[[effect]]`` tables given as TOML text instead of a file.
    slow_noise : bool
        As ``--slow-noise``: standard errors that also cover flicker and bias random walk
        (the bias judged against its average over the session).

    Returns
    -------
    Profile
        Not yet stored: ``profile.save("calib-profiles")`` stores it.

    Example
    -------
    >>> s = crosscal.simulate(gyro_noise_deg_s=0.002, accel_noise_g=2e-5)
    >>> p = crosscal.fit(s)
    >>> p.coefficients.head()
    """
    s = _session(session)
    load_effects(effects_file, effect_definitions)
    noise_json = None if noise is None else noise.to_json()
    text, samples, streamed, warnings, validation = _crosscal.fit(
        s._native, model, list(effects), list(disable), robust, strict, list(holdout), stand,
        classic_six_position, trim_rest, stream, noise_json, slow_noise,
    )
    return Profile(text, samples=samples, streamed=streamed, warnings=warnings,
                   validation=None if validation is None else json.loads(validation))


def load_effects(path: Optional[PathLike] = None, text: Optional[str] = None) -> list[str]:
    """Add user effects to this process's catalogue, from an effects file (``path``) or
    TOML text (``text``): afterwards their ids work wherever a catalogue effect's does
    (``fit``, ``simulate``'s hidden effects, ``diagnose``). Returns the ids loaded.
    Errors (syntax, unknown variables, unused coefficients) raise with exit code 25."""
    ids: list[str] = []
    if path is not None:
        ids += _crosscal.register_effects(str(path), False)
    if text is not None:
        ids += _crosscal.register_effects(text, True)
    return ids


def _profile_json(profile: Union[Profile, PathLike, str]) -> str:
    if isinstance(profile, Profile):
        return profile.to_json()
    return Profile.load(profile).to_json()


class Corrected:
    """A corrected record: ``t`` (shifted by the profile's time delay, if any), ``gyro``
    and ``accel`` (n, 3) in the input's units (raw inputs come out in deg/s and g),
    ``flags`` (per sample, channels inside a dead band; None when none), ``warmup``
    (leading streaming samples before the derivative window was full), ``time_offset_s``
    and ``warnings`` (samples outside the calibrated temperature range). Unpacks as
    ``gyro, accel = corrected``."""

    def __init__(self, t: np.ndarray, gyro: np.ndarray, accel: np.ndarray, flags: Optional[np.ndarray],
                 warmup: int, time_offset_s: float, warnings: list[str]) -> None:
        self.t, self.gyro, self.accel, self.flags = t, gyro, accel, flags
        self.warmup, self.time_offset_s, self.warnings = warmup, time_offset_s, warnings

    def __iter__(self):
        return iter((self.gyro, self.accel))

    def to_dataframe(self) -> "Any":
        """The record as a DataFrame with columns t, gx … az (and flags when present)."""
        import pandas as pd

        g, a = self.gyro, self.accel
        frame = {"t": self.t, "gx": g[:, 0], "gy": g[:, 1], "gz": g[:, 2], "ax": a[:, 0], "ay": a[:, 1], "az": a[:, 2]}
        if self.flags is not None:
            frame["flags"] = self.flags
        return pd.DataFrame(frame)


def _f64(a: Any) -> np.ndarray:
    return contiguous_f64(a)


def correct(
    profile: Union[Profile, PathLike],
    t: Any,
    gyro: Any,
    accel: Any,
    temp: Any = None,
    mode: str = "offline",
    *,
    temperature_range: str = "clamp",
    gyro_unit: Optional[str] = None,
    accel_unit: Optional[str] = None,
) -> Corrected:
    """Correct a unit's outputs with its profile (``crosscal correct``): C⁻¹ and K⁻¹ with
    the angular-acceleration terms and every effect in the profile undone.

    ``t`` (n,), ``gyro`` and ``accel`` (n, 3), ``temp`` (n,, °C) when the profile has
    temperature terms; in the units of the profile's sessions unless ``gyro_unit`` /
    ``accel_unit`` say otherwise. C-contiguous float64 arrays are read in place (others are
    converted once). ``mode="offline"`` uses the whole record (centred derivative,
    iterated); ``"streaming"`` is causal, as on the unit. ``temperature_range``: outside
    the calibrated range ``clamp`` (default), ``extrapolate`` or ``error``
    (:class:`crosscal.errors.CorrectionError`). The result equals ``crosscal correct`` on
    the same samples bit for bit.
    """
    text = _profile_json(profile)
    r = _crosscal.correct(text, _f64(t), _f64(gyro), _f64(accel), None if temp is None else _f64(temp), mode,
                          temperature_range, gyro_unit, accel_unit)
    return Corrected(*r)


class Streaming:
    """A causal corrector that keeps its state between blocks (what runs on the unit):

    >>> s = crosscal.Streaming(profile)
    >>> for t, g, a in blocks:
    ...     t_c, g_c, a_c, flags = s.push_block(t, g, a)

    Fixed memory; the block is corrected with the GIL released. Pass ``out=(t, gyro,
    accel, flags)`` arrays to write into them instead of allocating new ones.
    """

    def __init__(self, profile: Union[Profile, PathLike], *, temperature_range: str = "clamp",
                 gyro_unit: Optional[str] = None, accel_unit: Optional[str] = None) -> None:
        self._native = _crosscal.Streaming(_profile_json(profile), temperature_range, gyro_unit, accel_unit)

    def push_block(self, t: Any, gyro: Any, accel: Any, temp: Any = None, out: Any = None):
        """Correct the next block; returns ``(t, gyro, accel, flags)``."""
        return self._native.push_block(_f64(t), _f64(gyro), _f64(accel), None if temp is None else _f64(temp), out)

    def reset(self) -> None:
        """Forget the history (the start of a new record)."""
        self._native.reset()

    @property
    def warmup_samples(self) -> int:
        """Samples after a reset before the derivative window is full."""
        return self._native.warmup_samples

    @property
    def samples(self) -> int:
        """Samples corrected since the start or the last reset."""
        return self._native.samples

    @property
    def temperature_warning(self) -> Optional[str]:
        """The warning about samples outside the calibrated temperature range, if any."""
        return self._native.temperature_warning()


class Diagnosis:
    """What :func:`diagnose` found: ``verdict`` (adequate, explained, unexplained),
    ``proposal`` (effects to add), ``candidates`` and ``steps`` as DataFrames,
    ``channels`` (residual against noise floor per channel), ``warnings``, ``data`` (the
    whole diagnosis as ``crosscal diagnose --json`` prints it) and ``to_html()``, the
    report page with its plots (shown inline in a notebook)."""

    def __init__(self, native: "_crosscal.Diagnosis") -> None:
        self._native = native
        self.data: dict = json.loads(native.json())
        #: "stand" or "protocol".
        self.kind: str = native.kind
        #: With a profile: the runs outside its calibrated temperature range.
        self.temperature_note: Optional[str] = native.temperature_note

    def __repr__(self) -> str:
        return f"<crosscal.Diagnosis {self.verdict}: {', '.join(self.proposal) or 'nothing to add'}>"

    @property
    def verdict(self) -> str:
        """``adequate``, ``explained`` (an effect to add brings the residual to the noise) or
        ``unexplained`` (a systematic residual remains), on stand runs and protocol sessions
        alike, as the command's verdict line. On a protocol session whose pose residuals are
        beyond the noise, a closest catalogued match is ``unexplained``: no evidence."""
        return self._native.verdict

    @property
    def proposal(self) -> list[str]:
        """The effects the diagnosis proposes to add."""
        p = self.data.get("proposal")
        if p is None:
            return []
        return [p] if isinstance(p, str) else list(p)

    @property
    def warnings(self) -> list[str]:
        """Aliases, identifiability and the like."""
        return list(self.data.get("warnings", []))

    @property
    def candidates(self) -> "Any":
        """Every candidate effect with its evidence (ΔBIC, p-value, left-out gain, why rejected)."""
        import pandas as pd

        return pd.json_normalize(self.data.get("candidates", []))

    @property
    def steps(self) -> "Any":
        """The effects added one by one, with the evidence for each."""
        import pandas as pd

        rows = [{"step": i + 1, "effect": s["effect"], "delta_bic": s["score"]["delta_bic"],
                 "p_value": s["score"]["p_value"], "heldout_gain": s["score"]["evidence"]["heldout_gain"],
                 "indistinguishable": ", ".join(s.get("indistinguishable", [])), "why": s["score"]["explanation"]}
                for i, s in enumerate(self.data.get("steps", []))]
        return pd.DataFrame(rows, columns=["step", "effect", "delta_bic", "p_value", "heldout_gain", "indistinguishable", "why"])

    @property
    def channels(self) -> "Any":
        """Residual RMS, noise floor and systematic part per channel (SI)."""
        import pandas as pd

        return pd.json_normalize(self.data.get("channels", []))

    def to_html(self) -> str:
        """The self-contained HTML report (as ``crosscal diagnose --report``)."""
        return self._native.html()

    def _repr_html_(self) -> str:
        return self.to_html() if self.kind == "stand" else f"<pre>{json.dumps(self.data, indent=1)[:4000]}</pre>"


def diagnose(
    session: SessionLike,
    model: str = "default",
    effects: Sequence[str] = (),
    *,
    profile: Optional[Union[Profile, PathLike]] = None,
    trim_rest: bool = False,
    slow_noise: Optional[bool] = None,
) -> Diagnosis:
    """Compare model and measurement (``crosscal diagnose``): where the model fails and
    which physical effect is missing.

    Fits ``model`` (with ``effects``), or holds ``profile``'s coefficients as fitted, and
    tries every catalogue effect on the residual under a noise model estimated from it: an
    effect is proposed only on evidence from runs left out of the fit, with one size in
    every run; otherwise the verdict says the model is adequate or what stays unexplained.
    ``slow_noise=True`` is ``--slow-noise on``: flicker and bias random walk are measured
    and treated as noise, not as a systematic residual; ``False`` is ``--slow-noise off``
    (the AR noise model only); ``None`` (default) is ``auto``: slow noise is taken as noise
    when the session's slow variation wanders like it and hides no effect found without it.
    """
    s = _session(session)
    text = None if profile is None else _profile_json(profile)
    return Diagnosis(_crosscal.diagnose(s._native, model, list(effects), text, trim_rest, slow_noise))


class AllanResult:
    """Noise of a recording at rest: ``curve`` (a DataFrame per point: channel, tau_s,
    adev, low, high, edf), ``terms`` (a DataFrame per channel: white_density,
    bias_instability, random_walk, quantization, ramp, SI units), ``data`` (the report as
    ``crosscal noise --json``) and ``to_json()`` (for :func:`fit`'s ``noise``)."""

    def __init__(self, json_text: str) -> None:
        self._json = json_text
        self.data: dict = json.loads(json_text)

    def __repr__(self) -> str:
        return f"<crosscal.AllanResult {len(self.data['channels'])} channels, {self.data['n_samples']} samples>"

    @property
    def curve(self) -> "Any":
        """The Allan deviation per channel and cluster time, with its 68 % interval."""
        import pandas as pd

        rows = [{"channel": c["channel"], "unit": c["unit"], **p} for c in self.data["channels"] for p in c["points"]]
        return pd.DataFrame(rows)

    @property
    def terms(self) -> "Any":
        """The IEEE 952 noise terms per channel (None where the curve does not show one)."""
        import pandas as pd

        keys = ["white_density", "bias_instability", "bias_instability_tau_s", "random_walk", "quantization", "ramp"]
        rows = [{"channel": c["channel"], "unit": c["unit"], **{k: c.get(k) for k in keys}} for c in self.data["channels"]]
        return pd.DataFrame(rows).set_index("channel")

    def to_json(self) -> str:
        """The report as crosscal writes it (``noise --save``)."""
        return self._json


def noise(
    data: Any,
    rate_hz: float,
    channels: Optional[Sequence[str]] = None,
    *,
    gyro_unit: str = "deg/s",
    accel_unit: str = "g",
    g_m_s2: float = 9.80665,
    max_tau_s: Optional[float] = None,
    deviation: str = "allan",
    source: str = "array",
) -> AllanResult:
    """Allan deviation and noise terms of samples at rest (``crosscal noise``).

    ``data``: an array (n,) or (n, k), or a DataFrame with some of the columns gx … az;
    ``channels`` names the columns of an array (default gx, gy, gz, ax, ay, az for six
    columns, ``["gx"]`` for one). ``rate_hz`` is the sample rate. White-noise density,
    bias instability, rate random walk, quantisation and ramp are read as IEEE 952 does,
    each only where the curve shows it, with 68 % intervals.
    """
    if hasattr(data, "columns"):
        names = [c for c in ("gx", "gy", "gz", "ax", "ay", "az") if c in data.columns]
        arr = data[names].to_numpy(dtype=np.float64)
        channels = names
    else:
        arr = np.asarray(data, dtype=np.float64)
        if arr.ndim == 1:
            arr = arr[:, None]
        if channels is None:
            channels = ["gx", "gy", "gz", "ax", "ay", "az"][: arr.shape[1]] if arr.shape[1] != 1 else ["gx"]
    arr = np.ascontiguousarray(arr)
    return AllanResult(_crosscal.noise(arr, list(channels), float(rate_hz), gyro_unit, accel_unit, g_m_s2,
                                       max_tau_s, deviation, source))


def plan(
    rates_deg_s: Sequence[float] = (10, -10, 20),
    cone_angles_deg: Sequence[float] = (10, 20),
    mounts: int = 3,
    *,
    duration_s: float = 36.0,
    rate_hz: float = 100.0,
    model: str = "default",
    effects: Sequence[str] = (),
    arw_deg_rt_h: float = 0.15,
    vrw_m_s_rt_h: float = 0.02,
    suggest: bool = True,
) -> dict:
    """Predicted uncertainty of every coefficient for proposed conic runs, before recording
    (``crosscal plan``): every mount × cone angle × rate for ``duration_s`` each, the
    noise given as angle and velocity random walk. Returns the plan as a dict
    (``coefficients`` with predicted standard errors, ``unidentifiable`` with remedies,
    ``correlated`` pairs and, with ``suggest``, the extra run that helps most)."""
    return json.loads(_crosscal.plan(list(rates_deg_s), list(cone_angles_deg), mounts, duration_s, rate_hz, model,
                                     list(effects), arw_deg_rt_h, vrw_m_s_rt_h, suggest))


def simulate(preset: str = "paper", **settings: Any) -> Session:
    """A synthetic stand session in memory (``crosscal simulate``): the paper's unit on its
    18-run conic session by default, or ``preset="static"`` at rest.

    Settings (as the command's flags, units in the names): ``gyro_noise_deg_s``,
    ``accel_noise_g``, ``gyro_bias_deg_s`` / ``accel_bias_g`` (x, y, z), ``seed``,
    ``rates_deg_s``, ``cone_angles_deg``, ``mounts``, ``duration_s``, ``rate_hz``,
    ``serial``, ``hidden`` (catalogue effects hidden in the unit) with ``set`` (a dict or
    pairs NAME → true value, SI), ``temperature_c`` (breakpoints), ``arw_deg_rt_h``,
    ``gyro_bias_instability_deg_h``, ``rrw_deg_h_rt_h``, ``vrw_m_s_rt_h``,
    ``accel_bias_instability_ug``, ``accel_random_walk``, ``ar1``, ``quantize``,
    ``jitter_ms``, ``session_clock_s``, ``si_units``, ``disturb``, ``temp_noise_c``,
    ``temp_quantum_c``. ``session.save(dir)``
    writes it as ``crosscal simulate -o dir`` would.
    """
    settings["preset"] = preset
    if isinstance(settings.get("set"), dict):
        settings["set"] = list(settings["set"].items())
    for key in ("rates_deg_s", "cone_angles_deg", "hidden", "temperature_c", "disturb"):
        if key in settings and settings[key] is not None:
            settings[key] = list(settings[key])
    for key in ("gyro_bias_deg_s", "accel_bias_g", "quantize"):
        if key in settings and settings[key] is not None:
            settings[key] = tuple(float(v) for v in settings[key])
    return Session(_crosscal.simulate(settings))


class CheckResult:
    """Corrected outputs against the reference motion: ``passed``, ``summary`` (a DataFrame
    per sensor axis: worst error before and after correction, reduction factor, threshold),
    ``runs`` (a DataFrame per run and axis) and ``data`` (the report as
    ``crosscal check --json``)."""

    def __init__(self, json_text: str) -> None:
        self.data: dict = json.loads(json_text)

    def __repr__(self) -> str:
        return f"<crosscal.CheckResult {'PASS' if self.passed else 'FAIL'}, {len(self.data['runs'])} runs>"

    @property
    def passed(self) -> bool:
        """Every axis passes the paper's criteria."""
        return bool(self.data["pass"])

    @property
    def summary(self) -> "Any":
        """Per sensor axis, over all runs."""
        import pandas as pd

        return pd.json_normalize(self.data["summary"])

    @property
    def runs(self) -> "Any":
        """Per run and axis: amplitude, error statistics before and after."""
        import pandas as pd

        rows = [{"run": r["run"], **a} for r in self.data["runs"] for a in r["axes"]]
        return pd.json_normalize(rows)


def check(profile: Union[Profile, PathLike], session: SessionLike, mode: str = "offline", *,
          allow_other_unit: bool = False) -> CheckResult:
    """Correct every run of ``session`` with ``profile`` and compare with the reference
    motion (``crosscal check``): errors before and after, and the paper's reduction
    factors (gyro 30×, accelerometer 40 000×) as pass criteria. A profile of another unit
    (serials differ) raises :class:`crosscal.errors.WrongUnitError`, as the command exits
    16, unless ``allow_other_unit`` (``--allow-other-unit``)."""
    s = _session(session)
    return CheckResult(_crosscal.check(s._native, _profile_json(profile), mode, allow_other_unit))


def paper_table(profile: Union[Profile, PathLike], session: SessionLike, run: str = "cone+10") -> "Any":
    """The paper's comparison on one run (α = 10°, ω_s = 10 °/s, nominal mount in the
    paper's session), as ``crosscal demo`` prints it: per sensor axis the error before and
    after offline and streaming correction (% of the axis amplitude), the reduction, the
    paper's figures and whether crosscal does at least as well. A DataFrame."""
    import pandas as pd

    s = _session(session)
    return pd.DataFrame(json.loads(_crosscal.paper_table(s._native, _profile_json(profile), run)))


def exit_codes() -> list[tuple[int, str]]:
    """Every exit code of the command line and its meaning (the exception classes' codes)."""
    return list(_crosscal.exit_codes())


__all__ = ["fit", "check", "CheckResult", "paper_table", "correct", "Corrected", "Streaming", "diagnose", "Diagnosis", "noise", "AllanResult", "plan",
           "simulate", "exit_codes"]
