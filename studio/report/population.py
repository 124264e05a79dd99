"""ANSUR II population context of a measurement: percentile and z-score by sex.

The shipped summary (:data:`PERCENTILES_FILE`) holds, per sex and per measurement of
:data:`studio.body.iso7250.DEFINITIONS` that ANSUR II measures the same way (its ``ansur``
column), n, mean, standard deviation and the 1st…99th percentiles (SI units); BMI is computed
per soldier from ``weightkg`` and ``stature``. :func:`summarise_percentiles` rebuilds it from the
public CSVs (``ANSUR_II_FEMALE_Public.csv``, ``ANSUR_II_MALE_Public.csv``).
"""

from __future__ import annotations

import json
from functools import lru_cache
from pathlib import Path

import numpy as np

__all__ = ["PERCENTILES_FILE", "percentile_table", "population_context", "summarise_percentiles"]

PERCENTILES_FILE = Path(__file__).resolve().parent / "data" / "ansur2_percentiles.json"
_LEVELS = np.arange(1, 100)


def _columns() -> dict[str, tuple[str, float]]:
    """{measurement: (ANSUR column, factor to SI)}: millimetres, weight in tenths of kg."""
    from studio.body.iso7250 import DEFINITIONS

    out = {}
    for d in DEFINITIONS:
        if d.ansur and d.ansur != "bmi":
            out[d.name] = (d.ansur, 0.1 if d.ansur == "weightkg" else 1e-3)
    return out


def summarise_percentiles(folder: str | Path) -> dict:
    """The summary (module doc) from ANSUR II's public CSVs in ``folder``."""
    from studio.fit.quality import ANSUR_SOURCE, read_ansur

    out = {"format": "studio.population-percentiles", "version": 1, "levels": _LEVELS.tolist(),
           "source": ANSUR_SOURCE, "sexes": {}}
    for sex, cols in read_ansur(folder, _columns()).items():
        cols["bmi"] = cols["mass"] / cols["stature"] ** 2
        out["sexes"][sex] = {
            name: {"n": int(len(v)), "mean": round(float(v.mean()), 6), "std": round(float(v.std(ddof=1)), 6),
                   "percentiles": [round(float(q), 6) for q in np.percentile(v, _LEVELS)]}
            for name, v in cols.items()
        }
    return out


@lru_cache(maxsize=1)
def percentile_table() -> dict:
    """The shipped summary (:data:`PERCENTILES_FILE`)."""
    return json.loads(PERCENTILES_FILE.read_text())


def population_context(name: str, value: float, sex: str) -> dict | None:
    """``{"sex", "percentile", "z", "text"}`` of ``value`` (SI) for measurement ``name`` against
    ANSUR II of ``sex`` (``male``/``female``; anything else: the sex giving the smaller |z|),
    or None when ANSUR II has no comparable measurement. ``percentile`` is interpolated in
    the 1st–99th percentiles (clamped to 0.5 / 99.5 outside them: ``text`` says "< 1st" /
    "> 99th")."""
    sexes = percentile_table()["sexes"]
    use = [sex] if sex in sexes else list(sexes)
    best = None
    for s in use:
        st = sexes[s].get(name)
        if st is None or value is None or not np.isfinite(value):
            return None
        z = (value - st["mean"]) / st["std"]
        if best is None or abs(z) < abs(best[1]):
            best = (s, z, st)
    s, z, st = best
    q = np.asarray(st["percentiles"])
    if value < q[0]:
        pct, text = 0.5, "< 1st"
    elif value > q[-1]:
        pct, text = 99.5, "> 99th"
    else:
        pct = float(np.interp(value, q, _LEVELS))
        text = f"{pct:.0f}th"
    return {"sex": s, "percentile": round(pct, 1), "z": round(float(z), 2), "text": text}
