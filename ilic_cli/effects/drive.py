"""The built-in effects of the drive and the sensors: delay, flexibility, saturation, quantization, noise, disturbance, current loop.

None is linear in its parameters: delay, flexibility and the current loop are blocks with their own state in the plant
(:mod:`plant.blocks`), the others act on the command or the measurement.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from ilic_cli.effects.definition import Effect, Estimate, EstimateResult, Fit, PlantParam, Scan, col, unit_on
from ilic_cli.effects.grids import FLEX_DAMPING, delay_grid, flexible_acceleration, resonance_at_log_rate, resonance_grid
from ilic_cli.errors import ParameterError
from ilic_cli.regressor import Kinematics


def _delay_estimate(fit: Fit) -> EstimateResult:
    # the diagnosis baseline already holds the logged command (the regressor half a sample later): the delay found is beyond the hold
    d = float(fit.value)
    note = ""
    if fit.hold_s:
        note = f"the logged force is the held command: the delay is measured beyond its {fit.hold_s * 1e3:.3g} ms zero-order hold"
    if d < 0:
        note += ("; " if note else "") + "negative: the force acts after it is logged (drive lag)"
        if "current_loop" in _delay_realise({"delay": d}, fit.hold_s):
            note += (
                f", shorter than a sample: the drive's current loop, which the model file and the replays realise as a "
                f"first-order lag of {1.0 / (2.0 * math.pi * -d):.3g} Hz"
            )
    return {"delay": Estimate(float(fit.value), fit.value_std, "s")}, {"delay": d}, note


def _delay_realise(plant: Mapping[str, float], hold_s: float) -> dict[str, dict[str, float]]:
    """A drive lag shorter than a sample as the drive's current loop (the first-order lag of that time constant), else a delay.

    A lag within the sample is the current loop's (0.23 ms at 700 Hz): a pure
    delay of that size has the same low-frequency lag but not the loop's
    response to a step of the command, which the stick and break-away at a
    trapezoid's dwells show (measured: with a pure 0.24 ms delay in the replay,
    Stribeck friction at the dwells was kept on both clean current-loop
    trapezoids; with the first-order loop, on neither). ``hold_s`` is half the
    sample period (0: the logged force is no held command, and the sample does
    not bound the lag).
    """
    lag = -float(plant["delay"])
    if hold_s > 0.0 and 0.0 < lag < 2.0 * hold_s:
        return {"current_loop": {"bandwidth_hz": 1.0 / (2.0 * math.pi * lag)}}
    return {"delay": {"delay": float(plant["delay"])}}


def _flex_estimate(fit: Fit) -> EstimateResult:
    v = fit.value
    scalar = bool(np.isscalar(v))  # a bool: np.isscalar's TypeGuard would narrow v to types float() does not take
    f_res, zeta = (float(v), FLEX_DAMPING) if scalar else (float(v[0]), float(v[1]))
    ml = fit.combination({"M_load": 1.0})
    M = fit.get("M", float("nan"))
    w = 2.0 * math.pi * f_res
    frac = ml[0] / M if M > 0 else float("nan")
    k = w * w * ml[0]
    k_std = None
    if fit.value_std is not None and ml[0] > 0:
        k_std = k * math.sqrt((2 * fit.value_std / f_res) ** 2 + (ml[1] / ml[0]) ** 2)
    c = 2.0 * zeta * math.sqrt(max(k * ml[0], 0.0))
    est = {
        "f_res": Estimate(f_res, fit.value_std, "Hz"),
        "damping_ratio": Estimate(zeta, None, ""),
        "M_load": Estimate(*ml, "kg"),
        "load_fraction": Estimate(frac, ml[1] / M if M > 0 else None, ""),
        "stiffness": Estimate(k, k_std, "N/m"),
        "damping": Estimate(c, None, "N·s/m"),
    }
    plant = {"stiffness": k, "damping": c, "load_fraction": frac} if 0 < frac < 1 else None
    return est, plant, "" if plant else "the load fraction is outside (0, 1): not a plant flexibility"


def _flex_scan_value(values: Mapping[str, float], M: float) -> tuple[float, float]:
    ml = values["load_fraction"] * M
    k = values["stiffness"]
    return math.sqrt(k / ml) / (2 * math.pi), values["damping"] / (2.0 * math.sqrt(k * ml))


def _flex_build(kin: Kinematics, value: Any, fs_hz: float) -> np.ndarray:
    scalar = bool(np.isscalar(value))  # a bool: np.isscalar's TypeGuard would narrow value to types float() does not take
    f_hz, zeta = (value, FLEX_DAMPING) if scalar else value
    return np.c_[flexible_acceleration(kin.qdd, float(f_hz), fs_hz, float(zeta)) - kin.qdd]


def _delay_check(v: Mapping[str, float]) -> None:
    if abs(v["delay"]) > MAX_DELAY_S:
        raise ParameterError("delay.delay", v["delay"], f"within +-{MAX_DELAY_S:g} s")


MAX_DELAY_S = 1.0
"""Largest delay (s) either way."""
DELAY = Effect(
    "delay",
    "actuation delay",
    "The logged force and the force acting on the axis are not simultaneous: the measurement lags (d > 0) or the drive lags the command (d < 0).",
    params=(PlantParam("delay", "s", 0.002, "logged force = applied force this much earlier; negative: the drive lags the command"),),
    check=_delay_check,
    form="IDM(t) = tau_logged(t + d): the logged force is shifted by the delay d, searched",
    signature="residual proportional to the rate of change of the force; cross-correlation of force and model peaks at a non-zero lag",
    signature_kinds=("lag", "acceleration"),
    scan=Scan("delay", "s", delay_grid, log=False),
    shift=True,
    estimate=_delay_estimate,
    realise=_delay_realise,
    sentence=lambda p: f"{p['delay'].value * 1e3:+.3g} ms",
)


def _flex_check(v: Mapping[str, float]) -> None:
    if not 0.0 < v["load_fraction"] < 1.0:
        raise ParameterError("flexibility.load_fraction", v["load_fraction"], "in (0, 1)")


FLEXIBILITY = Effect(
    "flexibility",
    "transmission flexibility",
    "The carriage is coupled to the motor through a compliant screw and belt, so part of the mass lags the measured motion near a resonance.",
    params=(
        PlantParam("stiffness", "N/m", 2.0e6, "coupling stiffness", low=0.0, low_open=True),
        PlantParam("damping", "N·s/m", 500.0, "coupling damping", low=0.0),
        PlantParam("load_fraction", "", 0.3, "share of M behind the coupling"),
    ),
    check=_flex_check,
    form="M_load * (H(s) - 1) qdd with H the load's spring-damper response: resonance frequency f_res searched, then its damping ratio",
    signature="residual proportional to acceleration at high frequency: oscillations after acceleration steps and pulses; a spectral peak",
    signature_kinds=("frequency", "acceleration"),
    columns=(col("M_load", "mass behind the flexibility", "kg"),),
    build=_flex_build,
    noisy_columns=True,
    scan=Scan("f_res", "Hz", resonance_grid, secondary=("damping_ratio", "", 0.005, 0.5, FLEX_DAMPING), at_log_rate=resonance_at_log_rate),
    impossible=lambda th, v, joint: None if th[0] > 0 else f"negative mass behind the flexibility ({th[0]:.3g} {unit_on('kg', joint)})",
    estimate=_flex_estimate,
    scan_value=_flex_scan_value,
    sentence=lambda p: f"resonance {p['f_res'].value:.3g} Hz, {p['M_load'].value:.3g} {p['M_load'].unit} behind the spring",
)

SATURATION = Effect(
    "saturation",
    "drive saturation",
    "The drive cannot apply more than its peak force: the applied force is clipped.",
    params=(PlantParam("force_max", "N", 350.0, "largest force the drive applies", low=0.0, low_open=True),),
)

QUANTIZATION = Effect(
    "quantization",
    "encoder quantization",
    "The encoder measures the position in whole counts (EMPS: about 2e-7 m per count).",
    params=(PlantParam("resolution", "m", 2.0e-7, "one count", low=0.0, low_open=True),),
)

NOISE = Effect(
    "noise",
    "measurement noise",
    "Gaussian noise on the logged force and on the measured position (seeded, drawn up front).",
    params=(PlantParam("tau_std", "N", 0.0, "force noise std", low=0.0), PlantParam("q_std", "m", 0.0, "position noise std", low=0.0)),
)

DISTURBANCE = Effect(
    "disturbance",
    "band-limited force disturbance",
    "An unmodelled force acts on the axis (cable drag, vibration of the frame): white noise through a low-pass filter, seeded, not in the logged force.",
    params=(
        PlantParam("std", "N", 2.0, "standard deviation of the force", low=0.0),
        PlantParam("bandwidth_hz", "Hz", 20.0, "corner (-3 dB) frequency of its second-order Butterworth low-pass", low=0.0, low_open=True),
    ),
)

CURRENT_LOOP = Effect(
    "current_loop",
    "current-loop lag",
    "The drive's current loop makes the applied force follow the command as a first-order lag of time constant 1/(2 pi f), "
    "f its bandwidth (about 700 Hz: 0.23 ms); an inverse model sees it as a drive lag of that size.",
    params=(PlantParam("bandwidth_hz", "Hz", 700.0, "closed-loop bandwidth f of the current loop", low=0.0, low_open=True),),
)
