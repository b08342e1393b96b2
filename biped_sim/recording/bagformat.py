"""What a rosbag2 bag says about its topics besides the messages: schemas, type hashes, QoS, metadata.yaml.

Owns the rosbag2 side of the on-disk format (what ``ros2 bag record -s mcap`` on Jazzy writes),
shared by the writer process (:mod:`biped_sim.recording.writer`) and :mod:`biped_sim.recording.recover`:

* the ``ros2msg`` schema of a type: its .msg text and every dependency after a line of 80 ``=``
  and ``MSG: pkg/Type``, as rosbag2's message-definition cache builds it;
* the RIHS01 type hash (channel metadata ``topic_type_hash``, ``type_description_hash``);
* one offered QoS profile as rosbag2 v9 writes it (channel metadata ``offered_qos_profiles``);
* ``rosbag2_bagfile_information`` version 9 (rosbag2_storage/yaml.hpp): the ``rosbag2`` MCAP
  metadata record and ``metadata.yaml``.
"""
from __future__ import annotations

import json
import os
import re
import sys
from pathlib import Path

ROS_DISTRO = "jazzy"
METADATA_VERSION = 9
INFINITE = {"sec": 9223372036, "nsec": 854775807}   # rmw's infinite duration, as rosbag2 writes it
PROFILE = "ros2"                                     # the MCAP profile of a rosbag2 file
_PRIMITIVES = {"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
               "int32", "uint32", "int64", "uint64", "string", "wstring"}
_FIELD_TYPE = re.compile(r"(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+")


#: types recorded without their interface package (not on PyPI): (.msg text, RIHS01 hash of Jazzy's
#: type description; test_foxglove_layout computes it again from geometry_msgs' description)
UNINSTALLED_TYPES = {
    "tf2_msgs/msg/TFMessage": ("geometry_msgs/TransformStamped[] transforms\n",
                               "RIHS01_e369d0f05a23ae52508854b66f6aa0437f3449d652e8cbf22d5abe85d020f087"),
}


# -- type information: definitions and hashes from the installed interface packages ----------------
def _share_dir(package: str) -> Path:
    try:
        from ament_index_python.packages import get_package_share_directory
        return Path(get_package_share_directory(package))
    except Exception:  # noqa: BLE001 - fall back to the venv's share folder
        p = Path(sys.prefix) / "share" / package
        if p.is_dir():
            return p
        raise LookupError(f"interface package '{package}' is not installed (no share/{package} folder)") from None


def _split(type_name: str):
    parts = type_name.split("/")
    if len(parts) == 2:
        return parts[0], "msg", parts[1]
    if len(parts) == 3:
        return parts
    raise ValueError(f"message type must look like 'pkg/msg/Name', got {type_name!r}")


def message_definition(type_name: str) -> str:
    """The ``ros2msg`` schema text of a type: its .msg, then each dependency (depth first, sorted)."""
    seen = set()

    def text_of(name):
        pkg, ns, typ = _split(name)
        if f"{pkg}/{ns}/{typ}" in UNINSTALLED_TYPES:
            text = UNINSTALLED_TYPES[f"{pkg}/{ns}/{typ}"][0]
        else:
            path = _share_dir(pkg) / ns / f"{typ}.msg"
            if not path.is_file():
                raise LookupError(f"no message definition {path} for {type_name}")
            text = path.read_text()
        deps = set()
        for m in _FIELD_TYPE.finditer(text):
            t = m.group(1)
            if t in _PRIMITIVES:
                continue
            deps.add(t if "/" in t else f"{pkg}/{t}")
        out = text
        for dep in sorted(deps):
            if dep not in seen:
                seen.add(dep)
                out += "\n" + "=" * 80 + "\nMSG: " + dep + "\n" + text_of(dep)
        return out
    return text_of(type_name)


def type_hash(type_name: str) -> str:
    """The RIHS01 type-description hash of a type (from its generated ``.json`` description)."""
    pkg, ns, typ = _split(type_name)
    full = f"{pkg}/{ns}/{typ}"
    if full in UNINSTALLED_TYPES:
        return UNINSTALLED_TYPES[full][1]
    path = _share_dir(pkg) / ns / f"{typ}.json"
    try:
        for entry in json.loads(path.read_text())["type_hashes"]:
            if entry["type_name"] == full:
                return entry["hash_string"]
    except (OSError, KeyError, ValueError):
        pass
    return ""


# -- QoS as rosbag2 writes it (metadata v9) ---------------------------------------------------------
def _duration(d):
    if d is None:
        return dict(INFINITE)
    if isinstance(d, dict):
        return {"sec": int(d["sec"]), "nsec": int(d["nsec"])}
    ns = int(getattr(d, "nanoseconds", d))
    if ns <= 0 or ns >= 2**63 - 1:  # unspecified / infinite
        return dict(INFINITE)
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def qos_dict(qos=None) -> dict:
    """One offered QoS profile as a rosbag2 v9 dict; ``qos`` is None, a dict or an rclpy QoSProfile."""
    out = {"history": "keep_last", "depth": 10, "reliability": "reliable", "durability": "volatile",
           "deadline": dict(INFINITE), "lifespan": dict(INFINITE), "liveliness": "automatic",
           "liveliness_lease_duration": dict(INFINITE), "avoid_ros_namespace_conventions": False}
    if qos is None:
        return out
    if isinstance(qos, dict):
        out.update(qos)
        return out

    def name(v):
        return getattr(v, "name", str(v)).lower()
    out.update(history=name(qos.history), depth=int(qos.depth), reliability=name(qos.reliability),
               durability=name(qos.durability), liveliness=name(qos.liveliness),
               deadline=_duration(qos.deadline), lifespan=_duration(qos.lifespan),
               liveliness_lease_duration=_duration(qos.liveliness_lease_duration),
               avoid_ros_namespace_conventions=bool(qos.avoid_ros_namespace_conventions))
    return out


def to_yaml(obj) -> str:
    import yaml
    return yaml.safe_dump(obj, default_flow_style=False, sort_keys=False)


def channel_metadata(qos_profiles, hash_string) -> dict:
    """The MCAP channel metadata rosbag2 writes: the offered QoS profiles (YAML) and the type hash."""
    return {"offered_qos_profiles": to_yaml(qos_profiles).strip(), "topic_type_hash": hash_string}


def bag_metadata(mcap_name, topics, start_ns, end_ns, custom_data=None) -> dict:
    """The ``rosbag2_bagfile_information`` mapping (version 9).

    ``topics``: list of dicts with name, type, qos (list of dicts), hash, count.
    """
    count = sum(t["count"] for t in topics)
    start = int(start_ns) if count else 0
    duration = max(0, int(end_ns) - int(start_ns)) if count else 0
    return {
        "version": METADATA_VERSION,
        "storage_identifier": "mcap",
        "duration": {"nanoseconds": duration},
        "starting_time": {"nanoseconds_since_epoch": start},
        "message_count": count,
        "topics_with_message_count": [
            {"topic_metadata": {"name": t["name"], "type": t["type"], "serialization_format": "cdr",
                                "offered_qos_profiles": t["qos"], "type_description_hash": t["hash"]},
             "message_count": t["count"]} for t in topics],
        "compression_format": "",
        "compression_mode": "",
        "relative_file_paths": [mcap_name],
        "files": [{"path": mcap_name, "starting_time": {"nanoseconds_since_epoch": start},
                   "duration": {"nanoseconds": duration}, "message_count": count}],
        "custom_data": custom_data or None,
        "ros_distro": ROS_DISTRO,
    }


def rosbag2_record(info: dict) -> dict:
    """The ``rosbag2`` MCAP metadata record of a bag (rosbag2 writes it last, before the summary)."""
    return {"serialized_metadata": to_yaml(info), "ros_distro": ROS_DISTRO}


def write_metadata_yaml(bag_dir: Path, info: dict):
    """``metadata.yaml`` of a bag, written to a temporary file and renamed (never half written)."""
    tmp = Path(bag_dir) / "metadata.yaml.tmp"
    try:
        tmp.write_text(to_yaml({"rosbag2_bagfile_information": info}))
    except OSError:
        tmp.unlink(missing_ok=True)     # a full disk: leave no half file in the bag (recover writes it)
        raise
    os.replace(tmp, Path(bag_dir) / "metadata.yaml")
