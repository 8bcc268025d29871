"""The one run-log model: time-indexed samples of one axis plus metadata.

A :class:`RunLog` holds equally long float64 arrays (channels) keyed by name,
their units, and a JSON-serialisable metadata dictionary. Every reader returns
one and every writer takes one, so simulation, identification and diagnosis
share one shape of data.

Channels
--------
``t`` (s), ``q`` measured position (m or rad), ``tau`` joint force/torque
(N or N·m) are required. ``q_ref``, ``qd_ref``, ``qdd_ref`` (reference position,
velocity, acceleration), ``qd`` (measured velocity), ``vir`` (drive command, V)
and ``pulses`` are optional, and any other named channel may be added.

Metadata keys (all optional)
----------------------------
``sample_rate_hz`` nominal rate; ``drive_gain`` force per volt (N/V);
``controller`` dict with ``kind`` (``"pd"``, ``"ctc"``) and its gains;
``true_parameters`` dict when simulated; ``scenario`` and ``simulation``
dicts written by ``ilic simulate``; ``source`` the file it was read from;
``joint`` the joint name; ``vertical`` (or ``orientation: vertical``) a vertical axis.

The library reads the metadata through three typed views, never by key: :attr:`RunLog.controller`
(:class:`Controller`: the loop that ran and its drive gain), :attr:`RunLog.sensor` (:class:`Sensor`: the
joint, its type and units, the declared rate) and :attr:`RunLog.provenance` (:class:`Provenance`: where
the samples come from). The dictionary stays the serialised form the readers fill and the writers store.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ilic_cli.errors import LogError
from ilic_cli.timebase import nominal_rate_hz

if TYPE_CHECKING:
    import pandas as pd

REQUIRED: tuple[str, ...] = ("t", "q", "tau")
"""Channels every log must have."""

DEFAULT_UNITS: dict[str, str] = {
    "t": "s",
    "q": "m",
    "qd": "m/s",
    "q_ref": "m",
    "qd_ref": "m/s",
    "qdd_ref": "m/s^2",
    "tau": "N",
    "vir": "V",
    "pulses": "1",
}
"""Units assumed for the standard channels when a file does not say."""

CANONICAL_ORDER: tuple[str, ...] = ("t", "q", "qd", "q_ref", "qd_ref", "qdd_ref", "tau", "vir", "pulses")

ROTARY_UNITS = frozenset({"rad", "radian", "radians"})
"""Position units of a revolute joint."""

VERTICAL_KEYS = ("vertical", "axis_vertical")
"""Log metadata that says a prismatic axis moves along the vertical (a true value): its constant force is the load's weight."""


def joint_type(position_unit: str | None) -> str:
    """``revolute`` for a position in radians, else ``prismatic`` (the EMPS, the default)."""
    return "revolute" if (position_unit or "").strip().lower() in ROTARY_UNITS else "prismatic"


def vertical(meta: Mapping[str, object]) -> bool:
    """Whether the log's metadata says the axis is vertical (:data:`VERTICAL_KEYS`, or ``orientation: vertical``)."""
    if str(meta.get("orientation", "")).strip().lower() == "vertical":
        return True
    return any(meta.get(k) is True or str(meta.get(k, "")).strip().lower() in ("1", "true", "yes") for k in VERTICAL_KEYS)


def _number(value: Any) -> float | None:
    """``float(value)``, or None for a missing or non-numeric value."""
    try:
        return None if value is None or isinstance(value, bool) else float(value)
    except (TypeError, ValueError):
        return None


def _whole(value: Any) -> int | None:
    """``int(value)`` for a whole number (an int, an integral float, or its decimal text), else None: never a rounded guess."""
    if value is None or isinstance(value, bool):
        return None
    if isinstance(value, int):
        return value
    if isinstance(value, float):
        return int(value) if value.is_integer() else None
    try:
        return int(str(value).strip())
    except ValueError:
        return None


FRICTION_LAW = "friction_law_read"
"""The key of a log's metadata holding the smoothed Coulomb friction read from the recording (``{"vc": ...}``, the parameters of
the plant's ``coulomb_smoothing``: :mod:`ilic_cli.diagnosis.friction_law`): every replay of the log runs that law unless the model
it replays states its own (:func:`ilic_cli.simulation.replay.replay`), and the inverse model's sign is that law's
(:func:`ilic_cli.diagnosis.propose.prepare_system`)."""


def friction_law_speed(meta: Mapping[str, Any]) -> float | None:
    """The smoothing speed ``vc`` of the friction law a log's metadata holds (:data:`FRICTION_LAW`), ``None`` for stick/slip."""
    law = meta.get(FRICTION_LAW)
    return None if law is None else float(law["vc"])


PD_VELOCITIES = ("averaged", "backward", "exact")
"""The velocity estimates a PD controller entry may declare (``velocity``): the benchmark's difference of the position averaged over
two samples, the plain backward difference of the measured position, or the plant's own velocity (:class:`plant.controllers.PDSettings`)."""


@dataclass(frozen=True)
class Controller:
    """The loop that ran, as the log records it (``meta["controller"]`` and ``meta["drive_gain"]``).

    ``kind`` is ``"pd"``, ``"ctc"``, another recorded name, or ``""`` when the log gives gains without a kind.
    ``kp`` (1/s) and ``kv`` (V·s/m or V·s/rad) are the PD gains (top-level ``kp``/``kv`` keys are read too);
    ``drive_gain`` the force per volt of the command (N/V or N·m/V; the controller's ``gtau`` when no top-level key);
    ``settings`` every recorded key as it is (the CTC's settings, ``vmax``, ``pulse_input``, ``delay_samples``).
    """

    kind: str
    kp: float | None = None
    kv: float | None = None
    drive_gain: float | None = None
    settings: Mapping[str, Any] = field(default_factory=dict)

    @classmethod
    def from_meta(cls, meta: Mapping[str, Any]) -> Controller | None:
        """The controller of metadata ``meta``; None when it records none (no ``controller`` entry)."""
        ctl = meta.get("controller")
        if not ctl:
            return None
        doc = dict(ctl) if isinstance(ctl, Mapping) else {"kind": str(ctl)}
        return cls(
            kind=str(doc.get("kind", "")).lower(),
            kp=_number(doc.get("kp", meta.get("kp"))),
            kv=_number(doc.get("kv", meta.get("kv"))),
            drive_gain=_number(meta.get("drive_gain", doc.get("gtau"))),
            settings=doc,
        )


@dataclass(frozen=True)
class Sensor:
    """What the samples measure: the joint (name, type from the position unit, vertical or not), the units and the declared rate."""

    joint: str | None
    joint_type: str
    vertical: bool
    position_unit: str
    force_unit: str
    sample_rate_hz: float | None
    drive_gain: float | None

    @classmethod
    def of(cls, units: Mapping[str, str], meta: Mapping[str, Any]) -> Sensor:
        """The sensor view of a log's ``units`` and ``meta``."""
        q_unit = units.get("q", DEFAULT_UNITS["q"])
        return cls(
            joint=None if meta.get("joint") is None else str(meta["joint"]),
            joint_type=joint_type(q_unit),
            vertical=vertical(meta),
            position_unit=q_unit,
            force_unit=units.get("tau", DEFAULT_UNITS["tau"]),
            sample_rate_hz=_number(meta.get("sample_rate_hz")),
            drive_gain=_number(meta.get("drive_gain")),
        )


@dataclass(frozen=True)
class Provenance:
    """Where the samples come from: the file read (``source``), a simulation's scenario and true parameters, a replay's source."""

    source: str | None
    scenario: Mapping[str, Any] | None = None
    simulation: Mapping[str, Any] | None = None
    true_parameters: Mapping[str, float] | None = None
    replay_of: str | None = None
    model_file: str | None = None
    machine: str | None = None
    start_time_ns: int | None = None

    @classmethod
    def from_meta(cls, meta: Mapping[str, Any]) -> Provenance:
        """The provenance view of metadata ``meta``."""

        def text(key: str) -> str | None:
            value = meta.get(key)
            return None if value is None else str(value)

        return cls(
            source=text("source"),
            scenario=meta.get("scenario"),
            simulation=meta.get("simulation"),
            true_parameters=meta.get("true_parameters"),
            replay_of=text("replay_of"),
            model_file=text("model_file"),
            machine=text("machine"),
            start_time_ns=_whole(meta.get("start_time_ns")),
        )


@dataclass
class RunLog:
    """Samples of one axis over one run.

    Parameters
    ----------
    channels : dict of str to ndarray
        Equally long one-dimensional float64 arrays; must include ``t``, ``q``
        and ``tau``.
    units : dict of str to str
        Unit of each channel; missing entries default to :data:`DEFAULT_UNITS`.
    meta : dict
        JSON-serialisable metadata (see the module docstring).
    """

    channels: dict[str, np.ndarray]
    units: dict[str, str] = field(default_factory=dict)
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        chans: dict[str, np.ndarray] = {}
        for name in sorted(self.channels, key=_channel_sort_key):
            chans[name] = np.ascontiguousarray(np.asarray(self.channels[name], dtype=np.float64).reshape(-1))
        self.channels = chans
        lengths = {len(v) for v in chans.values()}
        if len(lengths) > 1:
            detail = ", ".join(f"{k}={len(v)}" for k, v in chans.items())
            raise LogError(self.meta.get("source"), f"channels differ in length ({detail})")
        for name in chans:
            self.units.setdefault(name, DEFAULT_UNITS.get(name, ""))
        self.units = {k: self.units[k] for k in chans}

    # -- access -----------------------------------------------------------
    def __len__(self) -> int:
        return len(self.channels["t"]) if "t" in self.channels else 0

    def __contains__(self, name: object) -> bool:
        return name in self.channels

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.channels[name]
        except KeyError:
            raise LogError(self.meta.get("source"), f"missing required channel '{name}'") from None

    @property
    def controller(self) -> Controller | None:
        """The loop that ran (:class:`Controller`), None when the log records none."""
        return Controller.from_meta(self.meta)

    @property
    def sensor(self) -> Sensor:
        """What the samples measure (:class:`Sensor`)."""
        return Sensor.of(self.units, self.meta)

    @property
    def provenance(self) -> Provenance:
        """Where the samples come from (:class:`Provenance`)."""
        return Provenance.from_meta(self.meta)

    @property
    def t(self) -> np.ndarray:
        """Time stamps (s)."""
        return self["t"]

    @property
    def dt_s(self) -> float:
        """Nominal sample period (s): from ``sample_rate_hz``, else :func:`ilic_cli.timebase.nominal_rate_hz` of the stamps."""
        rate = self.meta.get("sample_rate_hz")
        if rate:
            return 1.0 / float(rate)
        nominal = nominal_rate_hz(self.t) if len(self.t) >= 2 else None
        if nominal is None:
            raise LogError(self.meta.get("source"), "fewer than two increasing time stamps: no sample period")
        return 1.0 / nominal

    @property
    def fs_hz(self) -> float:
        """Nominal sample rate (Hz), ``1 / dt_s``: the one rate every computation on the log uses."""
        return 1.0 / self.dt_s

    @property
    def duration_s(self) -> float:
        """Time from the first to the last sample (s)."""
        t = self.t
        return float(t[-1] - t[0]) if len(t) else 0.0

    def require(self, *names: str) -> None:
        """Raise :class:`LogError` naming the first channel in ``names`` that is missing."""
        for name in names:
            if name not in self.channels:
                raise LogError(self.meta.get("source"), f"missing required channel '{name}'")

    def with_channels(self, **arrays: np.ndarray) -> RunLog:
        """Return a copy with channels added or replaced."""
        chans = dict(self.channels)
        chans.update(arrays)
        return RunLog(chans, dict(self.units), dict(self.meta))

    def slice(self, start: int, stop: int) -> RunLog:
        """Return the samples ``start:stop`` as a new log (metadata copied)."""
        return RunLog({k: v[start:stop] for k, v in self.channels.items()}, dict(self.units), dict(self.meta))

    # -- conversions ------------------------------------------------------
    def to_frame(self) -> pd.DataFrame:
        """Return the samples as a DataFrame indexed by ``t``."""
        import pandas as pd  # deferred: pandas costs ~0.3 s of import, paid only by a caller of to_frame()

        frame = pd.DataFrame({k: v for k, v in self.channels.items() if k != "t"}, index=pd.Index(self.t, name="t"))
        return frame

    def to_dict(self) -> dict[str, Any]:
        """Return a JSON-serialisable summary (no samples)."""
        return {
            "samples": len(self),
            "channels": list(self.channels),
            "units": dict(self.units),
            "meta": self.meta,
        }


def _channel_sort_key(name: str) -> tuple[int, str]:
    try:
        return (CANONICAL_ORDER.index(name), name)
    except ValueError:
        return (len(CANONICAL_ORDER), name)


def validate_samples(log: RunLog, where: str | None = None) -> None:
    """Refuse logs whose samples cannot be used.

    Raises :class:`LogError` for: a missing ``t``/``q``/``tau`` channel, fewer
    than two samples, NaN or infinite samples, and non-increasing (duplicated
    or backwards) timestamps. Irregular but increasing sampling is accepted
    here and reported by the quality checks.
    """
    src = where or log.meta.get("source")
    for name in REQUIRED:
        if name not in log.channels:
            raise LogError(src, f"missing required channel '{name}'")
    if len(log) < 2:
        raise LogError(src, f"only {len(log)} sample(s): a log needs at least two")
    for name, values in log.channels.items():
        bad = ~np.isfinite(values)
        if bad.any():
            i = int(np.argmax(bad))
            kind = "NaN" if np.isnan(values[i]) else "infinite"
            raise LogError(src, f"channel '{name}' has {int(bad.sum())} NaN/inf sample(s), first {kind} at index {i}")
    step = np.diff(log.t)
    if (step <= 0).any():
        i = int(np.argmax(step <= 0))
        what = "duplicated" if step[i] == 0 else "non-monotonic"
        raise LogError(src, f"{what} timestamps at index {i + 1} (t = {log.t[i + 1]:.9g} s)")
