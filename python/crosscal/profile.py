"""Calibration profiles: one unit's fitted coefficients, their uncertainties and everything
needed to correct its outputs, as the versioned JSON crosscal stores in
``calib-profiles/<serial>/<UTC time>.json`` (``crosscal help profile-format``).
"""

from __future__ import annotations

import json
import os
from typing import Any, Optional, Union

import numpy as np

from . import _crosscal
from .errors import NotFoundError

PathLike = Union[str, "os.PathLike[str]"]


class Profile:
    """A unit's calibration profile.

    ``coefficients`` is a DataFrame (name, value, std_error, unit, status, effect,
    sensor); ``covariance`` the covariance of the fitted coefficients (a DataFrame indexed
    by name both ways; coefficients of different output channels are fitted separately, so
    the matrix is block-diagonal by channel); ``to_json()`` the text crosscal writes,
    ``from_json()`` / ``load()`` read one, ``save(store)`` adds it to a profile store
    without overwriting anything. ``data`` is the whole profile as a dict.
    """

    def __init__(self, json_text: str, *, samples: Optional[int] = None, streamed: Optional[bool] = None,
                 warnings: Optional[list[str]] = None, validation: Optional[dict] = None,
                 path: Optional[str] = None) -> None:
        self._json = json_text
        self.data: dict = json.loads(json_text)
        #: Samples the fit used (None for a profile read from JSON).
        self.samples = samples
        #: Whether the fit streamed the recordings from disk.
        self.streamed = streamed
        #: The fit's findings in the recordings.
        self.warnings: list[str] = list(warnings or [])
        #: The check of held-out runs, when some were held out.
        self.validation = validation
        #: The file the profile was read from or saved to.
        self.path = path

    def __repr__(self) -> str:
        return f"<crosscal.Profile unit {self.serial}, model '{self.model}', {len(self.data.get('runs', []))} runs>"

    @property
    def serial(self) -> str:
        """The unit's serial number."""
        return self.data["serial"]

    @property
    def model(self) -> str:
        """The model's name (preset and effects)."""
        return self.data["model"]

    @property
    def effects(self) -> list[str]:
        """The catalogue effects in the model."""
        return list(self.data.get("effects", []))

    @property
    def temperature_range_c(self) -> Optional[tuple[float, float]]:
        """The temperature range the profile was calibrated over, °C (None: no temperatures)."""
        ranges = [r["temp_range_c"] for r in self.data.get("runs", []) if r.get("temp_range_c")]
        if not ranges:
            return None
        return (min(r[0] for r in ranges), max(r[1] for r in ranges))

    @property
    def coefficients(self) -> "Any":
        """Every coefficient: a DataFrame with name, value, std_error, unit, status
        (fitted, fixed, unidentifiable …), effect and sensor; SI units."""
        import pandas as pd

        rows = []
        for sensor in ("gyro", "accel"):
            for c in self.data[sensor]["coefficients"]:
                rows.append({
                    "name": c["name"], "value": c["value"], "std_error": c.get("std_error"),
                    "unit": c.get("unit", ""), "status": c.get("status", ""), "effect": c.get("effect", ""),
                    "sensor": sensor,
                })
        return pd.DataFrame(rows, columns=["name", "value", "std_error", "unit", "status", "effect", "sensor"])

    @property
    def covariance(self) -> "Any":
        """Covariance of the fitted coefficients, a DataFrame indexed by name (block-diagonal
        by output channel: each channel is its own least-squares problem)."""
        import pandas as pd

        names: list[str] = []
        blocks: list[np.ndarray] = []
        for sensor in ("gyro", "accel"):
            for ch in self.data[sensor].get("channels", []):
                names.extend(ch.get("covariance_names", []))
                blocks.append(np.asarray(ch.get("covariance", []), dtype=float).reshape(len(ch.get("covariance_names", [])), -1))
        m = np.zeros((len(names), len(names)))
        k = 0
        for b in blocks:
            n = b.shape[0]
            m[k:k + n, k:k + n] = b
            k += n
        return pd.DataFrame(m, index=names, columns=names)

    def value(self, name: str) -> float:
        """One coefficient's value (SI), e.g. ``profile.value("gyro.c_xy")``."""
        for sensor in ("gyro", "accel"):
            for c in self.data[sensor]["coefficients"]:
                if c["name"] == name:
                    return float(c["value"])
        raise NotFoundError(f"no coefficient '{name}' in the profile")

    def to_json(self) -> str:
        """The profile as crosscal writes it."""
        return self._json

    @classmethod
    def from_json(cls, text: str) -> "Profile":
        """A profile from JSON text, checked as a profile file is (an unknown format version
        raises :class:`crosscal.errors.ProfileFormatError`, a missing or non-finite
        coefficient :class:`crosscal.errors.ProfileError`)."""
        return cls(_crosscal.profile_normalise(text, "<profile>"))

    @classmethod
    def load(cls, path: PathLike) -> "Profile":
        """Reads a profile file, or a unit's folder of a store (then its newest profile)."""
        used, text = _crosscal.profile_read(os.fspath(path))
        return cls(text, path=used)

    def save(self, store: PathLike = "calib-profiles") -> str:
        """Adds the profile to the store at ``store`` as ``<serial>/<UTC time>.json``,
        written atomically and never over an existing file; returns its path."""
        self.path = _crosscal.profile_save(self._json, os.fspath(store))
        return self.path
