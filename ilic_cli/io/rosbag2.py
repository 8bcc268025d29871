"""ROS 2 bag folders through ``rosbags.rosbag2`` (storage ``sqlite3`` or ``mcap``).

Writing creates a bag of format version 9 (Humble CDR types, the topics of
:mod:`ilic_cli.io.rosschema`) with the storage plugin of
``WriteOptions.storage``. Reading accepts both storages; the ``.mcap`` files
of an MCAP-backed bag are first checked with :func:`ilic_cli.io.mcaplog.scan`
(CRCs, bounded decompression) before ``rosbags`` reads them.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from ilic_cli.errors import LogError
from ilic_cli.io import container, roscollect, rosdecode, rosencode, rosschema

if TYPE_CHECKING:
    from ilic_cli.io import Selection, WriteOptions
    from ilic_cli.runlog import RunLog

STORAGES = ("sqlite3", "mcap")


def write(log: RunLog, path: Path, options: WriteOptions) -> None:
    """Write ``log`` to a ROS 2 bag folder.

    Parameters
    ----------
    log : RunLog
        The log to write.
    path : Path
        Folder to create (must not exist yet). The storage file inside is
        named after the final target (``NAME/NAME.db3``), not the temporary folder.
    options : WriteOptions
        ``options.storage`` (``"sqlite3"`` or ``"mcap"``) and ``options.joint``.
    """
    from rosbags.rosbag2 import StoragePlugin, Writer

    if options.storage not in STORAGES:
        raise LogError(None, f"unknown rosbag2 storage '{options.storage}' (choose from {', '.join(STORAGES)})")
    plugin = StoragePlugin.MCAP if options.storage == "mcap" else StoragePlugin.SQLITE3
    joint = rosencode.writer_joint(log, options.joint)
    # rosbags names the storage file after the bag folder; write into a
    # folder named like the final target, then lift its files up into `path`.
    path.mkdir()
    inner = path / _target_name(path)
    container.write_bag(Writer(inner, version=Writer.VERSION_LATEST, storage_plugin=plugin), log, joint, rosschema.ROS2)
    for item in sorted(inner.iterdir()):
        item.rename(path / item.name)
    inner.rmdir()


def _target_name(tmp: Path) -> str:
    """Name of the final bag for a temporary ``.NAME.XXXXXX.tmp`` folder (else the folder's name)."""
    name = tmp.name
    if name.startswith(".") and name.endswith(".tmp") and "." in name[1:-4]:
        return name[1:-4].rsplit(".", 1)[0] or "bag"
    return name or "bag"


def _collect(reader: Any, path: Path) -> roscollect.Collected:
    """Stream the messages of every readable connection into a :class:`roscollect.Collector`."""

    collector = roscollect.Collector(path)
    sinks: dict[int, Any] = {}
    wanted = []
    for conn in reader.connections:
        fmt = getattr(conn.ext, "serialization_format", "cdr")
        kind = rosschema.ROS2 if fmt == "cdr" else fmt
        sink = collector.declare(rosschema.RawTopic(conn.topic, rosschema.normalize_msgtype(conn.msgtype), kind))
        if sink is not None:
            sinks[conn.id] = sink
            wanted.append(conn)
    container.feed_sinks(reader, wanted, sinks, path)
    return collector.finish()


def _precheck_mcap(path: Path) -> None:
    from ilic_cli.io.mcaplog import scan

    for file in sorted(path.glob("*.mcap")):
        try:
            scan(file)
        except LogError as exc:
            raise LogError(path, f"{file.name}: {exc.problem}") from None


def read(path: Path, selection: Selection) -> RunLog:
    """Read a run log from a ROS 2 bag folder.

    Parameters
    ----------
    path : Path
        The bag folder (with ``metadata.yaml``).
    selection : Selection
        Topic, reference topic and joint (for bags not written by ilic).

    Returns
    -------
    RunLog
    """
    from rosbags.rosbag2 import Reader

    if not path.is_dir():
        raise LogError(path, "a ROS 2 bag is a folder with metadata.yaml")
    if not (path / "metadata.yaml").is_file():
        raise LogError(path, "not a ROS 2 bag: no metadata.yaml in the folder")
    _precheck_mcap(path)
    try:
        reader = Reader(path)
        reader.open()
    except LogError:
        raise
    except Exception as exc:  # noqa: BLE001 - rosbags/sqlite/yaml raise many kinds on bad bags
        raise LogError(path, f"not a readable ROS 2 bag ({type(exc).__name__}: {container.short_text(exc)})") from None
    try:
        with container.guarded(path, "ROS 2 bag"):
            source = _collect(reader, path)
        return rosdecode.decode_guarded(source, selection, path, "ROS 2 bag")
    finally:
        container.close_quietly(reader)

