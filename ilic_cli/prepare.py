"""One preparation of a log for the numerics: its rate, its quality and the samples that may be used.

``identify``, ``diagnose`` and ``replay`` all start here, so the rate, the
data-quality warnings, the saturation masking and the contiguous parts
between gaps of the time stamps are worked out once and the same way for
each. The rules:

* **rate**: the log's nominal rate (:func:`ilic_cli.timebase.nominal_rate_hz`:
  the mean step over the log, gaps left out, rounded to a round rate within
  0.05 %), so that stamp jitter of a fixed-rate loop averages out;
* **gaps** (steps above 1.5 periods): identification filters, differentiates
  and decimates each contiguous part on its own and never across a gap
  (IDIM-LS stacks their rows, IDIM-ILIC drops the windows a gap cuts);
  ``diagnose`` and ``replay`` refuse such a log (a closed-loop replay cannot
  span a gap);
* **irregular sampling** (:func:`ilic_cli.timebase.sampling_kind`): the
  samples of a fixed-rate loop whose stamps only jitter are kept, and the
  stamps are put back on the loop's grid (:func:`restamped`): the samples
  were taken on time, so time-based work (a delay's shift, the sample hold,
  a replay) must not read the jitter as timing; a log sampled
  irregularly is interpolated linearly onto a uniform grid at its mean rate,
  within each part between gaps (:func:`to_uniform_grid`), and a warning
  says so and states the rule (:data:`ilic_cli.timebase.SAMPLING_RULE`);
* **saturation**: samples on the plateau of a saturated drive are masked;
* **rest**: samples where the axis stands still are masked too
  (:func:`ilic_cli.usable.with_rest`, the rule :data:`ilic_cli.usable.REST_RULE`):
  a stuck axis carries any force within the static friction, so the sign of
  the Coulomb column is undefined there. :attr:`PreparedLog.valid` holds both
  masks, so every estimator and the diagnosis fit the same rows;
* **force timing** (:func:`tau_sensor`, :attr:`PreparedLog.hold_s`): a force
  that is the drive's command held over each period is the model's mean over
  that period, i.e. the model half a period later.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ilic_cli.errors import LogError, ParameterError
from ilic_cli.jointlog import MOTION_CHANNELS, UNITS, channel_units
from ilic_cli.quality import assess_log, saturation_mask
from ilic_cli.runlog import RunLog
from ilic_cli.timebase import SAMPLING_RULE, clock_deviation, irregular_grid, nominal_rate_hz, sampling_kind, segments


@dataclass(frozen=True)
class RestSamples:
    """The samples of a log at which the axis stands still (:func:`ilic_cli.usable.rest_samples` finds them).

    Attributes
    ----------
    mask : ndarray of bool
        One per sample: True at rest, or within the position filter's reach of a sample at rest.
    dwells : int
        Stretches of rest found.
    speed_threshold : float
        The filtered speed below which a sample may be at rest (position unit per second).
    rule : str
        The rule, in words (:data:`ilic_cli.usable.REST_RULE`).
    speed_noise : float
        RMS of the filtered velocity over the dwells (position unit per second; 0: none): the velocity's noise, whose
        expected sign the Coulomb column is once rows at rest are left out (:data:`ilic_cli.usable.SIGN_RULE`).
    """

    mask: np.ndarray
    dwells: int
    speed_threshold: float
    rule: str
    speed_noise: float = 0.0

    @property
    def count(self) -> int:
        """Samples masked as at rest."""
        return int(np.count_nonzero(self.mask))

    def to_dict(self) -> dict[str, Any]:
        return {
            "rule": self.rule,
            "dwells": self.dwells,
            "samples_at_rest": self.count,
            "speed_threshold": self.speed_threshold,
            "speed_noise": self.speed_noise,
        }


def tau_sensor(log: RunLog) -> str | None:
    """How ``log``'s force samples the drive force, when the log says so; else ``None``.

    The sensor a simulated log was made with (``meta["simulation"]["tau_sensor"]``);
    ``command`` when the force is the drive command times the drive gain: a
    ``vir`` channel and a ``drive_gain``, as in the EMPS recordings, or a PD
    loop with its drive gain declared for a log that records neither
    (``--controller pd --drive-gain``: the force of that loop is its command);
    nothing is assumed for any other log.
    """
    sensor = (log.provenance.simulation or {}).get("tau_sensor")
    if sensor:
        return str(sensor)
    if not log.sensor.drive_gain:
        return None
    controller = log.controller
    declared_pd = controller is not None and controller.kind == "pd"
    return "command" if "vir" in log or declared_pd else None


def drive_command(log: RunLog) -> np.ndarray | None:
    """The drive command (V) of ``log``: its ``vir``, or, when its force is the drive's command (:func:`tau_sensor`), that
    force over the drive gain (a PD loop declared with ``--drive-gain``); ``None`` otherwise. A drive that clips its
    command shows as a plateau of it (:func:`ilic_cli.quality.saturation`) whether the log records ``vir`` or not."""
    if "vir" in log:
        return np.asarray(log["vir"], dtype=np.float64)
    gain = log.sensor.drive_gain
    if gain and tau_sensor(log) == "command" and "tau" in log:
        return np.asarray(log["tau"], dtype=np.float64) / gain
    return None


def hold_of(sensor: str | None, fs_hz: float) -> float:
    """Half a sample period when the logged force is the held command (``sensor == "command"``), else 0."""
    return 0.5 / fs_hz if sensor == "command" else 0.0


def force_hold_s(log: RunLog, fs_hz: float) -> float:
    """How long the logged force at a sample is held: half a period for the drive's held command (:func:`hold_of` of
    :func:`tau_sensor`), 0 for a PD law acting inside the dynamics (``continuous``: its command at the sample is the force
    there, read from the recording by the diagnosis and by ``identify``: :func:`ilic_cli.simulation.pd_law.inside_is_closer`)."""
    if law_inside(log):
        return 0.0
    return hold_of(tau_sensor(log), fs_hz)


def law_inside(log: RunLog) -> bool:
    """Whether the log's PD law acts on the plant's state at every integration step (``continuous``: the law inside a
    simulator's dynamics, as the log's controller entry says)."""
    controller = log.controller
    return controller is not None and controller.kind == "pd" and bool(controller.settings.get("continuous"))


@dataclass(frozen=True)
class PreparedLog:
    """A log with what the numerics need to know about it.

    Attributes
    ----------
    log : RunLog
        The log itself.
    fs_hz : float
        Its nominal sample rate (:attr:`RunLog.fs_hz`).
    valid : ndarray of bool or None
        Samples that may be used; False on the plateaus of a saturated drive
        (:func:`ilic_cli.quality.saturation_mask`) and, once
        :func:`ilic_cli.usable.with_rest` has looked, at rest; ``None`` when every one may.
    warnings : tuple of str
        The data-quality warnings, prefixed.
    segments : tuple of (int, int)
        The contiguous runs of samples between gaps of the time stamps
        (``(start, stop)``; one run without gaps).
    saturated : ndarray of bool or None
        The samples masked because the drive saturates (``None``: none).
    rest : RestSamples or None
        The samples masked at rest (``None``: not looked for yet).
    """

    log: RunLog
    fs_hz: float
    valid: np.ndarray | None
    warnings: tuple[str, ...]
    segments: tuple[tuple[int, int], ...] = ()
    saturated: np.ndarray | None = None
    rest: RestSamples | None = None

    @property
    def hold_s(self) -> float:
        """Half a period when the log's force is the drive's held command (:func:`force_hold_s`), else 0."""
        return force_hold_s(self.log, self.fs_hz)

    def with_rest(self, rest: RestSamples) -> PreparedLog:
        """This log with the samples of ``rest`` masked too (:attr:`valid`: neither saturated nor at rest)."""
        usable = ~rest.mask if self.saturated is None else ~(rest.mask | self.saturated)
        return replace(self, valid=None if usable.all() else usable, rest=rest)

    @property
    def source(self) -> str:
        source = self.log.provenance.source
        return "" if source is None else source

    @property
    def gap_samples(self) -> np.ndarray:
        """Index of the last sample before each gap."""
        return np.array([b - 1 for _, b in self.segments[:-1]], dtype=np.int64)

    def require_contiguous(self, what: str) -> None:
        """Refuse a log with gaps for ``what`` (a closed-loop replay cannot span a gap)."""
        if len(self.segments) > 1:
            t = self.log.t
            longest = max(float(t[b] - t[b - 1]) for _, b in self.segments[:-1])
            raise LogError(
                self.source,
                f"{len(self.segments) - 1} gap(s) in the time stamps (the longest {longest:.3g} s): {what} needs one "
                "contiguous recording; cut the log at the gaps (identify uses the contiguous parts by itself)",
            )

    def saturation_note(self) -> str | None:
        """``saturated drive: X % of the samples masked``, or ``None`` without masking."""
        if self.saturated is None:
            return None
        return f"saturated drive: {100.0 * float(np.mean(self.saturated)):.3g} % of the samples masked"


def to_uniform_grid(log: RunLog, rate_hz: float, parts: tuple[tuple[int, int], ...], rule: str) -> RunLog:
    """``log`` interpolated linearly onto a uniform grid at ``rate_hz``, each of ``parts`` on its own (never across a gap).

    Part ``(a, b)`` gives the samples ``t[a] + k / rate_hz`` up to ``t[b - 1]``;
    every channel is interpolated linearly (discrete channels such as
    ``pulses`` too). ``sample_rate_hz`` becomes ``rate_hz`` and ``resampled``
    records the original sample count and ``rule``.
    """
    t = log.t
    grids = []
    for a, b in parts:
        count = int(np.floor(float(t[b - 1] - t[a]) * rate_hz * (1 + 1e-12))) + 1
        if count > 100_000_000:
            raise ParameterError("rate_hz", rate_hz, f"at most 1e8 samples over {float(t[b - 1] - t[a]):.6g} s")
        grid = t[a] + np.arange(count, dtype=np.float64) / rate_hz
        grid[-1] = min(grid[-1], t[b - 1])
        grids.append(grid)
    channels: dict[str, np.ndarray] = {}
    for name, values in log.channels.items():
        pieces = [grid if name == "t" else np.interp(grid, t[a:b], values[a:b]) for grid, (a, b) in zip(grids, parts, strict=True)]
        channels[name] = np.concatenate(pieces)
    meta = {**log.meta, "sample_rate_hz": float(rate_hz), "resampled": {"method": "linear", "rule": rule, "from_samples": len(log), "rate_hz": float(rate_hz)}}
    return RunLog(channels, dict(log.units), meta)


def resample(log: RunLog, rate_hz: float) -> RunLog:
    """Return ``log`` on a uniform grid at ``rate_hz`` (``ilic convert --resample``).

    A fixed-rate loop whose stamps only jitter (:func:`ilic_cli.timebase.sampling_kind`)
    at ``rate_hz`` keeps its samples and is restamped on the uniform grid:
    interpolating between jittered stamps would distort samples taken on
    time. Any other log is interpolated linearly (:func:`to_uniform_grid`)
    within each part between gaps.
    """
    if not (rate_hz > 0 and np.isfinite(rate_hz)):
        raise ParameterError("rate_hz", rate_hz, "a positive number (Hz)")
    t = log.t
    nominal = nominal_rate_hz(t)
    kind = sampling_kind(t)
    if nominal and kind == "fixed-rate" and abs(nominal - rate_hz) <= 5e-4 * rate_hz and len(parts := segments(t, nominal)) == 1:
        return _on_grid(log, _grid_stamps(t, rate_hz, parts), rate_hz)
    parts = irregular_grid(t)[1] if kind == "irregular" else segments(t, nominal or rate_hz)
    out = to_uniform_grid(log, rate_hz, parts, "requested rate")
    if len(out) < 2:
        raise ParameterError("rate_hz", rate_hz, f"a rate that leaves two samples in {float(t[-1] - t[0]):.6g} s")
    return out


RESTAMP_TOLERANCE = 1e-3
"""Stamps within this share of a period of the uniform grid are left as they are: rounding of the stamps, far below any timing
the numerics resolve (DATA_EMPS.mat's stamps are within 3.2e-5 periods of its 1 kHz grid; the delay search steps by 0.05 periods)."""


def restamped(log: RunLog) -> tuple[RunLog, float]:
    """A fixed-rate loop's log with its stamps on the uniform grid of its nominal rate, within each part between gaps.

    Returns the log (``log`` itself when its stamps are within
    :data:`RESTAMP_TOLERANCE` of the grid, or it has no nominal rate) and the
    stamps' jitter: their largest deviation from a straight line through each
    part, in periods (0 when left as it is). The samples are not touched.
    """
    t = log.t
    rate = nominal_rate_hz(t)
    if not rate:
        return log, 0.0
    parts = segments(t, rate)
    grid = _grid_stamps(t, rate, parts)
    if float(np.max(np.abs(t - grid))) * rate <= RESTAMP_TOLERANCE:
        return log, 0.0
    jitter = max((clock_deviation(t[a:b]) for a, b in parts if b - a > 1), default=0.0)
    return _on_grid(log, grid, rate), jitter


def _grid_stamps(t: np.ndarray, rate_hz: float, parts: tuple[tuple[int, int], ...]) -> np.ndarray:
    """Stamps on the uniform grid of ``rate_hz`` from each part's first stamp (one stamp per sample)."""
    grid = np.empty_like(t)
    for a, b in parts:
        grid[a:b] = t[a] + np.arange(b - a, dtype=np.float64) / rate_hz
    return grid


def _on_grid(log: RunLog, grid: np.ndarray, rate_hz: float) -> RunLog:
    """``log`` with the stamps ``grid`` (its samples kept), and metadata saying it was restamped."""
    meta = {**log.meta, "sample_rate_hz": float(rate_hz)}
    meta["resampled"] = {"method": "restamped (stamp jitter of a fixed-rate loop)", "from_samples": len(log), "rate_hz": float(rate_hz)}
    return RunLog({**log.channels, "t": grid}, dict(log.units), meta)


def prepare_log(log: RunLog, prefix: str = "data quality") -> PreparedLog:
    """Assess ``log`` once: rate, quality warnings (``prefix: ...``) and the usable samples.

    A saturated drive command is never used silently: the samples on its
    plateau are masked, and the note says so. An irregularly sampled log is
    interpolated onto a uniform grid first (:func:`to_uniform_grid`, the
    module's rules), and a warning says so.
    """
    notes: tuple[str, ...] = ()
    if len(log) > 2 and "resampled" not in log.meta and sampling_kind(log.t) == "irregular":
        rate, parts = irregular_grid(log.t)
        before = len(log)
        log = to_uniform_grid(log, rate, parts, "irregular sampling")
        notes = (
            f"{prefix}: irregular sampling: {before} samples interpolated linearly onto a uniform {rate:g} Hz grid ({len(log)} samples, "
            f"{len(parts)} part(s)); rule: {SAMPLING_RULE}",
        )
    elif len(log) > 2 and "resampled" not in log.meta:
        log, jitter = restamped(log)
        if jitter:
            notes = (f"{prefix}: stamp jitter of a fixed-rate loop (up to {100 * jitter:.3g} % of a period): samples kept, restamped on its uniform grid",)
    command = drive_command(log)
    quality = assess_log(log, command)
    warnings = notes + tuple(f"{prefix}: {message}" for message in quality.warnings())
    saturated = None
    if quality.saturation_limit is not None and command is not None:
        mask = saturation_mask(command, quality.saturation_limit)
        saturated = mask if mask.any() else None
    fs = log.fs_hz
    valid = None if saturated is None else ~saturated
    return PreparedLog(log=log, fs_hz=fs, valid=valid, warnings=warnings, segments=segments(log.t, fs), saturated=saturated)


def as_joint(log: RunLog, joint: str) -> RunLog:
    """``log`` with the position and force units of a ``joint`` axis, values unchanged.

    For logs that carry no units (a ROS ``JointState``: metres and newtons or
    radians and newton-metres, by the joint's type, which the message does not
    say): the user's declaration labels every parameter (kg or kg·m², ...).
    """
    if joint not in UNITS:
        raise ParameterError("load_joint", joint, "prismatic or revolute")
    units = dict(log.units) | {name: unit for name, unit in channel_units(joint).items() if name in log.channels}
    return RunLog(dict(log.channels), units, dict(log.meta))


def to_load_side(log: RunLog, gear_ratio: float, torque_constant: float | None = None, load_joint: str = "prismatic") -> RunLog:
    """A motor-side log seen from the load, through a transmission of ``gear_ratio``.

    ``gear_ratio`` is the motor angle per unit of load motion (rad/m of a ball
    screw, rad/rad of a gearbox): the load position is ``q / gear_ratio`` (and
    so its velocities and accelerations), and the force on the load is the
    motor torque times ``gear_ratio``. With ``torque_constant`` (N·m/A) the
    logged ``tau`` is the motor current: the torque is ``torque_constant *
    tau``. Parameters identified on the result are the load's, in the units of
    a ``load_joint`` (kg, N·s/m, N or kg·m², N·m·s/rad, N·m).
    """
    if not (gear_ratio > 0 and np.isfinite(gear_ratio)):
        raise ParameterError("gear_ratio", gear_ratio, "a positive number (motor rad per load unit)")
    if torque_constant is not None and not (torque_constant > 0 and np.isfinite(torque_constant)):
        raise ParameterError("torque_constant", torque_constant, "a positive number (N·m/A)")
    factor = {"tau": (torque_constant or 1.0) * gear_ratio} | {n: 1 / gear_ratio for n in MOTION_CHANNELS}
    channels = {n: (v * factor[n] if n in factor else v) for n, v in log.channels.items()}
    meta = {
        **log.meta,
        "transmission": {
            "gear_ratio": gear_ratio,
            "torque_constant": torque_constant,
            "load_joint": load_joint,
            "motor_units": {n: log.units.get(n, "") for n in factor if n in log.channels},
        },
    }
    return as_joint(RunLog(channels, dict(log.units), meta), load_joint)
