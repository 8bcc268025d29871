"""Options and helpers shared by the subcommands."""

from __future__ import annotations

import contextlib
import math
import os
import sys
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

import click

from ilic_cli.errors import ChoiceError, IlicError, ParameterError
from ilic_cli.io import Selection, read_log
from ilic_cli.parameters import PARAMETERS, PD_TIMINGS

if TYPE_CHECKING:
    from ilic_cli.closed_loop_id import ClosedLoopSettings
    from ilic_cli.runlog import RunLog

F = TypeVar("F", bound=Callable[..., Any])

LOG_FORMATS = ["mat", "csv", "mcap", "rosbag1", "rosbag2"]


def _keep_effort(ctx: click.Context, param: click.Parameter, value: str | None) -> str | None:
    # --effort reaches load() through the click context, so that the commands' signatures stay as they are
    ctx.meta["ilic_effort"] = value
    return value


def input_options(func: F) -> F:
    """Add ``--input-format``, ``--topic``, ``--ref-topic``, ``--joint``, ``--effort`` and ``--columns``."""
    func = click.option(
        "--effort",
        default=None,
        metavar="TOPIC[:FIELD]",
        expose_value=False,
        callback=_keep_effort,
        help="ROS: topic (and field) with the effort: a JointState's effort, or a controller state's feedback.effort or output.effort "
        "(default: the measured topic's effort, else the controller state's output.effort).",
    )(func)
    func = click.option(
        "--columns",
        default=None,
        metavar="t=NAME,q=NAME,...",
        help="CSV: which columns hold t, q, qd, tau and q_ref (default: these names or common ones such as time, position, effort).",
    )(func)
    func = click.option("--joint", default=None, help="Joint name to read (default: the only joint).")(func)
    func = click.option(
        "--ref-topic",
        default=None,
        help="Reference topic: JointTrajectoryPoint, JointState or ros2_control controller state (default: /joint_reference, else a controller state).",
    )(func)
    func = click.option(
        "--topic",
        default=None,
        help="Topic with the measured JointState or ros2_control controller state (default: the only JointState topic, or /joint_states).",
    )(func)
    func = click.option(
        "--input-format", "input_format", type=click.Choice(LOG_FORMATS), default=None, help="Format of the input log (default: from the path)."
    )(func)
    return func


JOINTS = ["prismatic", "revolute"]
"""Joint types (:data:`ilic_cli.jointlog.UNITS`), for the ``--load-joint`` choice."""

JOINT_HELP = "The joint's type, i.e. its units (m, N or rad, N·m), for a log that does not say them (a ROS JointState, a CSV without units)."


def joint_option(extra_help: str = "") -> Callable[[F], F]:
    """Add ``--load-joint`` (:func:`declared_joint`): the same declaration in every command that reads a one-joint log."""
    return click.option("--load-joint", "load_joint", type=click.Choice(JOINTS), default=None, help=JOINT_HELP + extra_help)


def declared_joint(log: RunLog, load_joint: str | None) -> RunLog:
    """``log`` with the units of a ``--load-joint`` joint (values unchanged), or as read when none is given."""
    if load_joint is None:
        return log
    from ilic_cli.prepare import as_joint  # deferred: numpy (info and convert --help stay instant)

    return as_joint(log, load_joint)


def selection(topic: str | None, ref_topic: str | None, joint: str | None, columns: str | None = None, effort: str | None = None) -> Selection:
    """Build the reader's :class:`~ilic_cli.io.Selection` from the shared options (``--columns t=time,q=pos``, ``--effort``)."""
    mapping: dict[str, str] = {}
    for item in (columns or "").split(","):
        if not item.strip():
            continue
        channel, eq, name = item.partition("=")
        if not eq or not channel.strip() or not name.strip():
            raise IlicError("--columns", f"'{item.strip()}': expected CHANNEL=COLUMN (e.g. t=time,q=position,tau=effort)")
        mapping[channel.strip()] = name.strip()
    return Selection(topic=topic, ref_topic=ref_topic, joint=joint, columns=tuple(mapping.items()), effort=effort)


PROGRESS_MIN_BYTES = 20 * 2**20
"""Files (or bag folders) at least this large show a progress bar while they are read."""


ARM_HINT = "identify and replay read an arm's log whole with --urdf ARM.urdf"
"""What a one-joint command adds when a log holds several joints."""


def load(path: str | Path, input_format: str | None, topic: str | None, ref_topic: str | None, joint: str | None, columns: str | None = None) -> RunLog:
    """Read a log with the shared input options (with a progress bar for large files on a terminal)."""

    progress = ReadProgress if progress_enabled() and _size(Path(path)) >= PROGRESS_MIN_BYTES else None
    ctx = click.get_current_context(silent=True)
    effort = ctx.meta.get("ilic_effort") if ctx is not None else None
    try:
        return read_log(path, input_format, selection(topic, ref_topic, joint, columns, effort), progress=progress)
    except ChoiceError as exc:
        if exc.choice == "urdf":  # an arm's log that holds no one-joint choice
            raise ChoiceError(exc.where, f"{exc.problem}: {ARM_HINT}", exc.choice, exc.candidates) from None
        arm = f" ({ARM_HINT})" if exc.choice == "joint" and len(exc.candidates) > 1 else ""  # several joints: maybe an arm's log
        raise ChoiceError(exc.where, f"{exc.problem} with --{exc.choice}{arm}", exc.choice, exc.candidates) from None


def _size(path: Path) -> int:
    try:
        if path.is_dir():
            return sum(p.stat().st_size for p in path.iterdir() if p.is_file())
        return path.stat().st_size
    except OSError:
        return 0


class ReadProgress:
    """A one-line progress bar on stderr: ``reading NAME [#####     ]  50 %``; erased when done."""

    WIDTH = 30

    def __init__(self, path: Path) -> None:
        self.label = Path(path).name
        self.last = -1

    def update(self, done: int, total: int) -> None:
        """Redraw the bar when the percentage changes."""
        pct = max(0, min(100, int(100 * done / total))) if total > 0 else 0
        if pct == self.last:
            return
        self.last = pct
        filled = self.WIDTH * pct // 100
        click.echo(f"\r  reading {self.label} [{'#' * filled}{' ' * (self.WIDTH - filled)}] {pct:3d} %", err=True, nl=False)

    def close(self) -> None:
        """Erase the bar."""
        if self.last >= 0:
            click.echo("\r" + " " * (len(self.label) + self.WIDTH + 20) + "\r", err=True, nl=False)


def progress_enabled() -> bool:
    """Progress bars only on a terminal and never in CI."""
    return sys.stderr.isatty() and not os.environ.get("CI")


def note(message: str) -> None:
    """Print a message for the user on stderr (stdout carries only results)."""
    click.echo(message, err=True)


# ---------------------------------------------------------------------------
# option text and the wording of domain errors (only the command line speaks of flags)
# ---------------------------------------------------------------------------
STRUCTURES = ["rigid", "rigid-offset", "asymmetric"]
"""Model structures (:data:`ilic_cli.parameters.STRUCTURES`), for the ``--structure`` choice."""

OPTIONS: dict[str, str] = {
    "scenario": "--scenario",
    "controller": "--controller",
    "omega": "--omega",
    "xi": "--xi",
    "alpha": "--alpha",
    "window_s": "--window",
    "sigma_max_pct": "--sigma-max",
    "cutoff_hz": "--ilic-cutoff",
    "velocity": "--velocity",
    "structure": "--structure",
    "kp": "--kp",
    "kv": "--kv",
    "gtau": "--drive-gain",
    "vmax": "--vmax",
    "duration": "--duration",
    "substeps": "--substeps",
    "published_setup": "--published-setup",
    "tau_sensor": "--tau-sensor",
    "trajectory": "--trajectory",
    "effect": "--effect",
    "method": "--method",
    "clock_s": "--published-setup",
    "noise.tau_std": "--noise-tau",
    "noise.q_std": "--noise-q",
    "quantization.resolution": "--resolution",
    "parameter": "--param",
    "gear_ratio": "--gear-ratio",
    "torque_constant": "--torque-constant",
    "load_joint": "--load-joint",
    "rate_hz": "--resample",
    "max_iterations": "--max-iterations",
    "tolerance_pct": "--tolerance",
}
"""Parameter of a :class:`~ilic_cli.errors.ParameterError` -> the option that sets it."""


@contextlib.contextmanager
def options_named() -> Iterator[None]:
    """Turn a domain :class:`~ilic_cli.errors.ParameterError` into the option that set the value (:func:`option_for`)."""
    try:
        yield
    except ParameterError as exc:
        raise exc.at(exc.where or option_for(exc.parameter)) from None


def plant_of_model_file(path: Path) -> tuple[Any, dict[str, Any]]:
    """The plant (rigid parameters, effects) a model file describes; its errors name the file."""
    from ilic_cli.modelfile import load_model_file  # deferred: the plant pulls in numba
    from plant.dynamics import plant_model  # deferred: the plant pulls in numba

    doc = load_model_file(path)
    try:
        return plant_model(doc["parameters"], doc["effects"])
    except ParameterError as exc:
        raise exc.at(path) from None


def option_for(parameter: str) -> str | None:
    """The option a parameter's value comes from (``Fc`` -> ``--param``, ``stribeck.vs`` -> ``--effect``); ``None`` if none does."""

    if parameter in OPTIONS:
        return OPTIONS[parameter]
    if parameter in PARAMETERS:
        return "--param"
    if parameter.startswith("chi0."):
        return "--chi0"
    return "--effect" if "." in parameter else None


def parse_assignment(text: str, option: str) -> tuple[str, float]:
    """Parse ``NAME=VALUE`` with a finite float value (``--param``, ``--chi0``)."""

    key, eq, value = text.partition("=")
    if not eq or not key.strip():
        raise IlicError(option, f"'{text}': expected NAME=VALUE")
    try:
        v = float(value)
    except ValueError:
        raise IlicError(option, f"'{text}': '{value}' is not a number") from None
    if not math.isfinite(v):
        raise IlicError(option, f"'{text}': value must be finite")
    return key.strip(), v


def parse_effect_option(text: str) -> tuple[str, dict[str, float]]:
    """Parse ``ID`` or ``ID:k=v,k=v`` (``--effect``)."""
    from ilic_cli.effects import plant_ids  # deferred: the effects pull in numba, which info and convert never need

    eid, _, rest = text.partition(":")
    eid = eid.strip()
    if eid not in plant_ids():
        raise IlicError("--effect", f"unknown effect '{eid}' (known: {', '.join(plant_ids())})")
    params: dict[str, float] = {}
    if rest.strip():
        for item in rest.split(","):
            key, eq, value = item.partition("=")
            if not eq or not key.strip():
                raise IlicError("--effect", f"'{text}': expected ID:name=value,name=value")
            try:
                params[key.strip()] = float(value)
            except ValueError:
                raise IlicError("--effect", f"'{text}': '{value}' is not a number") from None
    return eid, params


def controller_options(func: F) -> F:
    """Add ``--controller``, ``--kp``, ``--kv`` and ``--drive-gain`` (the loop of a log that records none), and ``--pd-timing``."""
    func = click.option(
        "--pd-timing",
        "pd_timing",
        type=click.Choice(PD_TIMINGS),
        default="recorded",
        show_default=True,
        help="The PD loop the replays run: as read from the recording (which sample its command follows, when it acts, which "
        "velocity it feeds back; the EMPS recordings' command follows the same sample's position), or as documented in its "
        "metadata (the benchmark's loop, one period late).",
    )(func)
    func = click.option(
        "--drive-gain",
        "drive_gain",
        type=click.FloatRange(min=0, min_open=True),
        default=None,
        help="PD drive gain (N/V) of a log without a recorded controller.",
    )(func)
    func = click.option("--kv", type=click.FloatRange(min=0, min_open=True), default=None, help="PD velocity gain of a log without a recorded controller.")(
        func
    )
    func = click.option(
        "--kp", type=click.FloatRange(min=0, min_open=True), default=None, help="PD position gain (1/s) of a log without a recorded controller."
    )(func)
    func = click.option(
        "--controller",
        "controller",
        type=click.Choice(["pd", "ctc"]),
        default=None,
        help="The loop that ran, for a log that records none (pd needs --kp, --kv, --drive-gain; ctc: the paper's gains).",
    )(func)
    return func


def with_controller(log: RunLog, where: Path, controller: str | None, kp: float | None, kv: float | None, drive_gain: float | None) -> RunLog:
    """``log`` with the controller the options give when it records none; refuse a log with neither.

    A log that records its controller keeps it: the options are refused then,
    rather than silently overriding the recording.
    """
    from ilic_cli.runlog import RunLog  # deferred: numpy (info and convert --help stay instant)
    from plant.replay import records_controller  # deferred: the plant pulls in numba

    given = controller is not None or any(v is not None for v in (kp, kv, drive_gain))
    if records_controller(log):
        if given:
            raise IlicError("--controller", f"{where} records its controller; the options apply only to a log that records none")
        return log
    if controller is None:
        raise IlicError(
            where, "the log records no controller (its kind and gains): give the loop that ran with --controller pd --kp --kv --drive-gain, or --controller ctc"
        )
    meta = dict(log.meta)
    if controller == "pd":
        missing = [name for name, v in (("--kp", kp), ("--kv", kv), ("--drive-gain", drive_gain)) if v is None]
        if missing:
            raise IlicError("--controller", f"pd needs {', '.join(missing)}")
        meta["controller"], meta["drive_gain"] = {"kind": "pd", "kp": kp, "kv": kv}, drive_gain
    else:
        if any(v is not None for v in (kp, kv, drive_gain)):
            raise IlicError("--controller", "--kp, --kv and --drive-gain are PD gains; ctc takes none")
        meta["controller"] = {"kind": "ctc"}
    return RunLog(dict(log.channels), dict(log.units), meta)


@dataclass(frozen=True)
class InputOptions:
    """``--input-format``, ``--topic``, ``--ref-topic``, ``--joint`` and ``--columns``: how a log is read (:func:`load`)."""

    input_format: str | None
    topic: str | None
    ref_topic: str | None
    joint: str | None
    columns: str | None

    @classmethod
    def of(cls, o: Mapping[str, Any]) -> InputOptions:
        return cls(o["input_format"], o["topic"], o["ref_topic"], o["joint"], o["columns"])

    def load(self, path: Path, *, named_format: bool = True) -> RunLog:
        """The log at ``path`` (``named_format=False``: its format from its path, as a validation log's)."""
        return load(path, self.input_format if named_format else None, self.topic, self.ref_topic, self.joint, self.columns)


@dataclass(frozen=True)
class ControllerOptions:
    """``--controller``, ``--kp``, ``--kv``, ``--drive-gain`` (the loop of a log that records none) and ``--pd-timing``."""

    controller: str | None
    kp: float | None
    kv: float | None
    drive_gain: float | None
    pd_timing: str = "recorded"

    @classmethod
    def of(cls, o: Mapping[str, Any]) -> ControllerOptions:
        return cls(o["controller"], o["kp"], o["kv"], o["drive_gain"], o["pd_timing"])

    @property
    def given(self) -> bool:
        """Some controller option was given."""
        return self.controller is not None or any(v is not None for v in (self.kp, self.kv, self.drive_gain))

    def apply(self, log: RunLog, where: Path) -> RunLog:
        """``log`` with the options' controller when it records none (:func:`with_controller`)."""
        return with_controller(log, where, self.controller, self.kp, self.kv, self.drive_gain)


def structure_or_model_file(model: str | None, structure: str | None) -> tuple[str | None, Path | None]:
    """Resolve ``--model`` (a model file) and ``--structure``, accepting the old ``--model STRUCTURE`` with a warning.

    Returns ``(structure, model file)``; ``--model rigid`` (no such file) is
    the deprecated spelling of ``--structure rigid`` for this release.
    """

    if model is None:
        return structure, None
    if model in STRUCTURES and not Path(model).exists():
        if structure is not None and structure != model:
            raise IlicError("--model", f"'{model}' (the old spelling of --structure) contradicts --structure {structure}")
        note(f"ilic: warning: --model {model} is deprecated for a structure; use --structure {model} (--model now names a model file)")
        return model, None
    return structure, Path(model)


def closed_loop_settings(o: Mapping[str, Any]) -> dict[str, ClosedLoopSettings]:
    """DIDIM's and IDIM-IV's iteration, of one joint or n: each method's default (:data:`ilic_cli.closed_loop_id.DEFAULT_SETTINGS`), the options' limits."""
    from ilic_cli.closed_loop_id import DEFAULT_SETTINGS  # deferred: numpy and the estimators only when a method runs (`ilic --help` stays instant)

    max_iterations, tolerance = o["max_iterations"], o["tolerance"]
    return {
        m: replace(
            s, max_iterations=s.max_iterations if max_iterations is None else max_iterations, tolerance_pct=s.tolerance_pct if tolerance is None else tolerance
        )
        for m, s in DEFAULT_SETTINGS.items()
    }
