"""Bitcraze's (cfclient / Crazyflie firmware) Lighthouse conventions <-> ours, in one place.

Factory calibration (LH1): a cfclient system configuration stores per station
``calibs.<bs>.sweeps[axis]`` with ``phase, tilt, curve, gibphase, gibmag, ogeephase,
ogeemag`` (rad): the station's OOTX values as broadcast. In our model's terms
(:mod:`lhgraph.model.lh1`, default :class:`~lhgraph.model.factory.Convention`) they are

    phase  = phase_bc            tilt   = tilt_bc             curve = curve_bc
    gibmag = gibmag_bc           gibphase = gibphase_bc + pi + phase_bc

(the firmware's gib term is a function of the angle before the phase is taken off, ours of
the angle after). The deck firmware applies the curve with the opposite sign
(:func:`firmware_equivalent` gives its model, which reproduces its ``correctedAngle`` to a
few µrad median on the real LH1 log); the broadcast sign, in our convention, fits the
Bitcraze logs' own Qualisys paths and hive's OptiTrack better (docs/model.md,
docs/results/lh1_curve_sign.md). The ogee terms are LH2 only and must be zero here.

Factory calibration (LH2): our terms *are* Bitcraze's (:mod:`lhgraph.model.lh2` states the
model in them); the deck firmware's correction of the real LH2 log is reproduced to 0.2
µrad with its own stopping rule (docs/model.md). All seven terms are kept.

Station geometry: ``geos.<bs>`` has ``origin`` (m) and ``rotation`` (3x3, station frame to
world), with the station frame +x forward, +y left, +z up: the same as ours (SPEC §4), so
``T_world_lh = [rotation | origin]``; verified on the log by turning ``correctedAngle`` into
crossing-beam positions and comparing them with the firmware's own ``lhCrossingBeam`` fixes.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lhgraph.errors import InputError
from lhgraph.geometry.transforms import make_pose, nearest_rotation
from lhgraph.model.station import FactoryCalibration

Array = NDArray[np.float64]

BITCRAZE_KEYS = ("phase", "tilt", "curve", "gibphase", "gibmag", "ogeephase", "ogeemag")


def _wrap(angle: Array) -> Array:
    return np.mod(np.asarray(angle, dtype=float) + np.pi, 2.0 * np.pi) - np.pi


def calibration_from_bitcraze(sweeps: Sequence[Mapping[str, float]],
                              source: str | None = None) -> FactoryCalibration:
    """Our :class:`FactoryCalibration` from Bitcraze's two LH1 sweep dictionaries
    (``[axis0, axis1]``, keys :data:`BITCRAZE_KEYS`; rad; the curve as broadcast).
    InputError naming ``source`` if a key is missing or an ogee term is non-zero (LH2
    calibration)."""
    if len(sweeps) != 2:
        raise InputError(f"expected 2 sweeps, got {len(sweeps)}", source)
    values = {}
    for key in BITCRAZE_KEYS:
        try:
            values[key] = np.array([float(s.get(key, 0.0)) for s in sweeps])
        except (TypeError, ValueError, AttributeError):
            raise InputError(f"sweep value '{key}' is not a number", source) from None
    for key in ("phase", "tilt", "curve", "gibphase", "gibmag"):
        if any(key not in s for s in sweeps):
            raise InputError(f"sweep without '{key}'", source)
    if np.any(values["ogeephase"]) or np.any(values["ogeemag"]):
        raise InputError("ogee terms are set: that is an LH2 calibration", source)
    return FactoryCalibration(
        phase=values["phase"], tilt=values["tilt"], curve=values["curve"],
        gibphase=_wrap(values["gibphase"] + np.pi + values["phase"]),
        gibmag=values["gibmag"])


def firmware_equivalent(calibration: FactoryCalibration) -> FactoryCalibration:
    """The LH1 ``calibration`` (our terms, the broadcast curve) as the deck firmware applies
    it: the curve negated. Its correction reproduces the firmware's ``correctedAngle``."""
    return replace(calibration, curve=-np.asarray(calibration.curve))


def calibration_to_bitcraze(calibration: FactoryCalibration) -> list[dict[str, float]]:
    """Bitcraze's two sweep dictionaries (keys :data:`BITCRAZE_KEYS`, rad) of our LH1
    calibration: the inverse of :func:`calibration_from_bitcraze` (the broadcast values)."""
    c = calibration
    gibphase = _wrap(c.gibphase - np.pi - c.phase)
    return [{"phase": float(c.phase[k]), "tilt": float(c.tilt[k]),
             "curve": float(c.curve[k]), "gibphase": float(gibphase[k]),
             "gibmag": float(c.gibmag[k]), "ogeephase": 0.0, "ogeemag": 0.0}
            for k in (0, 1)]


def lh2_calibration_from_bitcraze(sweeps: Sequence[Mapping[str, float]],
                                  source: str | None = None) -> FactoryCalibration:
    """Our LH2 :class:`FactoryCalibration` from Bitcraze's two sweep (light plane)
    dictionaries: the same terms (InputError naming ``source`` if one is missing)."""
    if len(sweeps) != 2:
        raise InputError(f"expected 2 sweeps, got {len(sweeps)}", source)
    try:
        return FactoryCalibration(**{key: [float(s[key]) for s in sweeps]
                                     for key in BITCRAZE_KEYS})
    except KeyError as missing:
        raise InputError(f"sweep without {missing}", source) from None
    except (TypeError, ValueError):
        raise InputError("a sweep value is not a number", source) from None


def lh2_calibration_to_bitcraze(calibration: FactoryCalibration) -> list[dict[str, float]]:
    """Bitcraze's two sweep dictionaries of our LH2 calibration (the same terms)."""
    return [{key: float(getattr(calibration, key)[k]) for key in BITCRAZE_KEYS}
            for k in (0, 1)]


def pose_from_bitcraze(origin: ArrayLike, rotation: ArrayLike) -> Array:
    """``T_world_lh`` (4x4) of a cfclient geometry: ``origin`` (m), ``rotation`` (station
    frame to world, made orthonormal: cfclient stores float32); the frames agree with ours,
    see the module docstring."""
    return make_pose(nearest_rotation(rotation), np.asarray(origin, dtype=float).reshape(3))


def pose_to_bitcraze(T_world_lh: ArrayLike) -> tuple[list[float], list[list[float]]]:
    """``(origin, rotation)`` of a cfclient geometry from ``T_world_lh``: the inverse of
    :func:`pose_from_bitcraze`."""
    T = np.asarray(T_world_lh, dtype=float)
    return [float(x) for x in T[:3, 3]], [[float(x) for x in row] for row in T[:3, :3]]
