"""The custom data a bag carries (``metadata.yaml``'s ``custom_data``, or the rosbag2 record
embedded in a bare ``.mcap``): where a synthetic bag keeps its truth.
"""

from __future__ import annotations

import struct
from pathlib import Path

from .messages import MCAP_MAGIC, OP_FOOTER
from .salvage import Truncated, mcap_files, read_string

# --------------------------------------------------------------------------- custom data

UNREAD = object()
_OP_METADATA, _OP_METADATA_INDEX = 0x0C, 0x0D
_FOOTER_SIZE = 1 + 8 + 20  # opcode, length, summary start, summary offset start, CRC
_MAX_SUMMARY = 64 << 20  # a summary section larger than this is not searched


def _string_map(value: object) -> dict[str, str] | None:
    if not isinstance(value, dict) or not value:
        return None
    if not all(isinstance(k, str) and isinstance(v, str) for k, v in value.items()):
        return None
    return dict(value)


def _custom_data_of(info: object) -> dict[str, str] | None:
    """``custom_data`` of a ``rosbag2_bagfile_information`` mapping (None if absent/bad)."""
    return _string_map(info.get("custom_data")) if isinstance(info, dict) else None


def _safe_yaml(text: str) -> object:
    """``yaml.safe_load(text)`` through libyaml's parser where PyYAML has it (the same
    safe constructor, so the same objects and the same ``yaml.YAMLError`` s; a bag's
    ``metadata.yaml`` parses in under a millisecond instead of ~18 ms)."""
    import yaml

    loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
    return yaml.load(text, Loader=loader)  # a safe loader


def _embedded_metadata(path: Path) -> object:
    """The rosbag2 metadata an MCAP file holds (its ``rosbag2`` metadata record, found
    through the summary's metadata index), parsed from YAML; None when there is none."""

    size = path.stat().st_size
    with path.open("rb") as stream:
        if size < 2 * len(MCAP_MAGIC) + _FOOTER_SIZE:
            return None
        stream.seek(size - len(MCAP_MAGIC) - _FOOTER_SIZE)
        footer = stream.read(_FOOTER_SIZE)
        if footer[0] != OP_FOOTER:
            return None
        (summary_start,) = struct.unpack_from("<Q", footer, 9)
        summary_end = size - len(MCAP_MAGIC) - _FOOTER_SIZE
        if not 0 < summary_start < summary_end or summary_end - summary_start > _MAX_SUMMARY:
            return None
        stream.seek(summary_start)
        summary = stream.read(summary_end - summary_start)
        pos = 0
        while pos + 9 <= len(summary):
            op = summary[pos]
            (length,) = struct.unpack_from("<Q", summary, pos + 1)
            body = summary[pos + 9 : pos + 9 + length]
            pos += 9 + length
            if op != _OP_METADATA_INDEX:
                continue
            offset, record_length = struct.unpack_from("<QQ", body, 0)
            name, _ = read_string(body, 16)
            if name != "rosbag2" or record_length > _MAX_SUMMARY:
                continue
            stream.seek(offset)
            record = stream.read(record_length)
            if len(record) < 9 or record[0] != _OP_METADATA:
                return None
            _, at = read_string(record, 9)
            (map_size,) = struct.unpack_from("<I", record, at)
            at += 4
            end = at + map_size
            while at < end:
                key, at = read_string(record, at)
                value, at = read_string(record, at)
                if key == "serialized_metadata":
                    return _safe_yaml(value)
            return None
    return None


def read_custom_data(path: str | Path) -> dict[str, str] | None:
    """The ``custom_data`` map of a bag (directory or bare ``.mcap``), or None.

    Looks in ``metadata.yaml`` first, then in the rosbag2 metadata embedded in the MCAP
    file(s). Never raises for a bag without one or with a damaged one: None.
    """
    import yaml

    bag = Path(path)
    if bag.is_dir():
        try:
            document = _safe_yaml((bag / "metadata.yaml").read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, yaml.YAMLError):
            document = None
        if isinstance(document, dict) and "rosbag2_bagfile_information" in document:
            return _custom_data_of(document["rosbag2_bagfile_information"])
    for file in mcap_files(bag):
        try:
            found = _custom_data_of(_embedded_metadata(file))
        except (OSError, struct.error, UnicodeDecodeError, Truncated, yaml.YAMLError):
            continue
        if found is not None:
            return found
    return None


def starts_with_magic(path: Path) -> bool:
    try:
        with path.open("rb") as stream:
            return stream.read(len(MCAP_MAGIC)) == MCAP_MAGIC
    except OSError:
        return False
