"""Datasheets and lot capability: a unit's datasheet quantities as a DataFrame
(``crosscal datasheet``), a batch's capability per datasheet rule as another
(``batch-report.json``'s ``capability``), and Cpk of any values."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Optional, Sequence

from . import _crosscal
from .session import PathLike

_COLUMNS = ["name", "sensor", "axis", "value", "uncertainty", "unit", "count", "interval90", "sources",
            "definition", "reference", "not_measured"]


def datasheet(
    unit: str,
    store: PathLike = "calib-profiles",
    *,
    at: Optional[str] = None,
    gyro_range_deg_s: Optional[float] = None,
    accel_range_g: Optional[float] = None,
) -> "Any":
    """A unit's datasheet (``crosscal datasheet UNIT --store STORE --json``) as a DataFrame:
    one row per quantity and axis — ``name`` (as the ``datasheet`` rule kind names it),
    ``axis``, ``value`` and ``uncertainty`` (standard, k = 1) in the datasheet ``unit``,
    ``count`` and ``interval90`` (repeatability), ``sources``, ``definition`` — then one row
    per quantity not measured (``value`` NaN, ``not_measured`` says what would measure it).
    The frame's ``attrs`` hold the unit, the profile and the number of calibrations.

    ``at`` picks the profile in force at a time (RFC 3339 or a date); ``gyro_range_deg_s``
    and ``accel_range_g`` are the calibrated ranges nonlinearity is quoted against.
    """
    import pandas as pd

    d = json.loads(_crosscal.datasheet(str(store), unit, at, gyro_range_deg_s, accel_range_g))
    rows = [{k: q.get(k) for k in _COLUMNS} for q in d["quantities"]]
    frame = pd.DataFrame(rows, columns=_COLUMNS)
    frame["value"] = frame["value"].astype(float)
    frame["uncertainty"] = frame["uncertainty"].astype(float)
    frame.attrs.update({"unit": d["unit"], "profile": d["profile"], "calibrations": d["calibrations"]})
    return frame


def capability(report: PathLike) -> "Any":
    """A batch's lot capability (``batch-report.json``, or the folder holding it) as a
    DataFrame: one row per datasheet rule and axis with ``rule``, ``quantity``, ``axis``,
    ``unit``, ``n``, ``mean``, ``std``, the limits ``lsl``/``usl``, ``cpk`` with its 95 %
    interval ``cpk_low``/``cpk_high``, and the counts ``pass``, ``fail``, ``indeterminate``.
    The control chart across the store's lots is in ``attrs["control"]``."""
    import pandas as pd

    path = Path(report)
    if path.is_dir():
        path = path / "batch-report.json"
    data = json.loads(path.read_text(encoding="utf-8"))
    cols = ["rule", "quantity", "axis", "unit", "n", "mean", "std", "lsl", "usl", "cpk", "cpk_low", "cpk_high",
            "pass", "fail", "indeterminate"]
    frame = pd.DataFrame([{k: c.get(k) for k in cols} for c in data.get("capability", [])], columns=cols)
    frame.attrs["control"] = data.get("control", [])
    return frame


def cpk(values: Sequence[float], lsl: Optional[float] = None, usl: Optional[float] = None) -> dict:
    """Mean, standard deviation, Cpk and its 95 % confidence interval (Bissell 1990) of
    ``values`` against the specification limits, as the batch computes them."""
    mean, std, c, lo, hi = _crosscal.cpk([float(v) for v in values], lsl, usl)
    return {"mean": mean, "std": std, "cpk": c, "cpk_low": lo, "cpk_high": hi}
