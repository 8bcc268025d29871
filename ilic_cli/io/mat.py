"""EMPS-style MATLAB ``.mat`` files (level 5: plain ones by :mod:`ilic_cli.io.matfast`, any other with ``scipy.io``).

Layout (column vectors ``N x 1`` unless noted)
----------------------------------------------
=============  ==================  ===========================================
variable       channel / meta      notes
=============  ==================  ===========================================
``t``          ``t``               time (s)
``qm``         ``q``               measured position
``qg``         ``q_ref``           reference position
``vir``        ``vir``             drive command (V)
``gtau``       ``drive_gain``      scalar, N/V; ``tau = gtau * vir``
``kp, kv``     ``controller``      scalars: ``{"kind": "pd", "kp", "kv"}``
``pulses_N``   ``pulses``          uint8 when small non-negative integers
``tau``        ``tau``             only when ``gtau * vir`` does not give it
any other      same name           e.g. ``qd_ref``, ``qdd_ref``
``ilic_meta``  all metadata        JSON text (files written by ilic)
``ilic_units`` units               JSON text; its keys list the channels
=============  ==================  ===========================================

Reading a file without ``ilic_meta`` (the EMPS recordings) derives the
metadata: ``sample_rate_hz`` (nominal, see
:func:`ilic_cli.timebase.nominal_rate_hz`), ``drive_gain`` and the PD
``controller``. Files written by ilic carry ``ilic_meta``/``ilic_units`` and
read back to the same channels, units and metadata bit for bit. Writing uses
zlib compression and a fixed file header text, so the same log gives the same
bytes (scipy would otherwise stamp the creation time).
"""

from __future__ import annotations

import io
import re
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ilic_cli.errors import ChoiceError, LogError
from ilic_cli.io import matfast
from ilic_cli.io.rosjson import dump_json, meta_for_writing, parse_json_object, parse_units
from ilic_cli.runlog import RunLog
from ilic_cli.timebase import nominal_rate_hz

if TYPE_CHECKING:
    from ilic_cli.io import Selection, WriteOptions

CHANNEL_TO_VAR = {"t": "t", "q": "qm", "q_ref": "qg", "vir": "vir", "tau": "tau", "pulses": "pulses_N"}
"""Channel name -> variable name (other channels keep their name)."""

VAR_TO_CHANNEL = {v: k for k, v in CHANNEL_TO_VAR.items()}
SCALARS = ("gtau", "kp", "kv")
META_VAR = "ilic_meta"
UNITS_VAR = "ilic_units"
RESERVED = {*CHANNEL_TO_VAR.values(), *SCALARS, META_VAR, UNITS_VAR}

MAX_DECLARED_BYTES = 2 * 2**30
"""Refuse files whose variables declare more than this many bytes in total."""

HEADER_TEXT = b"MATLAB 5.0 MAT-file, written by ilic"
JOINT_NAMES_VAR = "joint_names"
"""The variable of an n-joint ``.mat`` (:mod:`ilic_cli.io.jointmat`) that names its joints: such a file is an arm's, not one axis's."""
_NAME_RE = re.compile(r"^[A-Za-z][A-Za-z0-9_]{0,62}$")


# -- reading ------------------------------------------------------------------
def _describe(value: Any) -> str:
    if isinstance(value, np.ndarray):
        if value.dtype.kind in "US":
            return "text"
        if value.dtype.kind in "OV":
            return "a cell array or struct"
        shape = "x".join(str(s) for s in value.shape)
        return f"a {shape} {value.dtype} array"
    return type(value).__name__


def _vector(name: str, value: Any, path: Path) -> np.ndarray:
    """Return a variable as a 1-D float64 array or raise naming what is wrong."""
    if not isinstance(value, np.ndarray) or value.dtype.kind not in "fiub":
        raise LogError(path, f"variable '{name}' must be a numeric column vector, got {_describe(value)}")
    if value.ndim > 2 or (value.ndim == 2 and min(value.shape) > 1) or value.size == 0:
        raise LogError(path, f"variable '{name}' must be a numeric column vector, got {_describe(value)}")
    return np.asarray(value, dtype=np.float64).reshape(-1)


def _scalar(name: str, value: Any, path: Path) -> float:
    if not isinstance(value, np.ndarray) or value.dtype.kind not in "fiu" or value.size != 1:
        raise LogError(path, f"variable '{name}' must be a numeric scalar, got {_describe(value)}")
    out = float(value.reshape(-1)[0])
    if not np.isfinite(out):
        raise LogError(path, f"variable '{name}' is not finite ({out})")
    return out


def _text(name: str, value: Any, path: Path) -> str:
    if not isinstance(value, np.ndarray) or value.dtype.kind != "U":
        raise LogError(path, f"variable '{name}' must be text, got {_describe(value)}")
    return "".join(str(x) for x in value.reshape(-1))


def _is_vector(value: Any) -> bool:
    return isinstance(value, np.ndarray) and value.dtype.kind in "fiub" and value.size > 1 and (value.ndim == 1 or (value.ndim == 2 and min(value.shape) == 1))


def _check_declared_sizes(path: Path) -> None:
    """Refuse absurd declared variable sizes before anything is decompressed."""
    import scipy.io  # deferred: 0.13 s of imports (scipy.sparse); only for files matfast does not read

    total = 0
    for _name, shape, _cls in scipy.io.whosmat(str(path)):
        count = 1
        for dim in shape:
            count *= int(dim)
        total += 8 * count
    if total > MAX_DECLARED_BYTES:
        raise LogError(path, f"variables declare {total} bytes (limit {MAX_DECLARED_BYTES}); file is corrupt or too large")


def _load(path: Path) -> dict[str, Any]:
    """The file's variables: by :mod:`ilic_cli.io.matfast` when it reads the file, else by ``scipy.io`` (which says what is wrong with it)."""
    try:
        raw = path.read_bytes()
    except (OSError, MemoryError):  # scipy.io's path says what is wrong
        return _load_scipy(path)
    fast = matfast.load(raw, MAX_DECLARED_BYTES)
    del raw
    if fast is not None:
        return fast
    return _load_scipy(path)


def _load_scipy(path: Path) -> dict[str, Any]:
    import scipy.io  # deferred: 0.13 s of imports (scipy.sparse); only for files matfast does not read

    try:
        _check_declared_sizes(path)
        return scipy.io.loadmat(str(path), squeeze_me=False, chars_as_strings=True, struct_as_record=True, verify_compressed_data_integrity=True)
    except LogError:
        raise
    except NotImplementedError:
        raise LogError(path, "MATLAB v7.3 (HDF5) files are not supported; save with -v7") from None
    except MemoryError:
        raise LogError(path, ".mat file needs more memory than available; file is corrupt or too large") from None
    except Exception as exc:  # noqa: BLE001 - scipy raises many kinds on bad files
        text = " ".join(str(exc).split())[:160]
        raise LogError(path, f"not a readable MATLAB .mat file ({type(exc).__name__}: {text})") from None


def read(path: Path, selection: Selection, *, fast: bool = True) -> RunLog:
    """Read an EMPS-style ``.mat`` file.

    Parameters
    ----------
    path : Path
        The ``.mat`` file.
    selection : Selection
        Ignored (a ``.mat`` file holds one axis).

    Returns
    -------
    RunLog
        With ``tau = gtau * vir`` unless the file has a ``tau`` variable.
    """
    data = {k: v for k, v in _load(path).items() if not k.startswith("__")}
    if JOINT_NAMES_VAR in data and "qm" not in data:  # an arm's log: read whole with its URDF (the command line names the option)
        names = tuple(str(np.asarray(x).reshape(-1)[0]) for x in np.asarray(data[JOINT_NAMES_VAR], dtype=object).reshape(-1))
        raise ChoiceError(path, f"an n-joint log of {len(names)} joints ({', '.join(names[:20])})", "urdf", names)
    for required in ("t", "qm"):
        if required not in data:
            what = "time" if required == "t" else "measured position"
            raise LogError(path, f"missing variable '{required}' ({what}); variables: {', '.join(sorted(data)) or 'none'}")

    units: dict[str, str] | None = None
    meta: dict[str, Any] | None = None
    if UNITS_VAR in data:
        units = parse_units(parse_json_object(_text(UNITS_VAR, data[UNITS_VAR], path), path, f"variable '{UNITS_VAR}'"), path)
    if META_VAR in data:
        meta = parse_json_object(_text(META_VAR, data[META_VAR], path), path, f"variable '{META_VAR}'")

    scalars = {name: _scalar(name, data[name], path) for name in SCALARS if name in data}
    channels: dict[str, np.ndarray] = {}
    for var in ("t", "qm", "qg", "vir", "tau", "pulses_N"):
        if var in data:
            channels[VAR_TO_CHANNEL[var]] = _vector(var, data[var], path)
    wanted_extras = set(units) - set(CHANNEL_TO_VAR) if units is not None else None
    for name, value in data.items():
        if name in RESERVED:
            continue
        if wanted_extras is not None:
            if name in wanted_extras:
                channels[name] = _vector(name, value, path)
        elif _is_vector(value):
            channels[name] = _vector(name, value, path)
    if units is not None:
        missing = [c for c in units if c not in channels and c != "tau"]
        if missing:
            raise LogError(path, f"variable(s) for channel(s) {', '.join(missing)} missing")

    n = len(channels["t"])
    if any(len(v) != n for v in channels.values()):
        detail = ", ".join(f"{CHANNEL_TO_VAR.get(k, k)}={len(v)}" for k, v in channels.items())
        raise LogError(path, f"variables have different lengths ({detail})")

    gain = scalars.get("gtau")
    if "tau" not in channels:
        if gain is None or "vir" not in channels:
            raise LogError(path, "no force: needs 'vir' and 'gtau' (tau = gtau * vir) or a 'tau' variable")
        channels["tau"] = gain * channels["vir"]
    if units is not None:
        # files written by ilic: exactly the channels that were written
        channels = {k: v for k, v in channels.items() if k in units}

    if meta is None:
        meta = {}
        rate = nominal_rate_hz(channels["t"])
        if rate:
            meta["sample_rate_hz"] = rate
        if gain is not None:
            meta["drive_gain"] = gain
        if "kp" in scalars or "kv" in scalars:
            controller: dict[str, Any] = {"kind": "pd"}
            controller.update({k: scalars[k] for k in ("kp", "kv") if k in scalars})
            meta["controller"] = controller
    return RunLog(channels, dict(units or {}), meta)


# -- writing ------------------------------------------------------------------
def _var_name(channel: str) -> str:
    if channel in CHANNEL_TO_VAR:
        return CHANNEL_TO_VAR[channel]
    if channel in RESERVED or not _NAME_RE.match(channel):
        raise LogError(None, f"channel '{channel}' cannot be a MATLAB variable name; rename it")
    return channel


def _pulses_array(values: np.ndarray) -> np.ndarray:
    """uint8 when every value is an integer in 0..255 (as in EMPS), else float64."""
    if np.all((values >= 0) & (values <= 255) & (values == np.round(values))):
        return values.astype(np.uint8).reshape(-1, 1)
    return values.reshape(-1, 1)


def _controller_gains(log: RunLog) -> dict[str, float]:
    """The PD gains ``kp`` and ``kv`` of the log's controller (a PD loop, or gains without a kind)."""
    controller = log.controller
    if controller is None or controller.kind not in ("pd", ""):
        return {}
    return {key: value for key, value in (("kp", controller.kp), ("kv", controller.kv)) if value is not None}


def write(log: RunLog, path: Path, options: WriteOptions) -> None:
    """Write ``log`` as an EMPS-style ``.mat`` file (see the module docstring).

    Parameters
    ----------
    log : RunLog
        The log to write.
    path : Path
        Destination file (a temporary path chosen by ``write_log``).
    options : WriteOptions
        Unused.
    """
    log.require("t", "q", "tau")
    ch = log.channels
    gain = log.sensor.drive_gain or None
    mdict: dict[str, np.ndarray] = {"t": ch["t"].reshape(-1, 1), "qm": ch["q"].reshape(-1, 1)}
    if "q_ref" in ch:
        mdict["qg"] = ch["q_ref"].reshape(-1, 1)
    tau = ch["tau"]
    if "vir" in ch:
        vir = ch["vir"]
    elif gain is not None:
        vir = tau / gain
    else:
        vir = None
    if vir is not None:
        mdict["vir"] = vir.reshape(-1, 1)
    if vir is None or gain is None or not np.array_equal(gain * vir, tau):
        mdict["tau"] = tau.reshape(-1, 1)
    if gain is not None:
        mdict["gtau"] = np.array([[gain]])
    for key, value in _controller_gains(log).items():
        mdict[key] = np.array([[value]])
    if "pulses" in ch:
        mdict["pulses_N"] = _pulses_array(ch["pulses"])
    for name, values in ch.items():
        if name in ("t", "q", "q_ref", "vir", "tau", "pulses"):
            continue
        mdict[_var_name(name)] = values.reshape(-1, 1)
    mdict[META_VAR] = np.array(dump_json(meta_for_writing(log.meta)))
    mdict[UNITS_VAR] = np.array(dump_json(dict(log.units)))

    parts = matfast.dump(mdict, HEADER_TEXT)  # scipy.io's variables, compressed at zlib level 1 in threads
    if parts is not None:
        with open(path, "wb") as out:
            out.writelines(parts)
        return
    import scipy.io  # deferred: 0.13 s of imports; only for variables matfast does not write

    buffer = io.BytesIO()
    scipy.io.savemat(buffer, mdict, do_compression=True, oned_as="column")
    raw = bytearray(buffer.getvalue())
    # MAT level 5: the first 116 bytes are free header text; scipy puts the
    # creation time there. A fixed text makes the file reproducible.
    raw[:116] = HEADER_TEXT.ljust(116, b" ")
    path.write_bytes(bytes(raw))
