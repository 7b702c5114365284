"""crosscal: cross-coupling calibration of three-axis gyroscopes and accelerometers.

The library behind the ``crosscal`` command, from Python, with numpy arrays and pandas
frames. crosscal fits each unit's cross-coupling — the gyro matrix C_ω with its
angular-acceleration terms C_ε, the accelerometer matrix K, biases and any catalogue effect
the unit needs — from a stand moving it in a known conic motion (after Szelmanowski &
Jakielaszek) or from hand-held and rate-table protocols; stores a versioned profile per
unit; corrects outputs offline or in streaming; and tells you which physical effect a model
is missing.

>>> import crosscal
>>> session = crosscal.simulate(gyro_noise_deg_s=0.002, accel_noise_g=2e-5)
>>> profile = crosscal.fit(session)                  # C_ω, C_ε, K, biases ± σ
>>> profile.coefficients                              # a DataFrame
>>> t, g, a, _ = session.arrays("cone+10")
>>> gyro, accel = crosscal.correct(profile, t, g, a)  # C⁻¹, K⁻¹ applied
>>> crosscal.diagnose(session).verdict               # what is the model missing?

Errors are :mod:`crosscal.errors` exceptions, one class per exit code of the command.
"""

from . import errors
from ._crosscal import version as _version
from .analysis import (
    AllanResult,
    CheckResult,
    Corrected,
    Diagnosis,
    Streaming,
    check,
    correct,
    diagnose,
    exit_codes,
    fit,
    load_effects,
    noise,
    paper_table,
    plan,
    simulate,
)
from .errors import CrosscalError
from .lot import capability, cpk, datasheet
from .profile import Profile
from .session import Session, read_session

__version__ = _version()

__all__ = [
    "AllanResult", "CheckResult", "Corrected", "CrosscalError", "Diagnosis", "Profile", "Session", "Streaming", "capability",
    "check", "correct", "cpk", "datasheet",
    "diagnose", "errors", "exit_codes", "fit", "load_effects", "noise", "paper_table", "plan", "read_session", "simulate",
]
