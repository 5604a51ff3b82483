"""Read and write ROS 2 bags (mcap storage, as Jazzy defaults to) without rosbag2.

Bags are written and read with the ``rosbags`` package. Messages are serialised by rclpy itself
(``rclpy.serialization``), so what a bag holds is byte for byte what a publisher sends; rosbags
only supplies the mcap container and the message schemas. The schemas of ``rfi_msgs`` are read
from the installed package (the ament index), so a bag written here is readable by ``ros2 bag``
on a full ROS install.

Errors that a user can cause (a missing or corrupt bag, an unknown message type) raise
:class:`BagError` with a one-line message.
"""

from __future__ import annotations

import importlib
import os
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore


class BagError(Exception):
    """A bag cannot be read or written; the message says why, in one line."""

    def __init__(self, message: str) -> None:
        super().__init__(' '.join(str(message).split()))


def msgtype_of(msg_or_class: Any) -> str:
    """Return the ROS type name ('pkg/msg/Name') of an rclpy message instance or class."""
    cls = msg_or_class if isinstance(msg_or_class, type) else type(msg_or_class)
    package = cls.__module__.split('.')[0]
    return f'{package}/msg/{cls.__name__}'


def message_class(msgtype: str) -> type:
    """Import the rclpy message class of a type name 'pkg/msg/Name' (or 'pkg/Name').

    Raises:
        BagError: the package or the type is not installed.
    """
    parts = msgtype.split('/')
    if len(parts) == 2:
        parts = [parts[0], 'msg', parts[1]]
    if len(parts) != 3 or not all(parts):
        raise BagError(f'malformed message type name {msgtype!r} (expected pkg/msg/Name)')
    package, kind, name = parts
    try:
        module = importlib.import_module(f'{package}.{kind}')
        return getattr(module, name)
    except (ImportError, AttributeError):
        raise BagError(f'unknown message type {msgtype!r}: package {package!r} does not provide it '
                       '(is the workspace built and install/setup.bash sourced?)') from None


def serialize(msg: Any) -> bytes:
    """Serialise an rclpy message to CDR bytes, exactly as a publisher sends it."""
    from rclpy.serialization import serialize_message
    return serialize_message(msg)


def deserialize(raw: bytes, msgtype: str) -> Any:
    """Deserialise CDR bytes into an rclpy message of type ``msgtype``."""
    from rclpy.serialization import deserialize_message
    return deserialize_message(raw, message_class(msgtype))


def _interface_share_dirs() -> list[Path]:
    """Share directories of installed interface packages that the Jazzy typestore lacks."""
    dirs = []
    for prefix in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep):
        share = Path(prefix, 'share', 'rfi_msgs')
        if (share / 'msg').is_dir():
            dirs.append(share)
    return dirs


@lru_cache(maxsize=1)
def typestore() -> Typestore:
    """The Jazzy typestore extended with the installed ``rfi_msgs`` types (for bag schemas).

    Raises:
        BagError: rfi_msgs is not installed in the current environment.
    """
    store = get_typestore(Stores.ROS2_JAZZY)
    shares = _interface_share_dirs()
    if not shares:
        raise BagError('rfi_msgs is not installed: build the workspace and source install/setup.bash')
    types: dict[str, Any] = {}
    for msg_file in sorted((shares[0] / 'msg').glob('*.msg')):
        types.update(get_types_from_msg(msg_file.read_text(), f'rfi_msgs/msg/{msg_file.stem}'))
    store.register(types)
    return store


@dataclass(frozen=True)
class BagMessage:
    """One message of a bag: topic, type, log time in ns and the CDR bytes."""

    topic: str
    msgtype: str
    stamp_ns: int
    raw: bytes

    def decode(self) -> Any:
        """The message as an rclpy object."""
        return deserialize(self.raw, self.msgtype)


class BagWriter:
    """Write an mcap bag from rclpy messages or raw CDR bytes.

    Use as a context manager::

        with BagWriter('out_bag') as bag:
            bag.write('/rfi/if_samples', msg, stamp_ns)

    Args:
        path: bag directory to create (must not exist unless ``overwrite``).
        overwrite: remove an existing bag directory first.
    """

    def __init__(self, path: str | os.PathLike[str], *, overwrite: bool = False) -> None:
        self.path = Path(path)
        if self.path.exists():
            if not overwrite:
                raise BagError(f'{self.path} exists already (remove it or pass overwrite)')
            if not (self.path / 'metadata.yaml').is_file() and any(self.path.iterdir()):
                raise BagError(f'{self.path} exists and is not a bag: not overwriting it')
            for child in self.path.iterdir():
                child.unlink()
            self.path.rmdir()
        self._writer = Writer(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
        self._connections: dict[str, Any] = {}
        self._types: dict[str, str] = {}
        self.counts: dict[str, int] = {}

    def __enter__(self) -> BagWriter:
        self._writer.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self._writer.close()

    def _connection(self, topic: str, msgtype: str) -> Any:
        conn = self._connections.get(topic)
        if conn is None:
            try:
                conn = self._writer.add_connection(topic, msgtype, typestore=typestore())
            except Exception as err:  # rosbags raises several types for unknown schemas
                raise BagError(f'cannot add topic {topic} of type {msgtype}: {err}') from None
            self._connections[topic] = conn
            self._types[topic] = msgtype
            self.counts[topic] = 0
        elif self._types[topic] != msgtype:
            raise BagError(f'topic {topic} has type {self._types[topic]}, not {msgtype}')
        return conn

    def write(self, topic: str, msg: Any, stamp_ns: int) -> None:
        """Write an rclpy message with log time ``stamp_ns`` (ns)."""
        self.write_raw(topic, msgtype_of(msg), serialize(msg), stamp_ns)

    def write_raw(self, topic: str, msgtype: str, raw: bytes, stamp_ns: int) -> None:
        """Write CDR bytes of type ``msgtype`` with log time ``stamp_ns`` (ns)."""
        self._writer.write(self._connection(topic, msgtype), int(stamp_ns), raw)
        self.counts[topic] += 1

    def set_custom_data(self, key: str, value: str) -> None:
        """Store ``key: value`` in the bag's ``metadata.yaml`` ``custom_data`` (rosbag2 metadata
        version 6 and later; ``ros2 bag info`` and :attr:`BagReader.custom_data` show it).

        Raises:
            BagError: key or value is not a string.
        """
        if not isinstance(key, str) or not isinstance(value, str):
            raise BagError(f'custom data must be str: str, got {type(key).__name__}: {type(value).__name__}')
        self._writer.set_custom_data(key, value)


class BagReader:
    """Read an mcap (or sqlite3) bag written by rosbag2 or by :class:`BagWriter`.

    Raises:
        BagError: on open, if the path is missing or is not a readable bag.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        if not self.path.exists():
            raise BagError(f'{self.path}: no such bag')
        try:
            self._reader = Reader(self.path)
            self._reader.open()
        except Exception as err:  # rosbags raises ReaderError and others for corrupt bags
            raise BagError(f'{self.path}: not a readable bag ({err})') from None

    def __enter__(self) -> BagReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        self._reader.close()

    @property
    def topics(self) -> dict[str, tuple[str, int]]:
        """Topic name -> (message type, message count)."""
        return {name: (info.msgtype or '', info.msgcount) for name, info in self._reader.topics.items()}

    @property
    def custom_data(self) -> dict[str, str]:
        """The ``custom_data`` of the bag's metadata (empty when it has none)."""
        return dict(self._reader.storage.metadata.custom or {})

    @property
    def duration_ns(self) -> int:
        return int(self._reader.duration)

    @property
    def start_ns(self) -> int:
        return int(self._reader.start_time)

    @property
    def message_count(self) -> int:
        return int(self._reader.message_count)

    def messages(self, topics: Iterable[str] | None = None, *, start_ns: int | None = None,
                 stop_ns: int | None = None) -> Iterator[BagMessage]:
        """Messages in log-time order, optionally only those of ``topics`` with log time in
        ``[start_ns, stop_ns)`` (absolute log times, ns).

        Raises:
            BagError: a topic of ``topics`` is not in the bag, or the bag is corrupt.
        """
        wanted = None if topics is None else set(topics)
        if wanted is not None:
            missing = wanted - set(self._reader.topics)
            if missing:
                raise BagError(f'{self.path}: no topic {", ".join(sorted(missing))} in the bag '
                               f'(it has {", ".join(sorted(self._reader.topics)) or "none"})')
        connections = [c for c in self._reader.connections if wanted is None or c.topic in wanted]
        try:
            for conn, stamp_ns, raw in self._reader.messages(connections=connections, start=start_ns, stop=stop_ns):
                yield BagMessage(conn.topic, conn.msgtype, int(stamp_ns), bytes(raw))
        except BagError:
            raise
        except Exception as err:
            raise BagError(f'{self.path}: corrupt bag ({type(err).__name__}: {err})') from None
