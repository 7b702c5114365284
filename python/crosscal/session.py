"""Sessions: a manifest and its runs, read from disk or built from numpy arrays and pandas
frames.

A session is what a calibration stand records: one unit (its serial), the units of its
columns, local gravity and a list of runs, each with its motion (a conic run, a static
pose, a multi-position protocol…), the unit's mount on the stand and its samples
``t, gx, gy, gz, ax, ay, az[, temp]``. ``crosscal help session`` (or
docs/reference-session.md) describes every field.
"""

from __future__ import annotations

import json
import os
from typing import Any, Iterable, Mapping, Optional, Sequence, Union

import numpy as np

from . import _crosscal
from .errors import NotFoundError, OutOfMemoryError, UsageError


def contiguous_f64(a: Any) -> np.ndarray:
    """``a`` as a C-contiguous float64 array (a view when it is one); numpy's refusal to
    allocate a copy is the package's :class:`~crosscal.errors.OutOfMemoryError`."""
    try:
        return np.ascontiguousarray(a, dtype=np.float64)
    except MemoryError as e:
        raise OutOfMemoryError(f"converting an input to a contiguous float64 array: {e}") from e

COLUMNS = ("t", "gx", "gy", "gz", "ax", "ay", "az")

PathLike = Union[str, "os.PathLike[str]"]


class Session:
    """A session in memory (read with :func:`read_session`, built with
    :meth:`Session.from_arrays` / :meth:`Session.from_dataframe`, or made by
    :func:`crosscal.simulate`).

    Attributes: ``serial``, ``path`` (the manifest's, None when built in memory),
    ``run_names``, ``n_samples``, ``warnings`` (gaps, saturation, spikes found on reading),
    ``manifest`` (the manifest as a dict).
    """

    def __init__(self, native: "_crosscal.Session") -> None:
        self._native = native

    def __repr__(self) -> str:
        where = self.path or "in memory"
        return f"<crosscal.Session unit {self.serial}: {len(self.run_names)} runs, {self.n_samples} samples ({where})>"

    @property
    def serial(self) -> str:
        """The unit's serial number."""
        return self._native.serial

    @property
    def path(self) -> Optional[str]:
        """The manifest's path, or None for a session built in memory."""
        return self._native.path

    @property
    def run_names(self) -> list[str]:
        """Run names in manifest order."""
        return list(self._native.run_names)

    @property
    def n_samples(self) -> int:
        """Samples over all runs."""
        return self._native.n_samples

    @property
    def warnings(self) -> list[str]:
        """What the reader found: gaps in t, saturation, spikes, an autopilot's calibration."""
        return list(self._native.warnings)

    @property
    def manifest(self) -> dict:
        """The manifest as a dict (as ``session.json`` holds it)."""
        return json.loads(self._native.manifest_json())

    def _index(self, run: Union[int, str]) -> int:
        if isinstance(run, str):
            try:
                return self.run_names.index(run)
            except ValueError:
                raise NotFoundError(f"no run '{run}': runs are {', '.join(self.run_names)}") from None
        return int(run)

    def arrays(self, run: Union[int, str]) -> tuple[np.ndarray, np.ndarray, np.ndarray, Optional[np.ndarray]]:
        """One run's samples in the manifest's units: ``(t, gyro (n, 3), accel (n, 3), temp or None)``."""
        return self._native.run_columns(self._index(run))

    def run(self, run: Union[int, str]) -> "Any":
        """One run's samples as a pandas DataFrame (columns t, gx … az[, temp], manifest units)."""
        import pandas as pd

        t, g, a, temp = self.arrays(run)
        frame = {"t": t, "gx": g[:, 0], "gy": g[:, 1], "gz": g[:, 2], "ax": a[:, 0], "ay": a[:, 1], "az": a[:, 2]}
        if temp is not None:
            frame["temp"] = temp
        return pd.DataFrame(frame)

    def save(self, folder: PathLike) -> str:
        """Writes the session (``session.json`` and one CSV per run) into ``folder``, which
        must not already hold one (crosscal never overwrites); returns the manifest's path."""
        return self._native.save(os.fspath(folder))

    @classmethod
    def from_arrays(
        cls,
        serial: str,
        runs: Sequence[Mapping[str, Any]],
        *,
        gyro_unit: str = "deg/s",
        accel_unit: str = "g",
        time_unit: str = "s",
        g_m_s2: float = 9.80665,
    ) -> "Session":
        """A session from arrays in memory.

        ``runs`` lists one mapping per run: ``name``, ``motion`` (as in a manifest, e.g.
        ``{"kind": "conic", "cone_angle_deg": 10, "rate_deg_s": 10, "phase_deg": 0}`` or
        ``{"kind": "static", "up_stand": [0, 0, 1]}``), optionally ``mount`` (e.g.
        ``["+y", "+z", "+x"]``), ``temperature_c``, ``start_s``, ``note``, and the samples,
        either ``t`` (n,), ``gyro`` (n, 3), ``accel`` (n, 3) and optionally ``temp`` (n,)
        arrays, or ``data``: a DataFrame with columns t, gx, gy, gz, ax, ay, az[, temp].
        Units are the session's (``gyro_unit`` deg/s, rad/s or raw; ``accel_unit`` g,
        m/s^2 or raw; ``time_unit`` s or ms). The samples are checked and converted exactly
        as the CSV reader checks and converts a file (a NaN, a t that does not increase:
        :class:`crosscal.errors.BadValueError`, :class:`crosscal.errors.TimeOrderError`,
        naming the run, row and column), so fitting the session gives the numbers
        ``crosscal fit`` gives on the same samples written to CSV.
        """
        entries = []
        columns = []
        for i, r in enumerate(runs):
            name = str(r.get("name", f"run{i + 1}"))
            if "motion" not in r:
                raise UsageError(f"run '{name}': no motion (e.g. {{'kind': 'conic', 'cone_angle_deg': 10, 'rate_deg_s': 10}})")
            entry: dict[str, Any] = {"name": name, "file": f"{name}.csv", "motion": dict(r["motion"])}
            for key in ("mount", "temperature_c", "start_s", "note"):
                if key in r and r[key] is not None:
                    entry[key] = r[key]
            entries.append(entry)
            if "data" in r:
                df = r["data"]
                missing = [c for c in COLUMNS if c not in df.columns]
                if missing:
                    raise UsageError(f"run '{name}': the DataFrame lacks column(s) {', '.join(missing)}")
                t = df["t"].to_numpy(dtype=np.float64)
                gyro = df[["gx", "gy", "gz"]].to_numpy(dtype=np.float64)
                accel = df[["ax", "ay", "az"]].to_numpy(dtype=np.float64)
                temp = df["temp"].to_numpy(dtype=np.float64) if "temp" in df.columns else None
            else:
                t, gyro, accel, temp = r["t"], r["gyro"], r["accel"], r.get("temp")
            columns.append(
                (
                    contiguous_f64(t),
                    contiguous_f64(gyro),
                    contiguous_f64(accel),
                    None if temp is None else contiguous_f64(temp),
                )
            )
        manifest = {
            "format": "crosscal-session/1",
            "serial": serial,
            "units": {"gyro": gyro_unit, "accel": accel_unit, "time": time_unit},
            "stand": {"g": g_m_s2},
            "runs": entries,
        }
        return cls(_crosscal.session_from_columns(json.dumps(manifest), columns))

    @classmethod
    def from_dataframe(
        cls,
        serial: str,
        runs: Iterable[tuple[str, Mapping[str, Any], Any]],
        **units: Any,
    ) -> "Session":
        """A session from pandas DataFrames: ``runs`` yields ``(name, motion, frame)``
        (frame columns t, gx, gy, gz, ax, ay, az[, temp]); keywords as
        :meth:`from_arrays` (``gyro_unit``, ``accel_unit``, ``time_unit``, ``g_m_s2``)."""
        return cls.from_arrays(serial, [{"name": n, "motion": m, "data": f} for n, m, f in runs], **units)


def read_session(path: PathLike, strict: bool = False) -> Session:
    """Reads a session manifest (``session.json``) and all its recordings.

    Recordings are read as the command line reads them: a bad value raises the exception of
    its exit code with ``file:line:column`` in the message; gaps in t are warnings
    (``Session.warnings``), or errors with ``strict=True``.
    """
    return Session(_crosscal.read_session(os.fspath(path), strict))
