"""Collected ROS columns -> RunLog.

A file with ``/ilic/metadata`` is read back exactly. Any other file is read
from its measured topic (``Selection.topic``; else the only
``sensor_msgs/JointState`` topic, or ``/joint_states``; else the only
ros2_control ``control_msgs/JointTrajectoryControllerState`` topic) for one
joint (``Selection.joint`` or the only one), picked by name in each message:
``q``/``qd``/``tau`` from ``position``/``velocity``/``effort`` (JointState) or
``feedback``/``actual`` (controller state), ``t`` from ``header.stamp`` (log
time when every stamp is zero) relative to the first sample. The reference
comes from ``Selection.ref_topic``, else ``/joint_reference``, else the
controller state topic: ``q_ref``/``qd_ref``/``qdd_ref`` from
``JointTrajectoryPoint``, ``JointState`` or the controller state's
``reference``/``desired``, matched to the joint by name where the message
carries names. ``tau`` can come from another topic and field
(``Selection.effort``); a controller state's ``output.effort`` (the
commanded effort) is used when the measured topic has no effort.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ilic_cli.errors import ChoiceError, LogError
from ilic_cli.io.container import guarded
from ilic_cli.io.jointparts import is_joints_metadata
from ilic_cli.io.rosjson import parse_json_object, parse_units
from ilic_cli.io.rosschema import (
    CONTROLLER_STATE,
    FORMAT_TAG,
    FORMAT_VERSION,
    JOINT_STATE,
    REFERENCE_FIELDS,
    STATE_FIELDS,
    STRING,
    TIME_NAME,
    TOPIC_EXTRAS,
    TOPIC_METADATA,
    TOPIC_REFERENCE,
    TOPIC_STATES,
    TRAJECTORY,
    TRAJECTORY_POINT,
)
from ilic_cli.io.rostopics import Collected
from ilic_cli.jointlog import UNITS, channel_units
from ilic_cli.runlog import RunLog
from ilic_cli.timebase import nominal_rate_hz

if TYPE_CHECKING:
    from ilic_cli.io import Selection

MEASURED_FIELDS: dict[str, dict[str, str]] = {
    JOINT_STATE: {"position": "position", "velocity": "velocity", "effort": "effort"},
    CONTROLLER_STATE: {"position": "feedback.positions", "velocity": "feedback.velocities", "effort": "feedback.effort"},
}
"""Measured topic type -> sample -> field of its columns (:mod:`ilic_cli.io.roscollect`)."""

EFFORT_FIELDS: dict[str, tuple[str, ...]] = {JOINT_STATE: ("effort",), CONTROLLER_STATE: ("feedback.effort", "output.effort")}
"""Fields that can give ``tau``, per message type (the first is the default)."""


def decode(source: Collected, selection: Selection, path: Path) -> RunLog:
    """Build a :class:`RunLog` from the collected messages of a container.

    Parameters
    ----------
    source : Collected
        Topics and decoded columns of the file.
    selection : Selection
        Topic, reference topic and joint to read (see the module docstring).
    path : Path
        The file, named in errors.

    Returns
    -------
    RunLog
        Not yet validated (``read_log`` validates).
    """
    topics = source.topics
    meta_topic = topics.get(TOPIC_METADATA)
    ours = meta_topic is not None and meta_topic.msgtype == STRING and selection.topic in (None, TOPIC_STATES)
    arm = _arm_joints(source, path) if ours else None
    if ours and arm is None:
        return _decode_ilic(source, selection, path)
    log = _decode_foreign(source, selection, path)
    return log if arm is None else _arm_joint(log, arm)


def _arm_joints(source: Collected, path: Path) -> dict[str, str] | None:
    """Each joint's declared type when the metadata is an n-joint log's (:func:`ilic_cli.io.jointparts.is_joints_metadata`), else None.

    Such a log is a plain JointState log to this reader: one of its joints is read when chosen,
    and without a choice the joints are listed to choose from (the whole arm is read with its URDF).
    """
    series = source.series(TOPIC_METADATA)
    if len(series) == 0 or series.text is None:
        return None
    payload = parse_json_object(series.text, path, f"{TOPIC_METADATA} message")
    if not is_joints_metadata(payload):
        return None
    return {str(p[0]): str(p[1]) for p in payload["joints"] if isinstance(p, list) and len(p) == 2 and p[1] in UNITS}


def _arm_joint(log: RunLog, kinds: dict[str, str]) -> RunLog:
    """One joint of an n-joint log in its declared type's units (rad and N·m for a revolute one), without the velocity
    the n-joint writers fill with zeros (:mod:`ilic_cli.io.jointros`: a JointState's ``velocity`` is written 0, not measured)."""
    kind = kinds.get(str(log.meta.get("joint")))
    channels = {k: v for k, v in log.channels.items() if k != "qd"}
    units = {k: u for k, u in log.units.items() if k in channels}
    if kind is not None:
        units |= {k: u for k, u in channel_units(kind).items() if k in channels}
    return RunLog(channels, units, dict(log.meta))


def decode_guarded(source: Collected, selection: Selection, path: Path, container: str) -> RunLog:
    """:func:`decode`, turning any unexpected library failure into a one-line :class:`LogError`.

    Parameters
    ----------
    source, selection, path
        As for :func:`decode`.
    container : str
        Container name for the message (``"MCAP"``, ``"ROS 1 bag"``...).
    """
    with guarded(path, container):
        return decode(source, selection, path)


def _read_metadata(source: Collected, path: Path) -> dict[str, Any]:
    series = source.series(TOPIC_METADATA)
    if len(series) == 0 or series.text is None:
        raise LogError(path, f"{TOPIC_METADATA} has no message")
    payload = parse_json_object(series.text, path, f"{TOPIC_METADATA} message")
    if payload.get("format") != FORMAT_TAG:
        raise LogError(path, f"{TOPIC_METADATA} is not ilic metadata")
    if not isinstance(payload.get("version"), int) or payload["version"] > FORMAT_VERSION:
        raise LogError(path, f"{TOPIC_METADATA} has unsupported version {payload.get('version')!r}; upgrade ilic")
    return payload


def _decode_ilic(source: Collected, selection: Selection, path: Path) -> RunLog:
    payload = _read_metadata(source, path)
    joint = payload.get("joint")
    if not isinstance(joint, str):
        raise LogError(path, f"{TOPIC_METADATA} has no joint name")
    if selection.joint is not None and selection.joint != joint:
        raise LogError(path, f"no joint '{selection.joint}' (joints: {joint})")
    if selection.effort:
        raise LogError(path, f"an ilic log's effort is its {TOPIC_STATES} effort; another effort topic cannot be chosen")
    units = parse_units(payload.get("units", {}), path)
    meta = payload.get("meta", {})
    if not isinstance(meta, dict):
        raise LogError(path, f"{TOPIC_METADATA}: meta is not a JSON object")
    if TOPIC_STATES not in source.topics or source.topics[TOPIC_STATES].msgtype != JOINT_STATE:
        raise LogError(path, f"no {TOPIC_STATES} topic of type {JOINT_STATE}")
    ref_name = selection.ref_topic or TOPIC_REFERENCE
    states = _joint_state_series(source, TOPIC_STATES, joint, path, strict=True)
    if ref_name != TOPIC_STATES:
        source.release(TOPIC_STATES)
    channels: dict[str, np.ndarray] = {}
    for channel, fieldname in STATE_FIELDS.items():
        if states[fieldname] is not None:
            channels[channel] = states[fieldname]
    n = len(states.pop("log_ns"))  # the log times: only their count (let go as each topic is taken, not held to the end)
    if ref_name in source.topics:
        ref = _reference_series(source, ref_name, 0, path)
        source.release(ref_name)
        ref_n = len(ref.pop("log_ns"))
        if ref_n != n:
            raise LogError(path, f"{ref_name} has {ref_n} messages but {TOPIC_STATES} has {n}")
        for channel, fieldname in REFERENCE_FIELDS.items():
            if ref[fieldname] is not None:
                channels[channel] = ref[fieldname]
    elif selection.ref_topic:
        raise LogError(path, f"no topic {selection.ref_topic} (topics: {', '.join(sorted(source.topics))})")
    stamp_ns = states["stamp_ns"] if TOPIC_EXTRAS not in source.topics else None
    del states
    if TOPIC_EXTRAS in source.topics:
        extras = _extras_series(source, path)
        source.release(TOPIC_EXTRAS)
        if len(extras[TIME_NAME]) != n:
            raise LogError(path, f"{TOPIC_EXTRAS} has {len(extras[TIME_NAME])} messages but {TOPIC_STATES} has {n}")
        t = extras.pop(TIME_NAME)
        channels.update(extras)
    else:
        assert stamp_ns is not None  # kept when there is no extras topic
        t = stamp_ns.astype(np.float64) / 1e9
    del stamp_ns
    source.release(TOPIC_STATES)
    channels["t"] = t
    return RunLog(channels, {k: v for k, v in units.items() if k in channels}, dict(meta))


def _first(mask: np.ndarray) -> int | None:
    """Index of the first True in ``mask``, or None."""
    hits = np.flatnonzero(mask)
    return int(hits[0]) if len(hits) else None


def _extras_series(source: Collected, path: Path) -> dict[str, np.ndarray]:
    series = source.series(TOPIC_EXTRAS)
    if len(series) == 0:
        return {TIME_NAME: np.empty(0)}
    assert series.name_id is not None
    names = list(series.names[int(series.name_id[0])])
    if TIME_NAME not in names or len(set(names)) != len(names):
        raise LogError(path, f"{TOPIC_EXTRAS} names {names} must be distinct and include '{TIME_NAME}'")
    flat, counts = series.fields["position"]
    changed = _first(series.name_id != series.name_id[0])
    wrong = _first(counts != len(names))
    if changed is not None and (wrong is None or changed <= wrong):
        raise LogError(path, f"message {changed} on {TOPIC_EXTRAS} changes the channel names")
    if wrong is not None:
        raise LogError(path, f"message {wrong} on {TOPIC_EXTRAS} has {int(counts[wrong])} values for {len(names)} names")
    rows = len(series)
    source.release(TOPIC_EXTRAS)  # its log times and stamps go before the channels are copied out
    del series
    if len(names) == 1:
        return {names[0]: flat}
    matrix = flat.reshape(rows, len(names))
    return {name: matrix[:, j].copy() for j, name in enumerate(names)}


def _joint_state_series(source: Collected, topic: str, joint: str | None, path: Path, *, strict: bool, fields: dict[str, str] | None = None) -> dict[str, Any]:
    """Collect one joint's samples from a topic whose messages name their joints (JointState, controller state).

    With ``strict`` every message must carry the joint; otherwise messages
    without it are skipped. ``joint=None`` picks the only joint, or raises
    listing the joints. ``fields`` maps each key of the result to a column
    of the topic (default: :data:`MEASURED_FIELDS` of its type); the first
    one must be present for the joint in every message kept.
    """
    fields = fields or MEASURED_FIELDS[source.topics[topic].msgtype]
    first_key = next(iter(fields))
    what = first_key.removesuffix("s")
    series = source.series(topic)
    if len(series) == 0:
        raise LogError(path, f"topic {topic} has no messages")
    assert series.name_id is not None and series.stamp_ns is not None
    # name lists in order of first appearance (in log-time order)
    if len(series.names) == 1:
        in_order = list(series.names)
    else:
        ids, first_at = np.unique(series.name_id, return_index=True)
        in_order = [series.names[int(i)] for i in ids[np.argsort(first_at, kind="stable")]]
    if joint is None:
        seen: dict[str, None] = {}
        for names in in_order:
            for name in names:
                seen.setdefault(name, None)
        joints = list(seen)
        if len(joints) > 1:
            listed = ", ".join(joints[:20]) + (", ..." if len(joints) > 20 else "")
            raise ChoiceError(path, f"topic {topic} has {len(joints)} joints ({listed}); choose one", "joint", tuple(joints))
        joint = joints[0] if joints else ""
    # per name list: index of the joint, -1 when named without it, -2 when unnamed
    table = np.array([names.index(joint) if joint in names else (-1 if names else -2) for names in series.names], dtype=np.int64)
    pos_counts = series.fields[fields[first_key]][1]
    if len(table) == 1 and table[0] >= 0:
        # one name list for every message, with the joint: no per-message index arrays
        jj = int(table[0])
        no_position = _first(pos_counts <= jj)
        if no_position is not None:
            raise LogError(path, f"message {no_position} on {topic}: no {what} for joint '{joint}'")
        out: dict[str, Any] = {"joint": joint, "log_ns": series.log_ns, "stamp_ns": series.stamp_ns, "message_id": series.message_id}
        for key, fieldname in fields.items():
            out[key] = series.values_at(fieldname, jj)
        return out
    j = table[series.name_id]
    j = np.where((j == -2) & (joint == "") & (pos_counts == 1), 0, j)
    missing_joint = _first(j == -1) if strict else None
    keep = j >= 0
    no_position = _first(keep & (pos_counts <= j))
    if missing_joint is not None and (no_position is None or missing_joint < no_position):
        raise LogError(path, f"message {missing_joint} on {topic} has no joint '{joint}'")
    if no_position is not None:
        raise LogError(path, f"message {no_position} on {topic}: no {what} for joint '{joint}'")
    if not keep.any():
        available = sorted({name for names in series.names for name in names})
        raise LogError(path, f"topic {topic} has no joint '{joint}' (joints: {', '.join(available) or 'none'})")
    all_kept = bool(keep.all())
    mask = None if all_kept else keep
    jk = j if all_kept else j[keep]
    out = {
        "joint": joint,
        "log_ns": series.log_ns if all_kept else series.log_ns[keep],
        "stamp_ns": series.stamp_ns if all_kept else series.stamp_ns[keep],
    }
    for key, fieldname in fields.items():
        out[key] = series.values_at(fieldname, jk, mask)
    if series.message_id is not None:
        out["message_id"] = series.message_id if all_kept else series.message_id[keep]
    return out


def _reference_series(source: Collected, topic: str, joint_index: int | None, path: Path, joint: str | None = None) -> dict[str, Any]:
    info = source.topics[topic]
    if info.msgtype == TRAJECTORY:
        return _trajectory_reference(source, topic, joint, path)
    if info.msgtype in (JOINT_STATE, CONTROLLER_STATE):
        # by name: a message without the joint is skipped, a topic without it refused
        if info.msgtype == JOINT_STATE:
            fields = {"positions": "position", "velocities": "velocity"}
        else:
            fields = {"positions": "reference.positions", "velocities": "reference.velocities", "accelerations": "reference.accelerations"}
        ref = _joint_state_series(source, topic, joint, path, strict=False, fields=fields)
        ref.setdefault("accelerations", None)
        return ref
    if info.msgtype != TRAJECTORY_POINT:
        raise LogError(path, f"reference topic {topic} has type {info.msgtype}; expected {TRAJECTORY_POINT}, {TRAJECTORY}, {JOINT_STATE} or {CONTROLLER_STATE}")
    series = source.series(topic)
    width = series.fields["positions"][1]
    if len(width) and bool((width == 1).all()):
        # one position per message (the usual case): strided views, no index arrays
        out1: dict[str, Any] = {"log_ns": series.log_ns}
        for fieldname in ("positions", "velocities", "accelerations"):
            out1[fieldname] = series.values_at(fieldname, 0)
        return out1
    j = np.where(width == 1, 0, -1)
    if joint_index is not None:
        j = np.where((width != 1) & (width > joint_index), joint_index, j)
    bad = _first(j < 0)
    if bad is not None:
        raise LogError(path, f"message {bad} on {topic} has {int(width[bad])} positions; cannot tell which belongs to the joint")
    out: dict[str, Any] = {"log_ns": series.log_ns}
    for fieldname in ("positions", "velocities", "accelerations"):
        out[fieldname] = series.values_at(fieldname, j)
    return out


def _trajectory_reference(source: Collected, topic: str, joint: str | None, path: Path) -> dict[str, Any]:
    """The joint's reference from ``JointTrajectory`` messages, by name: their points at ``header.stamp + time_from_start``.

    As a trajectory controller does, a message replaces what earlier ones
    planned from its first point on. The result's ``point_ns`` are the points'
    times, on which the reference is interpolated at the measured stamps.
    """
    fields = {"positions": "positions", "velocities": "velocities", "accelerations": "accelerations"}
    ref = _joint_state_series(source, topic, joint, path, strict=False, fields=fields)
    at, message = ref["stamp_ns"], ref["message_id"]
    starts = np.full(int(message.max()) + 2, np.iinfo(np.int64).max, dtype=np.int64)
    np.minimum.at(starts, message, at)
    later = np.minimum.accumulate(starts[::-1])[::-1]  # the earliest start of this message or any later one
    keep = at < later[message + 1]
    order = np.argsort(at[keep], kind="stable")
    out: dict[str, Any] = {"point_ns": at[keep][order], "log_ns": ref["log_ns"][keep][order]}
    for key in fields:
        out[key] = None if ref[key] is None else ref[key][keep][order]
    if len(out["point_ns"]) and bool((np.diff(out["point_ns"]) == 0).any()):
        raise LogError(path, f"{topic} plans two points at the same time for joint '{ref['joint']}'")
    return out


def _choose_state_topic(source: Collected, selection: Selection, path: Path) -> str:
    topics = source.topics
    readable = tuple(MEASURED_FIELDS)
    if selection.topic is not None:
        if selection.topic not in topics:
            raise LogError(path, f"no topic {selection.topic} (topics: {', '.join(sorted(topics)) or 'none'})")
        if topics[selection.topic].msgtype not in readable:
            raise LogError(path, f"topic {selection.topic} has type {topics[selection.topic].msgtype}, not {' or '.join(readable)}")
        return selection.topic
    for msgtype in readable:  # JointState first, then a controller state
        candidates = sorted(name for name, info in topics.items() if info.msgtype == msgtype and name != TOPIC_EXTRAS)
        if len(candidates) == 1:
            return candidates[0]
        if TOPIC_STATES in candidates:
            return TOPIC_STATES
        if candidates:
            raise ChoiceError(path, f"several {msgtype} topics ({', '.join(candidates)}); choose one", "topic")
    listed = ", ".join(f"{n} ({i.msgtype})" for n, i in sorted(topics.items())) or "none"
    raise LogError(path, f"no {JOINT_STATE} or {CONTROLLER_STATE} topic (topics: {listed})")


def _choose_ref_topic(source: Collected, selection: Selection, topic: str) -> str | None:
    """The reference topic: the chosen one, ``/joint_reference``, the measured controller state, or the only controller state."""
    topics = source.topics
    if selection.ref_topic is not None:
        return selection.ref_topic
    if TOPIC_REFERENCE in topics:
        return TOPIC_REFERENCE
    if topics[topic].msgtype == CONTROLLER_STATE:
        return topic
    controllers = [name for name, info in topics.items() if info.msgtype == CONTROLLER_STATE]
    return controllers[0] if len(controllers) == 1 else None


def _on_samples(values: np.ndarray, log_ns: np.ndarray, at_ns: np.ndarray) -> np.ndarray | None:
    """``values`` logged at ``log_ns`` on the samples logged at ``at_ns`` (sorted): one to one when they are as many, else linear in log time."""
    order = np.argsort(log_ns, kind="stable")
    if len(values) == len(at_ns):
        return values[order]
    if len(values) < 2:
        return None
    return np.interp(at_ns.astype(np.float64), log_ns[order].astype(np.float64), values[order])


def _effort(source: Collected, selection: Selection, path: Path) -> tuple[str, str] | None:
    """``(topic, field)`` that gives ``tau``: ``Selection.effort`` (``TOPIC`` or ``TOPIC:FIELD``), else None (the measured topic's effort)."""
    if not selection.effort:
        return None
    name, _, fieldname = selection.effort.partition(":")
    info = source.topics.get(name)
    if info is None:
        raise LogError(path, f"no effort topic {name} (topics: {', '.join(sorted(source.topics))})")
    choices = EFFORT_FIELDS.get(info.msgtype)
    if choices is None:
        raise LogError(path, f"effort topic {name} has type {info.msgtype}; expected {JOINT_STATE} or {CONTROLLER_STATE}")
    fieldname = fieldname or choices[0]
    if fieldname not in choices:
        raise LogError(path, f"{info.msgtype} has no effort field '{fieldname}' (fields: {', '.join(choices)})")
    return name, fieldname


def _decode_foreign(source: Collected, selection: Selection, path: Path) -> RunLog:
    topic = _choose_state_topic(source, selection, path)
    states = _joint_state_series(source, topic, selection.joint, path, strict=False)
    joint = states["joint"]
    stamps = states["stamp_ns"]
    time_source = "header.stamp"
    if not stamps.any():
        stamps = states["log_ns"]
        time_source = "log_time"
    order = np.argsort(stamps, kind="stable")
    stamps = stamps[order]
    start = int(stamps[0])
    t = (stamps - start).astype(np.float64) / 1e9
    channels: dict[str, np.ndarray] = {"t": t}
    for channel, fieldname in STATE_FIELDS.items():
        if states[fieldname] is not None:
            channels[channel] = states[fieldname][order]
    log_ns = states["log_ns"][order]
    meta: dict[str, Any] = {"joint": joint, "topic": topic, "start_time_ns": start, "time_source": time_source}
    ref_name = _choose_ref_topic(source, selection, topic)
    if ref_name is not None:
        if ref_name not in source.topics:
            raise LogError(path, f"no topic {ref_name} (topics: {', '.join(sorted(source.topics))})")
        joint_index = _joint_index(source, topic, joint)
        ref = _reference_series(source, ref_name, joint_index, path, joint=joint)
        for channel, fieldname in REFERENCE_FIELDS.items():
            values = ref[fieldname]
            if values is None:
                continue
            if "point_ns" in ref:  # a planned trajectory: interpolated in time at the measured stamps
                on_samples = np.interp(stamps.astype(np.float64), ref["point_ns"].astype(np.float64), values) if len(values) else None
            else:
                on_samples = _on_samples(values, ref["log_ns"], log_ns)
            if on_samples is not None:
                channels[channel] = on_samples
        meta["ref_topic"] = ref_name
    effort = _effort(source, selection, path)
    if effort is None and "tau" not in channels and ref_name is not None and source.topics[ref_name].msgtype == CONTROLLER_STATE:
        effort = (ref_name, "output.effort")  # no measured effort: the controller's commanded one, when it has one
        if source.series(ref_name).fields["output.effort"][1].max(initial=0) == 0:
            effort = None
    if effort is not None:
        got = _joint_state_series(source, effort[0], joint, path, strict=False, fields={"effort": effort[1]})
        on_samples = _on_samples(got["effort"], got["log_ns"], log_ns)
        if on_samples is None:
            raise LogError(path, f"{effort[0]} has fewer than 2 '{effort[1]}' values for joint '{joint}'")
        channels["tau"] = on_samples
        meta["tau_source"] = f"{effort[0]}:{effort[1]}"
    if "tau" not in channels:
        raise ChoiceError(path, f"topic {topic} has no effort for joint '{joint}' and no controller state gives one; choose the effort's topic", "effort")
    rate = nominal_rate_hz(t)
    if rate:
        meta["sample_rate_hz"] = rate
    return RunLog(channels, {}, meta)


def _joint_index(source: Collected, topic: str, joint: str) -> int | None:
    series = source.series(topic)
    if len(series) == 0 or series.name_id is None:
        return None
    names = series.names[int(series.name_id[0])]
    return names.index(joint) if joint in names else None
