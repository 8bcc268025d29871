"""ROS 2 bag folders through ``rosbags.rosbag2`` (storage ``sqlite3`` or ``mcap``).

Writing creates a bag of format version 9 (Humble CDR types, the topics of
:mod:`ilic_cli.io.rosschema`) with the storage plugin of
``WriteOptions.storage``, through ``rosbags``' writer; with
``WriteOptions.fast`` (the default) its storage takes the messages in bulk
(:mod:`ilic_cli.io.rosbulk`: an sqlite3 file with the per-message writer's
rows, ids and index, its table and index written as B-tree pages, or an MCAP
file with zstd chunks). Reading accepts both storages; the ``.mcap`` files
of an MCAP-backed bag are first checked with :func:`ilic_cli.io.mcaplog.scan`
(CRCs, bounded decompression). With ``fast`` (the default) that scan of a
bag's only, uncompressed ``.mcap`` file is also the read, and an sqlite3 bag's
table is read off the file's pages (:mod:`ilic_cli.io.sqlitepages`), or, for a
file that module does not read, in ranges of ids that sqlite3 joins into one
row each; the blobs are decoded in runs;
``rosbags`` still reads ``metadata.yaml`` and the topics, without counting the messages. Otherwise ``rosbags`` streams the
messages one by one.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from rosbags.rosbag2 import Reader, StoragePlugin, Writer

from ilic_cli.errors import LogError
from ilic_cli.io import container, roscollect, rosdecode, rosencode, rosschema
from ilic_cli.io.ros2sqlite import feed_sqlite, rosbags_sqlite_settings, single_sqlite

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
        ``options.storage`` (``"sqlite3"`` or ``"mcap"``), ``options.joint`` and
        ``options.fast`` (messages in bulk, or one by one through ``rosbags``).
    """
    if options.storage not in STORAGES:
        raise LogError(None, f"unknown rosbag2 storage '{options.storage}' (choose from {', '.join(STORAGES)})")
    plugin = StoragePlugin.MCAP if options.storage == "mcap" else StoragePlugin.SQLITE3
    joint = rosencode.writer_joint(log, options.joint)
    # rosbags names the storage file after the bag folder; write into a
    # folder named like the final target, then lift its files up into `path`.
    path.mkdir()
    inner = path / _target_name(path)
    columns = rosencode.encode_columns(log, joint) if options.fast else None
    if columns is not None:
        _write_columns(inner, plugin, columns)
    else:
        container.write_bag(Writer(inner, version=Writer.VERSION_LATEST, storage_plugin=plugin), log, joint, rosschema.ROS2)
    for item in sorted(inner.iterdir()):
        item.rename(path / item.name)
    inner.rmdir()


def _write_columns(path: Path, plugin: Any, columns: rosencode.Columns) -> None:
    """Write a bag with ``rosbags``' writer (metadata, topics, ``metadata.yaml``) and the messages in bulk.

    The storage plugins are the bulk ones of :mod:`ilic_cli.io.rosbulk`; the
    writer's message counts and time range are kept as its per-message
    ``write`` would keep them.
    """
    from ilic_cli.io.rosbulk import BulkMcapStorage, BulkSqlite3Storage  # the bulk writers import mcap (some 60 ms): a read does not load them

    class BulkBagWriter(Writer):
        STORAGE_PLUGINS = {StoragePlugin.SQLITE3: BulkSqlite3Storage, StoragePlugin.MCAP: BulkMcapStorage}

    writer = BulkBagWriter(path, version=Writer.VERSION_LATEST, storage_plugin=plugin)
    ts = rosschema.typestore(rosschema.ROS2)
    writer.open()
    try:
        connections = {spec.topic: writer.add_connection(spec.topic, spec.msgtype, typestore=ts) for spec in columns.topics}
        first = int(columns.log_ns[0])
        writer.write(connections[rosschema.TOPIC_METADATA], first, columns.metadata)
        assert isinstance(writer.storage, (BulkSqlite3Storage, BulkMcapStorage))  # BulkBagWriter's plugins
        writer.storage.add_samples(columns, {topic: conn.id for topic, conn in connections.items()})
        for topic in columns.sample_topics():
            writer.counts[connections[topic].id] += len(columns.log_ns)
        writer.min_timestamp = min(writer.min_timestamp, int(columns.log_ns.min()))
        writer.max_timestamp = max(writer.max_timestamp, int(columns.log_ns.max()))
    except BaseException:
        writer.abort()
        raise
    writer.close()


def _target_name(tmp: Path) -> str:
    """Name of the final bag for a temporary ``.NAME.XXXXXX.tmp`` folder (else the folder's name)."""
    name = tmp.name
    if name.startswith(".") and name.endswith(".tmp") and "." in name[1:-4]:
        return name[1:-4].rsplit(".", 1)[0] or "bag"
    return name or "bag"


def _collect(reader: Any, path: Path, fast: bool) -> roscollect.Collected:
    """Stream the messages of every readable connection into a :class:`roscollect.Collector`.

    With ``fast`` a bag with one uncompressed sqlite3 file is read with one
    query (:func:`ilic_cli.io.ros2sqlite.feed_sqlite`); otherwise ``rosbags`` streams the messages.
    """
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
    storage = single_sqlite(reader) if fast else None
    if storage is not None:
        feed_sqlite(storage, wanted, sinks, path)
    else:
        container.feed_sinks(reader, wanted, sinks, path)
    return collector.finish()


def _scan_mcap(path: Path, fast: bool) -> roscollect.Collected | None:
    """Check every ``.mcap`` file of the bag (CRCs, bounds); with ``fast`` and one file, also read it.

    Returns the collected messages when the bag's only storage file was read, else None.
    """
    files = sorted(path.glob("*.mcap"))
    if not files:
        return None
    from ilic_cli.io import mcaplog  # mcap (some 30 ms) deferred: a bag of sqlite3 storage does not load it

    collector = roscollect.Collector(path) if fast and len(files) == 1 else None
    for file in files:
        try:
            mcaplog.scan(file, collector, fast=fast)
        except LogError as exc:
            raise LogError(path, f"{file.name}: {exc.problem}") from None
    return collector.finish() if collector is not None else None


def _reads_only(reader: Any, path: Path) -> bool:
    """Whether the bag's storage is the one uncompressed ``.mcap`` file :func:`_scan_mcap` read."""
    bag = getattr(reader, "storage", None)
    storages = getattr(bag, "storages", None)
    metadata = getattr(bag, "metadata", None)
    if not isinstance(storages, list) or len(storages) != 1 or metadata is None or metadata.compression_mode:
        return False
    stored = getattr(storages[0], "path", None)
    return isinstance(stored, Path) and stored.suffix == ".mcap" and [stored.resolve()] == [p.resolve() for p in path.glob("*.mcap")]


def read(path: Path, selection: Selection, *, fast: bool = True) -> RunLog:
    """Read a run log from a ROS 2 bag folder.

    Parameters
    ----------
    path : Path
        The bag folder (with ``metadata.yaml``).
    selection : Selection
        Topic, reference topic and joint (for bags not written by ilic).
    fast : bool
        Decode runs of same-layout messages as columns (ranges of ids joined
        by sqlite3, the MCAP chunk walker for MCAP storage); False: message by
        message through ``rosbags``.

    Returns
    -------
    RunLog
    """
    if not path.is_dir():
        raise LogError(path, "a ROS 2 bag is a folder with metadata.yaml")
    if not (path / "metadata.yaml").is_file():
        raise LogError(path, "not a ROS 2 bag: no metadata.yaml in the folder")
    scanned = _scan_mcap(path, fast)
    try:
        reader = Reader(path)
        with rosbags_sqlite_settings(uncounted=fast):
            reader.open()
    except LogError:
        raise
    except Exception as exc:  # noqa: BLE001 - rosbags/sqlite/yaml raise many kinds on bad bags
        raise LogError(path, f"not a readable ROS 2 bag ({type(exc).__name__}: {container.short_text(exc)})") from None
    try:
        with container.guarded(path, "ROS 2 bag"):
            source = scanned if scanned is not None and _reads_only(reader, path) else _collect(reader, path, fast)
        return rosdecode.decode_guarded(source, selection, path, "ROS 2 bag")
    finally:
        container.close_quietly(reader)
